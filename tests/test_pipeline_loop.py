"""The one pipeline as a complete path of the hybrid loop (contactdyn/hybrid/pipeline_mode.py): its output samples equal
the interpreted call's at the same states, a run on it equals the same run interpreted (``LivePipelines.use`` off),
there is no readable model left to evaluate, and a call with no answer gives NaN rates (no other model behind it)."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

BENCH = Path(__file__).resolve().parent.parent / "benchmarks"
sys.path.insert(0, str(BENCH))
from pipeline_proto import CASES, case, states  # noqa: E402
from run_agreement import interpreted_evaluate, interpreted_samples  # noqa: E402

from contactdyn.errors import SimulationError  # noqa: E402
from contactdyn.hybrid.pipeline_mode import PipelineMode  # noqa: E402
from contactdyn.model import evaluation  # noqa: E402
from contactdyn.model.paths import INTERPRETED, PIPELINE, LivePipelines  # noqa: E402
from contactdyn.model.pipeline.pipeline import Pipeline  # noqa: E402
from contactdyn.model.system import System  # noqa: E402
from contactdyn.scene.scene_file import load_scene  # noqa: E402
from contactdyn.simulate import run_system  # noqa: E402

pytestmark = pytest.mark.usefixtures("user_laws_after_module")  # (its cases import the examples' laws)

ROOT = BENCH.parent
#: the samples' arrays of output.samples.Samples, per name (dicts by key)
FIELDS = ("tau", "tau_cmd", "limit_torque", "tip", "x_d", "body_force", "F_n", "gap", "F_d", "F_f", "v_slip", "iface",
          "stages")
#: the output samples' agreement with the interpreted call's at the same states, relative to each array's largest
#: magnitude: the call's own (≤ 1e-12, tests/test_pipeline_proto.py); measured 0 (bit for bit) over the cases
SAMPLES_RTOL = 1e-12
RUN_RTOL = 1e-9  #: a run on the pipeline against the interpreted run's: each channel, relative to its largest value
#: the runs' tolerances: the two right-hand sides differ by rounding, which the step control amplifies up to a fraction
#: of the tolerance (the rigid writer's v_slip at its own rtol: 4.3e-9 on this round's AMD EPYC, below 1e-9 on the
#: machine CI ran it on before); at these, ≤ 1.6e-11 (measured on the EPYC)
TIGHT = {"solver.rtol": 1e-11, "solver.atol": 1e-13}
EVENT_ATOL = 1e-9  #: [s] their events' times (measured ≤ 4e-11 s on these scenes)


def _arrays(S) -> dict[str, np.ndarray]:
    out = {}
    for name in FIELDS:
        value = getattr(S, name)
        for key, arr in (value.items() if isinstance(value, dict) else [("", value)]):
            out[f"{name}.{key}"] = np.asarray(arr, float)
    return out


def _worst(got: dict, ref: dict) -> tuple[float, str]:
    worst, where = 0.0, ""
    for key, r in ref.items():
        g = got[key]
        assert g.shape == r.shape, key
        assert np.array_equal(np.isnan(g), np.isnan(r)), key
        if not r.size or np.all(np.isnan(r)):
            continue
        d = float(np.nanmax(np.abs(g - r))) / max(float(np.nanmax(np.abs(r))), 1e-300)
        if d > worst:
            worst, where = d, key
    return worst, where


@pytest.mark.parametrize("name", list(CASES))
def test_the_output_samples_are_the_interpreted_ones(name):
    system, modes, phase, t, x0 = case(name)
    pm = PipelineMode(Pipeline(system, modes, phase))
    X = np.array(states(x0, 4))
    ts = t + np.linspace(0.0, 0.05, len(X))
    got, ref = _arrays(pm.samples(ts, X)), _arrays(interpreted_samples(system, ts, X, modes, phase))
    worst, where = _worst(got, ref)
    assert worst <= SAMPLES_RTOL, where
    assert pm.singular == 0


def _run(scene: str, duration: float, compiled: bool, monkeypatch):
    monkeypatch.setattr(LivePipelines, "use", compiled)
    return run_system(System(load_scene(ROOT / scene, {"duration": duration, **TIGHT})))


#: scenes whose every mode the pipeline packs, short (their events: touch, separate, stop, slip, stick)
SCENES = [("sims/b1.toml", 0.3), ("sims/case2_writer_rigid.toml", 1.5), ("benchmarks/hard/bounce.toml", 0.5),
          ("benchmarks/hard/stickslip.toml", 1.0), ("examples/impedance_press.toml", 0.2)]


@pytest.mark.parametrize("scene,duration", SCENES)
def test_a_run_on_the_pipeline_is_the_interpreted_run(scene, duration, monkeypatch):
    on, off = _run(scene, duration, True, monkeypatch), _run(scene, duration, False, monkeypatch)
    assert {row["path"] for row in on.stats["paths"].values()} == {PIPELINE}
    assert {row["path"] for row in off.stats["paths"].values()} == {INTERPRETED}
    assert set(on.channels) == set(off.channels)
    for key, ref in off.channels.items():
        ref, got = np.asarray(ref, float), np.asarray(on.channels[key], float)
        scale = float(np.nanmax(np.abs(ref))) if ref.size and not np.all(np.isnan(ref)) else 0.0
        assert np.nanmax(np.abs(got - ref), initial=0.0) <= RUN_RTOL * scale, key
    assert [(e["kind"], e["name"]) for e in on.events] == [(e["kind"], e["name"]) for e in off.events]
    np.testing.assert_allclose([e["t"] for e in on.events], [e["t"] for e in off.events], rtol=0, atol=EVENT_ATOL)


def test_a_pipeline_run_has_no_readable_model_to_evaluate(monkeypatch):
    """The readable model (evaluate) is gone: the segments integrate (their right-hand side, compiled steps,
    event values), sample and decide their transitions (PipelineMode.evaluation) on the one call, compiled: one
    source."""
    assert not hasattr(evaluation, "evaluate"), "the readable model (evaluate) is back"
    r = _run("benchmarks/hard/stickslip.toml", 1.0, True, monkeypatch)
    assert {row["path"] for row in r.stats["paths"].values()} == {PIPELINE}
    assert len(r.events) > 10 and r.stats["rhs_evals"] > 1000


EVENT_FIELDS = ("normal_force", "gap", "friction", "slip", "limit_torque", "joint_hold", "force_d", "interface",
                "node_positions")
ARRAY_FIELDS = ("xdot", "lam", "tau", "tau_cmd", "p_tip", "body_force", "joint_friction", "x_d")


def _stacked(named: dict[str, list]) -> dict[str, np.ndarray]:
    return {k: np.array(v, float) for k, v in named.items()}


@pytest.mark.parametrize("name", list(CASES))
def test_an_instants_evaluation_off_the_call_is_the_interpreted_calls(name):
    """PipelineMode.evaluation (what the transitions decide on) against the interpreted call's at the same states: ẋ,
    λ, the event values by name, τ, the command, the tip, the stage states, each to SAMPLES_RTOL of its largest
    magnitude over the states (the same names present on both; None on both or neither)."""
    system, modes, phase, t, x0 = case(name)
    pm = PipelineMode(Pipeline(system, modes, phase))
    got, ref = {}, {}
    for x in states(x0, 3):
        mine, theirs = pm.evaluation(t, x), interpreted_evaluate(system, t, x, modes, phase)
        assert mine.stages.keys() == theirs.stages.keys()
        for f in ARRAY_FIELDS:
            a, b = getattr(mine, f), getattr(theirs, f)
            assert (a is None) == (b is None), f
            if b is not None:
                got.setdefault(f, []).append(a)
                ref.setdefault(f, []).append(b)
        for f in (*EVENT_FIELDS, "stages"):
            a, b = getattr(mine, f), getattr(theirs, f)
            assert f == "stages" or set(a) == set(b), f
            for k, value in b.items():
                got.setdefault(f"{f}.{k}", []).append(a.get(k, (0.0, 0.0, 0.0)))
                ref.setdefault(f"{f}.{k}", []).append(value)
    worst, where = _worst(_stacked(got), _stacked(ref))
    assert worst <= SAMPLES_RTOL, where


_INTERPRETED = """
import json, sys
import numpy as np
sys.path.insert(0, {bench!r})
from pipeline_proto import case, states
from contactdyn.model.pipeline.pipeline import Pipeline, samples_at
out = {{}}
for name in {names!r}:
    system, modes, phase, t, x0 = case(name)
    p = Pipeline(system, modes, phase).packed
    X = np.array(states(x0, 2))
    Xd, E, W, done = samples_at(t + np.arange(2) * 0.01, X, p.ints, p.reals, p.work, p.events)
    out[name] = [Xd.tolist(), E.tolist(), W.tolist(), int(done)]
