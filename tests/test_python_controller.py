"""A user controller numba cannot compile runs inside the compiled call as a declared Python stage
(``contactdyn.laws.controllers.abi.python_controller_address``): a ctypes callback rebuilds, from the call's buffer,
the ControlInput a controller is given (its dictionaries by key, the controller's own ``self``) and calls its
``command``. Per case the compiled call's ẋ against the same call interpreted (``run_agreement.interpreted_evaluate``)
at a few states; whole runs against the interpreted runs (``LivePipelines.use = False``); the controller's own
exception; the ControlInput itself, field by field."""

from __future__ import annotations

import tomllib
import types
import warnings
from dataclasses import fields
from pathlib import Path

import numpy as np
import pytest
from run_agreement import assert_runs_agree, interpreted_evaluate

from contactdyn import parse_scene, simulate
from contactdyn.errors import SimulationError
from contactdyn.laws import Controller, Param
from contactdyn.laws.controllers import CONTROLLERS
from contactdyn.laws.controllers import abi as controller_abi
from contactdyn.laws.failures import LawError
from contactdyn.model.paths import LivePipelines
from contactdyn.model.pipeline.pack import python_controller
from contactdyn.model.pipeline.pipeline import Pipeline
from contactdyn.simulate import prepare

ROOT = Path(__file__).resolve().parents[1]
RTOL = 1e-9  #: each component of ẋ to RTOL × (1 + its largest magnitude over the states)
_GAIN = {"k": 1.0}  #: a Python dict: numba cannot type it as a global


class DictForcePI(Controller):
    """examples/force_law.py's force PI law reading ControlInput's dictionaries (``forces``, ``force_d``,
    ``normals``, ``surfaces``, ``touching``) and a Python dict: numba cannot compile it."""

    name = "dict_force_pi_test"
    uses_forces = True
    n_states = 1
    params = (Param("stiffness", "N/m", "K", 2000.0), Param("damping", "N·s/m", "D", 100.0),
              Param("damping_n", "N·s/m", "D_n", 50.0), Param("ki", "1/s", "k_i", 20.0),
              Param("cancel", "-", "c", 0.5, hi=1.0))

    def command(self, inp):
        c = self.config
        key = next(iter(inp.force_d))
        n = inp.normals[key]
        F_d = inp.force_d[key][0]
        f = c.stiffness * (inp.x_d - inp.p_tip) - c.damping * inp.v_tip
        f = f - (f * n).sum() * n
        rate_n = (n * (inp.v_tip - inp.surfaces[key][1])).sum()
        f = f - (c.damping_n * rate_n + F_d + inp.z[0]) * n
        tau = _GAIN["k"] * (inp.J.T @ f) - c.cancel * inp.tau_contact
        zdot = np.array([float(inp.touching[key.partition(".")[0]]) * c.ki * (F_d - inp.forces[key])])
        return tau, zdot


class WatchingImpedance(Controller):
    """A task impedance over every set-point reading ``touching``, ``normals``, ``surfaces``, ``forces`` and
    τ_c, its gravity and a_d (a carried reference folds it), its config its own object (``read``): numba does not
    compile it."""

    name = "watching_impedance_test"
    uses_forces = True
    needs_gravity = True
    params = (Param("k", "N/m", "K", 3000.0), Param("d", "N·s/m", "D", 200.0), Param("kf", "1", "k_f", 0.3))

    @classmethod
    def read(cls, r):
        return types.SimpleNamespace(kind=cls.name, **dict(Controller.read.__func__(cls, r).values))

    def command(self, inp):
        cfg = self.config
        f = cfg.k * (inp.x_d - inp.p_tip) + cfg.d * (inp.v_d - inp.v_tip) + 0.5 * inp.a_d
        for key, (F_d, rate) in inp.force_d.items():
            n, (p_s, v_s) = inp.normals[key], inp.surfaces[key]
            pressed = float(inp.touching[key.partition(".")[0]])
            f = f - (pressed * (F_d + 1e-3 * rate) + cfg.kf * (F_d - inp.forces[key])) * n
            f = f - 10.0 * ((p_s - inp.p_tip) @ n) * n - 5.0 * ((v_s - inp.v_tip) @ n) * n
        return inp.J.T @ f + inp.gravity - 0.1 * inp.tau_contact, None


class Raising(Controller):
    """τ = 0 until t = 0.01 s, then its own error (reads a Python dict: a Python stage)."""

    name = "raising_ctl_test"
    reads_orientation = False

    def command(self, inp):
        if inp.t > 0.01:
            raise _ControllerFailed(f"the controller gave up at t > 0.01 s (gain {_GAIN['k']})")
        return _GAIN["k"] * 0.0 * inp.q, None


class _ControllerFailed(RuntimeError):
    pass


