"""A law numba cannot compile runs inside the compiled call as a declared Python stage (issue 29 item 2): a ctypes
callback of its Python function where its cfunc's address would be (contactdyn.laws.abi), the mode on the compiled
call, the law named in ``stats["paths"]``, its own exception surfacing as it does on the interpreted run."""

from __future__ import annotations

import copy
import tomllib
import warnings

import numpy as np
import pytest
from run_agreement import interpreted_evaluate

from contactdyn import parse_scene, simulate
from contactdyn.laws import abi
from contactdyn.laws.failures import LawError
from contactdyn.laws.friction_laws import FRICTION_LAWS, FrictionLaw, Stribeck, register_friction_law
from contactdyn.model.paths import INTERPRETED, PIPELINE, slower_paths
from contactdyn.model.pipeline.pipeline import Pipeline
from contactdyn.scene.scene_file import sims_dir
from contactdyn.simulate import prepare

K, B = 5e4, 1500.0  #: [N/m], [N·s/m]
_LIMIT = {"x": 1e-4}  #: a Python dict: the raising law does not compile either


def _fall(law: str, duration: float = 0.05, **settings):
    """The cylindrical robot's vertical axis falling at 0.5 m/s onto a one-stage chain of ``law``, 1 mm below."""
    return parse_scene({
        "duration": duration, "solver": {"rtol": 1e-10, "atol": 1e-13, **settings},
        "robot": {"urdf": "cylindrical3", "active_joints": ["q3"], "gravity": [0.0, 0.0, 0.0], "q0": [0.999],
                  "v0": [0.5]},
        "contact": {"tip": {"point": [1.0, 0.0, 0.2], "normal": {
            "direction": [0, 0, 1], "model": "chain", "environment": [{"k": K, "b": B, "law": law}]}}},
        "controller": {"kind": "task_pd", "kp": 0.0, "kd": 0.0},
    })


def _bonded(law: str):
    """The axis on a chain anchor —[law]— mass —[linear]— surface, bonded, with the energy audit (each stage's
    force at ẋ = 0 asked too)."""
    chain = {"model": "chain", "environment": [{"k": K, "b": B, "law": law}, {"m": 2.0}, {"k": 2 * K, "b": 2 * B}]}
    return parse_scene({
        "duration": 0.01, "solver": {"rtol": 1e-10, "atol": 1e-13, "record_energy": True},
        "robot": {"urdf": "cylindrical3", "active_joints": ["q3"], "gravity": [0.0, 0.0, -9.81], "q0": [1.0],
                  "v0": [0.3]},
        "contact": {"tip": {"point": [1.0, 0.0, 0.2], "normal": {"direction": [0, 0, 1], **chain},
                            "bonded": True}},
        "controller": {"kind": "task_pd", "kp": 0.0, "kd": 0.0, "axes": [[1.0, 0.0, 0.0]]},
    })


@pytest.fixture
def affine_uncompilable(uncompilable_law, stage_law_registry):
    """The conftest's uncompilable law declared affine (F = k x + b ẋ, its coefficients k and b): the same chain
    structure as ``linear`` (a damped free end is a state of an affine law's chain only)."""
    class AffineUncompilable(uncompilable_law):
        name, affine = "uncompilable_affine", True

    return stage_law_registry(AffineUncompilable)


def test_an_uncompilable_stage_law_runs_in_the_compiled_call_as_the_linear_law(affine_uncompilable):
    """The whole run with the law as a Python stage is the run of the built-in linear law (to 1e-12 of each
    channel's largest value; measured bitwise equal), every mode on the compiled call, the touching one naming the
    law and numba's reason."""
    assert abi.stage_address(affine_uncompilable) == 0  # (numba cannot compile it)
    mine, linear = simulate(_fall(affine_uncompilable.name)), simulate(_fall("linear"))
    assert {row["path"] for row in mine.stats["paths"].values()} == {PIPELINE}
    why = mine.stats["paths"]["main: tip touching"]["why"]
    assert why.startswith("stage law 'uncompilable_affine' of tip.n is a Python stage (numba cannot compile"), why
    assert "_SCALE" in why
    assert mine.stats["paths"]["main: tip free"]["why"] == ""  # no stage acts before the touch
    assert len(mine["t"]) == len(linear["t"])
    for channel in ("q", "v", "contact.tip.F_n", "stage.tip.n.env1.F"):
        ref = np.asarray(linear[channel])
        np.testing.assert_allclose(mine[channel], ref, rtol=0, atol=1e-12 * np.abs(ref).max(), err_msg=channel)


def test_a_non_affine_python_stage_runs_on_the_compiled_call(uncompilable_law):
    """The conftest's law itself (not affine: its chain has one state fewer than linear's, so the steps differ):
    the compiled call, declared, and the linear law's run to the solver's tolerance (measured 7e-11)."""
    mine, linear = simulate(_fall(uncompilable_law.name)), simulate(_fall("linear"))
    assert {row["path"] for row in mine.stats["paths"].values()} == {PIPELINE}
    assert slower_paths(mine.stats["paths"]) == [
        f"main: tip touching: compiled call ({mine.stats['paths']['main: tip touching']['why']})"]
    ref = np.asarray(linear["contact.tip.F_n"])
    np.testing.assert_allclose(mine["contact.tip.F_n"], ref, rtol=0, atol=1e-9 * np.abs(ref).max())


