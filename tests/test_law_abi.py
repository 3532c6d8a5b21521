"""Laws called by address (contactdyn.laws.abi): each law through its compiled C function equals its Python
function; a law numba cannot compile is declared and computed in Python; the chain calls its laws through the
addresses in its packed arrays, and the same chain code runs interpreted under NUMBA_DISABLE_JIT=1."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numba
import numpy as np
import pytest
from run_agreement import interpreted_evaluate

from contactdyn import parse_scene
from contactdyn.hybrid.pipeline_mode import PipelineMode, mode_runner
from contactdyn.laws import abi
from contactdyn.laws.failures import LawError
from contactdyn.laws.friction_laws import FRICTION_LAWS, Coulomb, FrictionLaw, FrictionSpec, Stribeck
from contactdyn.laws.stage_laws import STAGE_LAWS, HuntCrossley, Linear, StageLaw, register_stage_law
from contactdyn.model import chain_forces as cf
from contactdyn.model.pipeline.pack import CH_NS, CH_STAGES, I_CHAINS
from contactdyn.model.pipeline.pipeline import Pipeline
from contactdyn.simulate import prepare

ROOT = Path(__file__).resolve().parent.parent


def _cubic_law() -> type[StageLaw]:
    """examples/cubic_stage.py's law, left unregistered and its module forgotten, so a scene that imports
    ``cubic_stage`` registers it again (the registry is every test's: ``_registry``)."""
    saved = dict(STAGE_LAWS)
    sys.path.insert(0, str(ROOT / "examples"))
    try:
        from cubic_stage import Cubic
    finally:
        sys.path.remove(str(ROOT / "examples"))
        sys.modules.pop("cubic_stage", None)
        STAGE_LAWS.clear()
        STAGE_LAWS.update(saved)
    return Cubic


Cubic = _cubic_law()


@pytest.fixture(autouse=True)
def _registry():
    """The cubic law registered for a test's scenes, its module importable (numba imports a law's module to
    load its cached code); the registry, the path and the modules as they were afterwards."""
    saved = dict(STAGE_LAWS)
    register_stage_law(Cubic)
    sys.path.insert(0, str(ROOT / "examples"))
    yield
    sys.path.remove(str(ROOT / "examples"))
    sys.modules.pop("cubic_stage", None)
    STAGE_LAWS.clear()
    STAGE_LAWS.update(saved)

K, B = 1e5, 300.0  #: [N/m], [N·s/m]
XS = np.concatenate([-np.logspace(-6, -2, 7), [0.0], np.logspace(-7, -2, 11)])  #: compressions [m]
XDS = np.array([-1.0, -0.1, -1e-3, 0.0, 1e-3, 0.1, 1.0])  #: rates [m/s]
SPEEDS = np.concatenate([[0.0], np.logspace(-6, 1, 29)])  #: slip speeds [m/s]


@numba.njit(cache=True)
def _stage_grid(address, k, b, p, xs, xds, out):
    for i in range(xs.size):
        for j in range(xds.size):
            out[i, j] = abi.call_stage(address, k, b, p, 0, p.size, xs[i], xds[j])


@numba.njit(cache=True)
def _friction_grid(address, mu_s, mu_k, p, speeds, out):
    for i in range(speeds.size):
        out[i] = abi.call_friction(address, mu_s, mu_k, p, 0, p.size, speeds[i])


def _close(got: np.ndarray, want: np.ndarray, scale: np.ndarray | None = None) -> None:
    """|got − want| ≤ 1e-15 · scale (default |want|). A stage force's scale is the size of its terms,
    k|x| + b|ẋ| + |F|: numba forms x**3 as x·x·x where Python calls pow(), an ulp apart, which a sum of
    cancelling terms shows as more than 1e-15 of F."""
    scale = np.abs(want) if scale is None else scale
    assert np.all(np.abs(got - want) <= 1e-15 * scale), np.max(np.abs(got - want) / scale)


@pytest.mark.parametrize("law, p", [(Linear, ()), (HuntCrossley, (1.5,)), (HuntCrossley, (2.3,)), (Cubic, (1e9,))])
def test_a_stage_law_through_its_address_equals_its_python_function(law, p):
    address = abi.stage_address(law)
    assert address != 0 and law.compiled_reason == ""
    params = np.array(p, dtype=float)
    got = np.empty((XS.size, XDS.size))
    _stage_grid(address, K, B, params, XS, XDS, got)
    want = np.array([[law.force(K, B, p, x, xd) for xd in XDS] for x in XS])
    scale = K * np.abs(XS)[:, None] + B * np.abs(XDS)[None, :] + np.abs(want)
    _close(got, want, scale)
    if law is not Cubic:  # no integer power: the same operations, bit for bit
        np.testing.assert_array_equal(got, want)
    twin = np.array([[abi.call_stage(address, K, B, params, 0, len(p), x, xd) for xd in XDS] for x in XS])
    np.testing.assert_array_equal(twin, want)  # the plain-Python twin calls the law's own function


@pytest.mark.parametrize("law, p", [(Coulomb, ()), (Stribeck, (0.01,)), (Stribeck, (1e-9,))])
def test_a_friction_law_through_its_address_equals_its_kinetic_coefficient(law, p):
    address = abi.friction_address(law)
    assert address != 0 and law.compiled_reason == ""
    spec = FrictionSpec(0.6, 0.4, 0.0, law.name, p)
    got = np.empty(SPEEDS.size)
    _friction_grid(address, spec.mu_s, spec.mu_k, np.array(p, dtype=float), SPEEDS, got)
    _close(got, np.array([float(spec.mu(v)) for v in SPEEDS]))
    _close(got, spec.mu(SPEEDS))  # the law's Python function on an array of speeds, as the samples call it


def test_a_friction_law_given_by_kinetic_only_is_declared_python():
    class Old(FrictionLaw):
        name = "old_style"

        @staticmethod
        def kinetic(spec, speed):
            return spec.mu_k + 0.0 * speed

    assert abi.friction_address(Old) == 0
    assert "kinetic(spec, speed) only" in Old.compiled_reason


def _axis_scene(law: str, extra: dict | None = None):
    """The cylindrical robot's vertical axis on a chain anchor —[law]— mass —[linear]— surface, bonded."""
    inner = {"k": K, "b": B, "law": law, **(extra or {})}
    chain = {"model": "chain", "environment": [inner, {"m": 2.0}, {"k": 2 * K, "b": 2 * B}]}
    return parse_scene({
        "duration": 0.01, "solver": {"rtol": 1e-10, "atol": 1e-13},
        "robot": {"urdf": "cylindrical3", "active_joints": ["q3"], "gravity": [0.0, 0.0, -9.81], "q0": [1.0],
                  "v0": [0.3]},
        "contact": {"tip": {"point": [1.0, 0.0, 0.2], "normal": {"direction": [0, 0, 1], **chain},
                            "bonded": True}},
        "controller": {"kind": "task_pd", "kp": 0.0, "kd": 0.0, "axes": [[1.0, 0.0, 0.0]]},
    })


def _evaluations(law: str, extra: dict | None = None, states: int = 3):
    """(stages, xdot) of the model on the compiled call (``PipelineMode.evaluation``; under NUMBA_DISABLE_JIT=1 the
    same source interpreted) at the start and at states with the mass and the tip moved."""
    system, modes, phase, x = prepare(_axis_scene(law, extra))
    mode = mode_runner(system)(modes, phase)
    out = []
    for i in range(states):
        xi = x.copy()
        xi[system.nv] += 1e-4 * i  # the mass [m]
        xi[system.nQ] += 0.05 * i  # the axis' speed [m/s]
        ev = mode.evaluation(0.0, xi)
        out.append((dict(ev.stages), ev.xdot.copy()))
    return system, out


def test_a_law_numba_cannot_compile_is_declared_and_computed_in_python(uncompilable_law):
    assert abi.stage_address(uncompilable_law) == 0
    assert uncompilable_law.compiled_reason.startswith("numba cannot compile")
    assert "_SCALE" in uncompilable_law.compiled_reason
    system, got = _evaluations("uncompilable")
    c = system.contacts[0]
    arrays = cf.pack(system, c, c.normal, True, False)  # (the chain's plan touching, as the call packs it)
    assert [k for k, _ in arrays.python_stages] == [0]  # the stage of that law, and only it, in Python
    _, want = _evaluations("linear")
    for (stages, xdot), (stages_lin, xdot_lin) in zip(got, want, strict=True):
        assert list(stages.values()) == list(stages_lin.values())
        np.testing.assert_array_equal(xdot, xdot_lin)


def test_the_chain_calls_each_law_through_the_address_in_its_arrays():
    """The compiled call reads each stage's law from the chain's stage table packed into its ints: the two laws
    swapped there, each stage computes with the other's law (and its parameters)."""
    system, modes, phase, x = prepare(_axis_scene("cubic", {"k3": 1e12}))
    x[system.nv], x[system.nQ] = x[system.nv] + 1e-4, 0.05  # the mass moved [m], the axis moving [m/s]
    mode = PipelineMode(Pipeline(system, modes, phase))
    declared = mode.evaluation(0.0, x).stages
    ints = mode.pipe.packed.ints
    chain = ints[ints[I_CHAINS]:]  # (the one chain: the normal's)
    stages = ints[chain[CH_STAGES]:chain[CH_STAGES] + 7 * chain[CH_NS]].reshape(chain[CH_NS], 7)  # (a view)
    laws = stages[:, cf.S_LAW].copy()
    assert list(laws) == [abi.stage_address(Cubic), abi.stage_address(Linear)]
    law_columns = [cf.S_LAW, cf.S_PARAMS_AT, cf.S_N_PARAMS]  # a law's address and where its parameters are
    stages[:, law_columns] = stages[::-1, law_columns].copy()  # the two laws swapped in the table
    swapped = mode.evaluation(0.0, x).stages
    (x0, xd0, F0), (x1, xd1, F1) = swapped["tip.n.env1"], swapped["tip.n.env2"]
    assert x0 * x1 != 0.0  # both stages deformed
    assert F0 == Linear.force(K, B, (), x0, xd0)  # stage 1's k and b under the linear law
    assert F1 == Cubic.force(2 * K, 2 * B, (1e12,), x1, xd1)  # stage 2's under the cubic law, with stage 1's k3
    assert declared["tip.n.env1"][2] == Cubic.force(K, B, (1e12,), x0, xd0) != F0
    assert declared["tip.n.env2"][2] == Linear.force(2 * K, 2 * B, (), x1, xd1) != F1


_DISABLED = """
import json, sys
sys.path.insert(0, {examples!r})
sys.path.insert(0, {tests!r})
import numba
assert numba.config.DISABLE_JIT
from contactdyn.laws.stage_laws import register_stage_law
from test_law_abi import Cubic, _evaluations
register_stage_law(Cubic)
_, out = _evaluations({law!r}, {extra!r})
print(json.dumps([[list(s.items()), x.tolist()] for s, x in out]))
"""


@pytest.mark.parametrize("law, extra", [("cubic", {"k3": 1e12}), ("hunt_crossley", {"exponent": 1.5})])
def test_the_chain_runs_interpreted_under_numba_disable_jit(law, extra):
    code = _DISABLED.format(examples=str(ROOT / "examples"), tests=str(ROOT / "tests"), law=law, extra=extra)
    env = {**os.environ, "NUMBA_DISABLE_JIT": "1", "PYTHONPATH": str(ROOT)}
    done = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr[-2000:]
    interpreted = json.loads(done.stdout.splitlines()[-1])
    _, compiled = _evaluations(law, extra)
    for (stages, xdot), (stages_c, xdot_c) in zip(interpreted, compiled, strict=True):
        assert [(k, tuple(v)) for k, v in stages] == list(stages_c.items())
        assert xdot == xdot_c.tolist()


def test_registered_laws_compile():
    for law in STAGE_LAWS.values():
        assert abi.stage_address(law) != 0, law.compiled_reason
    for law in FRICTION_LAWS.values():
        assert abi.friction_address(law) != 0, law.compiled_reason


def test_a_pickled_chain_packs_again_in_its_new_process():
    import pickle

    from contactdyn.model.constraints import velocity_rows

    system, modes, phase, x = prepare(_axis_scene("hunt_crossley", {"exponent": 1.5}))
    assert modes[0].touching  # (bonded)
    system.robot.update(x[:system.nv], x[system.nQ:system.nQ + system.nv])
    velocity_rows(system, x, modes)  # (the bond's row: the chain's forces, its arrays packed and kept)
    dc = system.contacts[0].normal
    assert dc.arrays  # packed, with the laws' addresses of this process
    assert pickle.loads(pickle.dumps(dc)).arrays == {}  # another process would pack with its own


@pytest.fixture
def raising_law(stage_law_registry):
    """A law that raises its own error beyond 1 µm of compression, registered as ``raising``."""

    class Raising(StageLaw):
        name = "raising"

        @staticmethod
        def force(k, b, p, x, xdot):
            if x > 1e-6:
                raise ValueError("raising: compression beyond its range")
            return k * x + b * xdot

    return stage_law_registry(Raising)


def test_a_compiled_law_that_raises_raises_its_own_error_not_a_zero_force(raising_law):
    """The interpreted call raises the law's own error (its evaluation and its right-hand side); so does the compiled
    call, whose cfunc cannot carry it out (status -1): the call is run once more interpreted there
    (Pipeline.failed_call). Never a zero force."""
    assert abi.stage_address(raising_law)  # it compiles: numba compiles the raise
    system, modes, phase, x = prepare(_axis_scene("raising"))
    compiled, interpreted = (mode_runner(system, compiled=c)(modes, phase) for c in (True, False))
    interpreted_evaluate(system, 0.0, x, modes, phase)  # undeformed: a force
    assert np.all(np.isfinite(compiled.rhs(0.0, x.copy()))) and np.all(np.isfinite(interpreted.rhs(0.0, x.copy())))
    x[system.nv] -= 1e-4  # the mass moved down [m]: the law's stage compressed beyond its range
    with pytest.raises(ValueError, match="compression beyond its range"):
        interpreted_evaluate(system, 0.0, x, modes, phase)
    with pytest.raises(ValueError, match="compression beyond its range"):
        interpreted.rhs(0.0, x.copy())
    with pytest.raises(LawError, match=r"t = 0 s: stage law 'raising' \(test_law_abi\.py, line \d+\) raised "
                                       "ValueError: raising: compression beyond its range") as info:
        compiled.rhs(0.0, x.copy())  # (the law's error, named: its exception chained)
    assert type(info.value.__cause__) is ValueError


def _scaled_law(scale: float) -> type[StageLaw]:
    """A law made by a factory: its force reads ``scale`` from the factory's closure."""

    class Scaled(StageLaw):
        name = f"scaled_{scale:g}"

        @staticmethod
        def force(k, b, p, x, xdot):
            return scale * k * x

    return Scaled


def test_laws_made_by_one_factory_are_compiled_apart():
    """Same file, same qualified name, another closure: each law its own machine code (no cache shared)."""
    got = []
    for scale in (1.0, 2.0, 3.0):
        out = np.zeros((1, 1))
        _stage_grid(abi.stage_address(_scaled_law(scale)), 10.0, 0.0, np.zeros(0), np.ones(1), np.zeros(1), out)
        got.append(out[0, 0])
    assert got == [10.0, 20.0, 30.0]