print(json.dumps(out))
"""


def test_the_diagnostics_interpreted_are_the_compiled_ones():
    """NUMBA_DISABLE_JIT=1: samples_at's rates, event values and work (the diagnostics section) bit for bit."""
    names = ["writer_rigid_stick", "b1_limit", "impedance_press"]
    env = {**os.environ, "NUMBA_DISABLE_JIT": "1", "PYTHONPATH": str(ROOT)}
    done = subprocess.run([sys.executable, "-c", _INTERPRETED.format(bench=str(BENCH), names=names)], env=env,
                          capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr[-2000:]
    interpreted = json.loads(done.stdout.strip().splitlines()[-1])
    from contactdyn.model.pipeline.pipeline import samples_at
    for name in names:
        system, modes, phase, t, x0 = case(name)
        p = Pipeline(system, modes, phase).packed
        got = samples_at(t + np.arange(2) * 0.01, np.array(states(x0, 2)), p.ints, p.reals, p.work, p.events)
        for a, b in zip(got[:3], interpreted[name][:3], strict=True):
            assert np.array_equal(a, np.array(b)), name
        assert got[3] == interpreted[name][3] == 2


@pytest.mark.parametrize("name", ["writer_rigid_stick", "b1_limit", "writer5dof_tool_slide", "b1_joints_mixed",
                                  "b1_joints_limit"])
def test_a_call_with_no_answer_gives_nan_rates_and_no_evaluation(name):
    """A call whose status is not 1 (its contact system not finite: velocities of 1e300 overflow it) is answered by
    no other model: NaN rates (which the step control rejects), counted in ``failed_calls``, its status in the ring;
    an instant's evaluation there raises. The same mode at a finite state answers again."""
    system, modes, phase, t, x0 = case(name)
    pm = PipelineMode(Pipeline(system, modes, phase))
    x = np.array(states(x0, 2)[1], float)
    assert np.all(np.isfinite(pm.rhs(t, x))) and pm.pipe.failed_calls == 0
    bad = x.copy()
    bad[system.nQ:] = 1e300
    assert np.all(np.isnan(pm.rhs(t, bad))) and pm.pipe.failed_calls == 1
    assert pm.values(t, bad)[-1] != 1.0  # (the call's own status: no other model's values put in its place)
    with pytest.raises(SimulationError, match="no finite answer at this state"):
        pm.evaluation(t, bad)
    assert np.all(np.isfinite(pm.rhs(t, x))) and pm.values(t, x)[-1] == 1.0