@pytest.fixture(scope="module", autouse=True)
def registered():
    """This module's controllers registered for its scenes, the registry as it was after."""
    saved = dict(CONTROLLERS)
    CONTROLLERS.update({cls.name: cls for cls in (DictForcePI, WatchingImpedance, Raising)})
    yield
    CONTROLLERS.clear()
    CONTROLLERS.update(saved)


def _parse(doc: dict, path: str):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return parse_scene(doc, file=str(ROOT / path))


def axis_scene(kind: str, duration: float = 0.05, sample_rate: float | None = None):
    """The cylindrical robot's tip onto a chain surface (tests/test_compiled_path's), under controller ``kind`` (run
    at ``sample_rate`` [Hz], if given)."""
    return parse_scene({
        "duration": duration, "robot": {"urdf": "cylindrical3", "active_joints": ["q3"], "q0": [0.999], "v0": [0.5]},
        "contact": {"tip": {"point": [1.0, 0.0, 0.2], "normal": {"direction": [0, 0, 1], "model": "chain",
                                                                  "environment": [{"k": 5e4, "b": 1500.0}]}}},
        "controller": {"kind": kind, **({"sample_rate": sample_rate} if sample_rate else {})}})


def force_pi_press(duration: float = 0.5, sample_rate: float | None = None):
    """examples/force_pi_press.toml (a bonded model-b surface: its row folded, friction sliding) under DictForcePI,
    at the solver's rtol 1e-10 (at its 1e-8 the compiled twin, examples/force_law.py's ForcePI, was 6.3e-9 off
    the since deleted readable model's run in 0.2 s, as this law is: the integration's, not the law's); run at
    ``sample_rate`` [Hz], if given (its dictionaries then rebuilt from what a sample measured)."""
    path = "examples/force_pi_press.toml"
    doc = tomllib.loads((ROOT / path).read_text())
    doc["imports"], doc["duration"] = [], duration
    if sample_rate:
        doc["controller"]["sample_rate"] = sample_rate
    doc["solver"].update(rtol=1e-10, atol=1e-12)
    doc["controller"]["kind"] = DictForcePI.name
    return _parse(doc, path)


def cart_push(duration: float = 3.0):
    """sims/case1_cart.toml's push (two set-points, one on a tangential chain, a reference carried by the cart,
    motors) under WatchingImpedance."""
    path = "sims/case1_cart.toml"
    doc = tomllib.loads((ROOT / path).read_text())
    doc["duration"] = duration
    doc["phase"][1]["controller"] = {"kind": WatchingImpedance.name}
    return _parse(doc, path)


def _states(x0: np.ndarray, count: int = 4) -> list[np.ndarray]:
    rng = np.random.default_rng(5)
    return [x0.copy(), *(x0 + 1e-3 * (1.0 + np.abs(x0)) * rng.normal(size=x0.size) for _ in range(count - 1))]


def _touching(system, modes):
    return [m.with_(touching=True, offsets=tuple(0.001 * (i + 1) for i, _ in enumerate(c.tangent_chains)))
            for c, m in zip(system.contacts, modes, strict=True)]


def _case(name: str):
    """(system, modes, phase, t [s], x0) of a case: the controller's phase, its contacts touching or not."""
    if name in ("fixture_free", "fixture_touching"):
        system, modes, phase, x0 = prepare(axis_scene("uncompilable_ctl"))
        return system, modes if name == "fixture_free" else _touching(system, modes), phase, 0.0123, x0
    if name == "force_pi_press":
        system, modes, phase, x0 = prepare(force_pi_press())
        return system, _touching(system, modes), phase, 0.0123, x0
    system, modes, phase, x0 = prepare(cart_push())
    phase = system.start_phase(1, 1.05, x0, phase)
    return system, _touching(system, modes), phase, 1.0623, x0


CASES = ["fixture_free", "fixture_touching", "force_pi_press", "cart_push"]


@pytest.mark.parametrize("name", CASES)
def test_the_python_stage_rates_are_the_interpreted_calls(name, uncompilable_controller):
    """ẋ of the compiled call (the controller called back through ctypes) is the interpreted call's
    (interpreted_evaluate) at each state, every call answered, the controller named as a Python stage with numba's
    reason."""
    system, modes, phase, t, x0 = _case(name)
    assert python_controller(phase.controller)
    pipe = Pipeline(system, modes, phase)
    assert pipe.python_stages == [f"controller {phase.controller.name!r} is a Python stage "
                                  f"({type(phase.controller).compiled_reason})"]
    xs = _states(x0)
    refs = np.array([interpreted_evaluate(system, t, x, modes, phase).xdot for x in xs])
    got = np.array([pipe.rhs(t, x.copy()) for x in xs])
    assert pipe.failed_calls == 0
    scale = 1.0 + np.abs(refs).max(axis=0)
    assert float((np.abs(got - refs) / scale).max()) <= RTOL
    if name != "fixture_free":
        assert np.abs(refs[:, system.nQ:2 * system.nQ]).max() > 0.0  # (something moves)