def test_a_python_stage_modes_rates_are_the_interpreted_calls(uncompilable_law):
    """ẋ of the packed mode with a Python stage (and the energy audit, which asks each stage's force at ẋ = 0)
    equals the interpreted call's (run_agreement.interpreted_evaluate) at states around the start (to 1e-9)."""
    system, modes, phase, x0 = prepare(_bonded(uncompilable_law.name))
    pipe = Pipeline(system, modes, phase)
    assert [row.split(" (")[0] for row in pipe.python_stages] == ["stage law 'uncompilable' of tip.n is a Python stage"]
    rng = np.random.default_rng(3)
    for i in range(5):
        x = x0.copy()
        x[system.nv] += 1e-4 * i  # the mass [m]
        x[system.nQ] += 0.05 * i  # the axis' speed [m/s]
        x[:system.nQ] += 1e-5 * rng.normal(size=system.nQ) * (i > 0)
        want = interpreted_evaluate(system, 0.0, x.copy(), modes, phase).xdot
        got = pipe.rhs(0.0, x.copy())
        np.testing.assert_allclose(got, want, rtol=0, atol=1e-9 * (1.0 + np.abs(want).max()))
    assert pipe.failed_calls == 0


@pytest.fixture
def raising_law(stage_law_registry):
    """A linear law that raises ValueError past a compression of 0.1 mm (numba cannot compile it: a dict)."""
    from contactdyn.laws.stage_laws import StageLaw

    class Raising(StageLaw):
        name = "raising"

        @staticmethod
        def force(k, b, p, x, xdot):
            if x > _LIMIT["x"]:
                raise ValueError(f"raising law: compression {x} m past its limit")
            return k * x + b * xdot

    return stage_law_registry(Raising)


def test_a_python_stage_that_raises_surfaces_its_own_error(raising_law):
    """The law's ValueError, as the interpreted run raises it (the same message: the same state and time), named
    (LawError: the law, its file and line, the exception chained), not a NaN, a printed traceback or a fallback."""
    said = r"t = \S+ s: stage law 'raising' \(test_python_stages\.py, line \d+\) raised ValueError: raising law: " \
        r"compression .* past its limit"
    with pytest.raises(LawError, match=said) as compiled:
        simulate(_fall(raising_law.name))
    with pytest.raises(LawError, match=said) as interpreted:
        simulate(_fall(raising_law.name), compiled=False)
    assert str(compiled.value) == str(interpreted.value)
    assert type(compiled.value.__cause__) is ValueError
    assert abi._raised == []  # re-raised once, not kept for a later call


def test_a_python_stages_error_is_raised_by_the_pipelines_own_rhs(raising_law):
    system, modes, phase, x = prepare(_fall(raising_law.name))
    modes = [m.with_(touching=True) for m in modes]
    pipe = Pipeline(system, modes, phase)
    q0, x = x[0], x.copy()
    x[0] = q0 + 2e-3  # 1 mm past the surface: the stage compressed beyond the law's limit
    with pytest.raises(LawError, match="past its limit"):
        pipe.rhs(0.0, x)
    x[0] = q0 + 1.05e-3  # compressed 0.05 mm: a force
    assert np.all(np.isfinite(pipe.rhs(0.0, x))) and pipe.failed_calls == 0


# ---- a friction law numba cannot compile -----------------------------------------------------------------------
@pytest.fixture
def python_stribeck():
    """Stribeck's law given by ``kinetic(spec, speed)`` only (Python: not compiled), registered for the test."""
    class PythonStribeck(FrictionLaw):
        name, params = "python_stribeck", Stribeck.params

        @classmethod
        def kinetic(cls, spec, speed):
            return spec.mu_k + (spec.mu_s - spec.mu_k) * np.exp(-(speed / spec.params[0]) ** 2)

    register_friction_law(PythonStribeck)
    yield PythonStribeck
    FRICTION_LAWS.pop(PythonStribeck.name, None)


def _stribeck_b1(law: str) -> dict:
    doc = tomllib.loads((sims_dir() / "b1.toml").read_text())
    doc["contact"]["tip"]["tangent"] = {"model": "friction", "directions": [[1.0, 0.0, 0.0]], "law": law,
                                        "mu_s": 0.6, "mu_k": 0.4, "v_s": 0.1}
    doc["duration"] = 0.5
    return doc


def test_a_python_friction_law_runs_in_the_compiled_call(python_stribeck):
    """The sliding modes on the compiled call with μ(|v_t|) called back in Python, named; the run is the compiled
    Stribeck law's (to 1e-9 of the normal force: numpy's exp and the compiled one may differ in the last bit)."""
    assert abi.friction_address(python_stribeck) == 0
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        mine = simulate(parse_scene(copy.deepcopy(_stribeck_b1("python_stribeck")), file=str(sims_dir() / "b1.toml")))
        builtin = simulate(parse_scene(copy.deepcopy(_stribeck_b1("stribeck")), file=str(sims_dir() / "b1.toml")))
    paths = mine.stats["paths"]
    assert {row["path"] for row in paths.values()} == {PIPELINE} and INTERPRETED not in str(paths)
    sliding = [row["why"] for label, row in paths.items() if "sliding" in label]
    assert sliding
    assert all(why.startswith("friction law 'python_stribeck' of tip is a Python stage (") for why in sliding)
    assert all(row["why"] == "" for label, row in paths.items() if "sliding" not in label)
    assert list(paths) == list(builtin.stats["paths"])
    for channel in ("contact.tip.F_n", "contact.tip.F_f"):
        ref = np.asarray(builtin[channel])
        np.testing.assert_allclose(mine[channel], ref, rtol=0, atol=1e-9 * np.abs(ref).max(), err_msg=channel)
