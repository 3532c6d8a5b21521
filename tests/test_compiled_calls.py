"""The one pipeline's compiled call (contactdyn.model.pipeline) at the states a run passes through equals the same
call interpreted (run_agreement.interpreted_evaluate), on modes the per-call cases of tests/test_pipeline_proto.py do
not hold: the hybrid law, a redundant arm's null-space damping, a clipping voltage, the writers' stick, launch and
slide, a 1-D slide; and the packed reference and force set-points are the laws' own (Reference.at, Ramp.at)
bitwise."""

from __future__ import annotations

import sys
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "benchmarks"))
from pipeline_proto import case  # noqa: E402
from run_agreement import interpreted_evaluate  # noqa: E402
from test_controllers import hybrid_doc  # noqa: E402
from test_output_samples import pressing_writer  # noqa: E402

from contactdyn import Robot, parse_scene  # noqa: E402
from contactdyn.hybrid.loop import HybridRun  # noqa: E402
from contactdyn.hybrid.pipeline_mode import PipelineMode  # noqa: E402
from contactdyn.laws.trajectory import Move, Ramp, Reference  # noqa: E402
from contactdyn.model.phases import start_phase  # noqa: E402
from contactdyn.model.pipeline.actuation import reference, set_points  # noqa: E402
from contactdyn.model.pipeline.pipeline import Pipeline, call  # noqa: E402
from contactdyn.model.system import System  # noqa: E402
from contactdyn.scene.reader import read_toml  # noqa: E402
from contactdyn.scene.scene_file import find_scene, load_scene  # noqa: E402
from contactdyn.simulate import prepare  # noqa: E402

#: a compiled call against the interpreted call (interpreted_evaluate) at a run's states, relative to 1 + |ẋ|'s
#: largest entry (the bound the deleted twin's tests held); measured 0 (bit for bit) over these scenes' states
CALL_RTOL = 1e-10


def assert_calls_are_the_interpreted_call(scene, per_segment: int = 6) -> tuple:
    """Run ``scene``; at ``per_segment`` states along each segment (its dense output) the segment's pipeline call
    answers (status 1: an answer, not NaN rates) and its ẋ is the interpreted call's (interpreted_evaluate). Every
    segment on the pipeline's compiled call. Returns (the system, the run's segments)."""
    system = System(scene)
    run = HybridRun(system)
    run.run(0.0)
    assert run.segments
    for seg in run.segments:
        assert isinstance(seg.runner, PipelineMode) and not seg.runner.interpreted  # on the compiled call
        seg.runner.use(seg.modes)
        p = seg.runner.pipe.packed
        for t in np.linspace(seg.t0, seg.t1, per_segment):
            x = seg.sol(t)
            got = call(float(t), x.copy(), p.ints, p.reals, p.work, p.events)
            assert p.events[-1] == 1.0, (seg.modes, t)
            ref = interpreted_evaluate(system, float(t), x, seg.modes, seg.phase).xdot
            assert np.abs(got - ref).max() <= CALL_RTOL * (1.0 + np.abs(ref).max()), (seg.modes, t)
    return system, run.segments


@pytest.mark.parametrize("cancel", ["target", "measured"])
def test_the_hybrid_law_through_motors(cancel):
    """The hybrid law on the 2-DOF writer pressing case 2's (b) surface through DC motors: with cancel = "target"
    its tip force f_swap = (F − F*) n goes into τ by Jᵀ, with "measured" it does not."""
    assert_calls_are_the_interpreted_call(parse_scene(hybrid_doc(cancel=cancel), {"duration": 0.3}))


@pytest.mark.parametrize("u_max", [None, 4.0])
def test_a7_pressing_a_bonded_wall_through_motors_clipped_or_not(u_max):
    """A7 on the 2-DOF writer pressing a bonded wall (its measured force folded into the solve) under DC motors;
    with a 4 V limit the voltages clip at the start (the clip re-checked with the fold, in the call)."""
    system, segments = assert_calls_are_the_interpreted_call(parse_scene(pressing_writer(u_max=u_max)))
    if u_max is not None:
        seg = segments[0]
        ev = interpreted_evaluate(system, seg.t0, seg.sol(seg.t0), seg.modes, seg.phase)
        assert np.abs(ev.u).max() == u_max  # [V] the clipping branch ran


def test_a7_on_a_redundant_arm():
    """A7 on the 5-DOF writer (J⁺ of a 3×5 Jacobian, the null-space damping k_null) pressing a bonded wall under DC
    motors with the rotors taken out of H (``inertia = "link"``)."""
    q0 = [0.3, 0.678629948129, 1.834747110377, 0.428215595084, 0.0]  # [rad] sims/case2_writer5dof's pose
    p0 = Robot.load("writer5dof").frame_position(np.array(q0), "tip")
    drive = {"kind": "dc_motor", "R": 0.272, "C_M": 0.061, "J": 0.000452, "N": 160.0, "N_star": 65.12}
    doc = {"duration": 0.2, "robot": {"urdf": "writer5dof", "tip": "tip", "q0": q0, "drive": drive},
           "controller": {"kind": "position_dynamic", "kp": 400.0, "kv": 40.0, "k_null": 5.0, "inertia": "link"},
           "phase": [{"name": "main", "reference": {"space": "task", "start": (p0 + [0.005, 0.0, -0.01]).tolist(),
                                                    "moves": []}}],
           "contact": {"c": {"point": p0.tolist(), "bonded": True,
                             "normal": {"direction": [-1, 0, 0], "model": "b", "k": 1e4, "b": 10.0, "m": 2.0}}}}
    assert_calls_are_the_interpreted_call(parse_scene(doc))