def test_the_fold_is_what_makes_the_force_reading_stage_agree():
    """The force PI law's measured force is a bonded row's: without the fold (its B columns at unit forces, the
    callback called once per row) the rates are off; with it they are the interpreted call's."""
    system, modes, phase, t, x0 = _case("force_pi_press")
    pipe = Pipeline(system, modes, phase)
    ref = interpreted_evaluate(system, t, x0, modes, phase).xdot
    assert np.abs(pipe.rhs(t, x0.copy()) - ref).max() <= RTOL * (1.0 + np.abs(ref).max())
    from contactdyn.model.pipeline.pack import READS_FORCES
    pipe.packed.ints[READS_FORCES] = 0  # no fold: τ at the forces before the solve
    assert np.abs(pipe.rhs(t, x0.copy()) - ref).max() > 1e-3 * (1.0 + np.abs(ref).max())


def test_the_control_input_is_the_interpreted_calls_field_by_field():
    """The ControlInput the compiled call's callback builds (its command sees it: recorded here) against the one the
    interpreted call gives the same controller at the same state: every field, each dictionary's keys in order and
    values."""
    system, modes, phase, t, x0 = _case("cart_push")
    seen = []
    ctl = phase.controller
    original = type(ctl).command
    ctl.command = lambda inp: (seen.append(inp), original(ctl, inp))[1]
    Pipeline(system, modes, phase).rhs(t, x0.copy())
    n_fast = len(seen)
    interpreted_evaluate(system, t, x0, modes, phase)
    del ctl.command
    fast, interpreted = seen[0], seen[n_fast]  # (each path's first call: then the carried reference's probe)
    assert n_fast > 1
    for name in (f.name for f in fields(fast)):
        a, b = getattr(fast, name), getattr(interpreted, name)
        if isinstance(b, dict):
            assert list(a) == list(b), name
            for key in b:
                np.testing.assert_allclose(np.ravel(a[key]), np.ravel(b[key]), rtol=1e-12, atol=1e-12,
                                           err_msg=f"{name}[{key}]")
        elif b is None:
            assert a is None, name
        else:
            np.testing.assert_allclose(a, b, rtol=1e-12, atol=1e-12, err_msg=name)
            assert np.shape(a) == np.shape(b), name
    assert fast.normals is system.force_directions
    assert set(fast.touching) == {c.name for c in system.contacts} and list(fast.surfaces) == ["tip", "tip.t1"]


def _both_ways(scene_of, monkeypatch):
    fast = simulate(scene_of())
    monkeypatch.setattr(LivePipelines, "use", False)
    return fast, simulate(scene_of())


@pytest.mark.parametrize("scene_of", [lambda: axis_scene("uncompilable_ctl"), lambda: force_pi_press(0.2),
                                      lambda: force_pi_press(0.1, sample_rate=1000.0), lambda: cart_push(1.2)],
                         ids=["fixture", "force_pi_press", "force_pi_press_sampled", "cart_push"])
def test_a_run_with_a_python_stage_controller_is_the_interpreted_run(scene_of, monkeypatch, uncompilable_controller):
    """Every mode on the compiled call (the controller's named as a Python stage), the run the interpreted run's."""
    fast, interpreted = _both_ways(scene_of, monkeypatch)
    assert any("is a Python stage (" in row["why"] and "controller '" in row["why"]
               for row in fast.stats["paths"].values())
    assert_runs_agree(fast, interpreted)


def test_the_controllers_own_error_surfaces_as_on_the_interpreted_call(monkeypatch):
    """Its exception, raised inside the compiled call, is kept and raised after it as the law's error (LawError: the
    law, its file and line, the time; the exception chained): the same as the interpreted call's, not a NaN, a status
    or ctypes' printout, nor counted as a call with no answer; a run raises it, compiled and interpreted."""
    system, modes, phase, x0 = prepare(axis_scene(Raising.name))
    pipe = Pipeline(system, modes, phase)
    np.testing.assert_allclose(pipe.rhs(0.005, x0.copy()),
                               interpreted_evaluate(system, 0.005, x0, modes, phase).xdot, rtol=1e-12, atol=1e-12)
    with pytest.raises(LawError) as fast:
        pipe.rhs(0.02, x0.copy())
    assert pipe.failed_calls == 0
    with pytest.raises(LawError) as interpreted:
        interpreted_evaluate(system, 0.02, x0, modes, phase)
    line = Raising.command.__code__.co_firstlineno + 2
    assert str(fast.value) == str(interpreted.value) == (
        f"t = 0.02 s: controller 'raising_ctl_test' (test_python_controller.py, line {line}) raised _ControllerFailed: "
        "the controller gave up at t > 0.01 s (gain 1.0)")
    assert type(fast.value.__cause__) is _ControllerFailed
    with pytest.raises(LawError, match="raised _ControllerFailed: the controller gave up"):
        simulate(axis_scene(Raising.name))
    monkeypatch.setattr(LivePipelines, "use", False)
    with pytest.raises(LawError, match="raised _ControllerFailed: the controller gave up"):
        simulate(axis_scene(Raising.name))


def test_a_sampled_laws_own_error_surfaces_at_the_sample_where_it_fails(monkeypatch):
    """A law run at samples (its own stage at each sample, hybrid.sampled_law) raises its own exception there,
    compiled and interpreted; one that gives a non-finite command is named with the time of that sample."""
    with pytest.raises(LawError, match=r"t = 0\.011 s: controller 'raising_ctl_test' .* gave up at t > 0.01 s"):
        simulate(axis_scene(Raising.name, sample_rate=1000.0))
    monkeypatch.setattr(LivePipelines, "use", False)
    with pytest.raises(LawError, match=r"t = 0\.011 s: controller 'raising_ctl_test' .* gave up at t > 0.01 s"):
        simulate(axis_scene(Raising.name, sample_rate=1000.0))
    monkeypatch.setattr(LivePipelines, "use", True)
    monkeypatch.setattr(Raising, "command", lambda self, inp: (np.full(len(inp.q), np.nan if inp.t > 0.01 else 0.0),
                                                               None))
    with pytest.raises(SimulationError, match=r"t = 0\.011 s: controller 'raising_ctl_test' "
                                              r"\(test_python_controller\.py\) gave no finite command: τ = \[nan\] "
                                              r"at q = \[\S+\], v = \[\S+\]"):
        simulate(axis_scene(Raising.name, sample_rate=1000.0))


def test_a_wrong_number_of_torques_raises_the_interpreted_calls_error(monkeypatch):
    """τ of the wrong length: the law named, with what it must return and what it gave, on either path (before:
    numpy's broadcast error)."""
    monkeypatch.setattr(Raising, "command", lambda self, inp: (np.zeros(2), None))
    system, modes, phase, x0 = prepare(axis_scene(Raising.name))
    said = r"controller 'raising_ctl_test': its command must return \(τ, ż\): τ 1 numbers .* τ of shape \(2,\)"
    with pytest.raises(SimulationError, match=said) as fast:
        Pipeline(system, modes, phase).rhs(0.0, x0.copy())
    with pytest.raises(SimulationError, match=said) as interpreted:
        interpreted_evaluate(system, 0.0, x0, modes, phase)
    assert str(fast.value) == str(interpreted.value)


def test_the_python_stage_keys_rebuild_the_dictionaries():
    """control_input on a buffer written by hand: the dictionaries by key in ControlInput's order (forces:
    the contacts, then the chains; surfaces: per contact then its chains), None where a field is empty."""
    nv = 2
    keys = controller_abi.InputKeys(("a", "a.t1", "b"), ("a", "b"), ("a.t1",), {"a.t1": np.ones(3)}, True)
    layout = controller_abi.layout_of(nv, 0, ("gravity", "x_d", "v_d", "a_d"), 1, 3, 3)
    buf = np.arange(layout[-1], dtype=float)
    inp = controller_abi.control_input(buf, layout, keys)
    rows = buf[layout[3 + 2 * controller_abi.FIELD["keys"]]:layout[-1]].reshape(3, controller_abi.KEY_W)
    assert list(inp.forces) == ["a", "b", "a.t1"] and inp.forces["a.t1"] == rows[1, 0]
    assert list(inp.surfaces) == ["a", "a.t1", "b"] and np.array_equal(inp.surfaces["b"][1], rows[2, 5:8])
    assert inp.touching == {"a": True, "b": True} and inp.gravity is None and inp.x_d is None
    assert inp.force_d == {"a.t1": (inp.force_set[0], inp.force_rate[0])} and inp.H.shape == (nv, nv)


@pytest.mark.parametrize("scene_of", [lambda: force_pi_press(0.2), lambda: cart_push(1.2)],
                         ids=["force_pi_press", "cart_push"])
def test_an_interpreted_run_of_a_python_stage_controller_is_the_compiled_run(scene_of):
    """A scene kind's first run (the call interpreted, contactdyn.numerics.twins) with a controller that reads the
    ControlInput's dictionaries: the compiled run bit for bit."""
    fast, first = simulate(scene_of()), simulate(scene_of(), interpreted=True)
    assert set(first.channels) == set(fast.channels)
    for key, values in fast.channels.items():
        assert np.array_equal(np.asarray(first.channels[key]), np.asarray(values), equal_nan=True), key