@pytest.mark.parametrize("name", ["case2_writer5dof", "case2_writer_ur5"])
def test_the_operational_law_on_the_writers_stuck_launching_and_sliding(name):
    """The operational_space law with the pencil stuck (press), launched from rest and sliding in 2-D (circle)."""
    _, segments = assert_calls_are_the_interpreted_call(load_scene(name, {"duration": 1.6}))
    kinds = {(m.stuck, m.from_rest) for seg in segments for m in seg.modes if m.touching}
    assert kinds == {(True, False), (False, True), (False, False)}  # stuck, launching, sliding


def test_the_operational_law_on_a_1d_slide():
    """The 5-DOF writer with 1-D friction along x drawing a line: the pencil stuck, then sliding along its one
    tangent (the 1-D friction force −μ F d plus the viscous force, d the mode's fixed direction)."""
    doc = read_toml(find_scene("case2_writer5dof"))
    doc["duration"] = 1.0
    doc["contact"]["pencil"]["tangent"]["directions"] = [[1.0, 0.0, 0.0]]
    doc["phase"][1]["reference"]["moves"] = [{"kind": "trapezoid", "delta": [0.02, 0.0, 0.0], "duration": 0.4}]
    _, segments = assert_calls_are_the_interpreted_call(parse_scene(doc))
    assert {m.stuck for seg in segments for m in seg.modes if m.touching} == {True, False}


def test_the_packed_reference_is_reference_at_bitwise():
    """The pipeline's reference (the moves' table in ``reals``) equals Reference.at bitwise (the same sums in the
    same order) for 1–3 moves of every non-circle kind, before, during and after them (a circle's:
    tests/test_pipeline_rows.py)."""
    system, modes, phase, _, _ = case("writer5dof_ops")
    rng = np.random.default_rng(0)
    kinds = ["trapezoid", "triangle", "velocity_ramp", "constant_velocity", "step", "exponential"]
    for _ in range(20):
        moves = tuple(Move(rng.normal(size=3), float(rng.uniform(0, 2)), float(rng.uniform(0.1, 2)),
                           kinds[rng.integers(len(kinds))], float(rng.uniform(0.05, 0.5)))
                      for _ in range(rng.integers(1, 4)))
        ref = Reference(rng.normal(size=3), moves)
        p = Pipeline(system, modes, replace(phase, reference=ref)).packed
        for t in np.linspace(-1.0, 5.0, 61):
            for got, want in zip(reference(t, p.ints, p.reals), ref.at(t), strict=True):
                assert np.array_equal(got, want), t


def test_the_packed_set_points_are_ramp_at_bitwise():
    """The pipeline's force set-points (F_d [N], Ḟ_d [N/s]) equal each Ramp.at's bitwise, for every ramp kind,
    before, inside and after the ramp and at its corners."""
    system, modes, phase, _, _ = case("force_loop_hybrid")
    key = next(iter(phase.forces))
    ramps = (Ramp(100.0, 0.1, 0.2, "exponential"), Ramp(-5.0, 0.3, 0.5, "linear", 2.0), Ramp(7.0, 0.2, 0.1, "step"))
    for ramp in ramps:
        p = Pipeline(system, modes, replace(phase, forces={key: ramp})).packed
        for t in np.concatenate([np.linspace(-0.5, 3.0, 36), np.ravel(ramp.corners())]):
            F_d, _, rate = set_points(float(t), p.ints, p.reals)
            assert (F_d[0], rate[0]) == tuple(ramp.at(float(t))), t


@pytest.mark.parametrize("scene", ["case3_a_position", "case3_b_force"])  # position_dynamic; force_dynamic, a row
def test_a_force_reading_law_is_folded_into_the_call_as_in_the_interpreted_call(scene):
    """The press phase's law reads the measured force (folded into the KKT solve): at states near the start, every
    contact touching, the compiled call is the interpreted call's (interpreted_evaluate) to 1e-12 of 1 + |ẋ| (measured
    0: bit for bit), every call with an answer."""
    system, modes, phase, x0 = prepare(load_scene(scene))
    press = start_phase(system, 1, 0.0, x0, phase)
    assert press.controller.uses_forces
    touching = [replace(m, touching=True) for m in modes]
    pipe = Pipeline(system, touching, press)
    rng = np.random.default_rng(5)
    for k in range(3):
        t, x = 0.02 * k, x0 + 1e-3 * rng.normal(size=system.n)
        ref = interpreted_evaluate(system, t, x, touching, press).xdot
        assert np.abs(pipe.rhs(t, x) - ref).max() <= 1e-12 * (1.0 + np.abs(ref).max())
    assert pipe.failed_calls == 0
