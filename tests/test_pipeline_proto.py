"""Issue 29's prototype pipeline (contactdyn/model/pipeline/): the compiled call gives the same ẋ and event values
as the interpreted call (the same functions run as Python: ``run_agreement.interpreted_evaluate``), and as the same
source under NUMBA_DISABLE_JIT=1, on every in-scope case of benchmarks/pipeline_proto.py, at its mode's start and at
random states near it."""

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
from pipeline_proto import CASES, agreement, case, states  # noqa: E402
from run_agreement import interpreted_evaluate  # noqa: E402

from contactdyn.model.pipeline.pipeline import Pipeline  # noqa: E402

pytestmark = pytest.mark.usefixtures("user_laws_after_module")  # (its cases import the examples' laws)

#: ‖ẋ − ẋ_interpreted‖∞ ≤ RTOL ‖ẋ_interpreted‖∞ (the bound the readable model, another order of the arithmetic, was
#: held to; the interpreted call does the compiled call's operations: measured bit for bit on every case, 4 states)
RTOL = 1e-12


@pytest.mark.parametrize("name", list(CASES))
def test_the_pipeline_gives_the_interpreted_rates(name):
    system, modes, phase, t, x0 = case(name)
    pipe = Pipeline(system, modes, phase)
    worst, _ = agreement(pipe, system, modes, phase, t, states(x0, 4))
    assert worst <= RTOL
    assert pipe.failed_calls == 0


@pytest.mark.parametrize("name", ["b1", "writer_rigid_stick", "b1_limit", "cart_chains_touch", "hard_stiff",
                                  "force_loop_hybrid", "force_pi_press", "case3b_force_press_clip", "cart_push",
                                  "cart_push_apart_clip"])
def test_the_event_values_are_the_interpreted_ones(name):
    system, modes, phase, t, x0 = case(name)
    pipe = Pipeline(system, modes, phase)
    x = states(x0, 2)[1]
    pipe.rhs(t, x)
    got, ev = pipe.values(), interpreted_evaluate(system, t, x, modes, phase)
    for c in system.contacts:
        scale = 1.0 + abs(ev.normal_force[c.name])
        assert got[c.name]["F_n"] == pytest.approx(ev.normal_force[c.name], abs=RTOL * scale)
        assert got[c.name]["gap"] == pytest.approx(ev.gap[c.name], abs=1e-15)
        nt = len(c.tangents) if c.friction is not None else 0
        if nt:
            np.testing.assert_allclose(got[c.name]["v_t"][:nt], ev.slip[c.name], rtol=0, atol=1e-14)
            np.testing.assert_allclose(got[c.name]["F_f"][:nt], ev.friction[c.name], rtol=0, atol=RTOL * scale)
    for i, torque in got["limit"].items():
        assert torque == pytest.approx(ev.limit_torque[i], abs=RTOL * (1.0 + abs(ev.limit_torque[i])))


@pytest.mark.parametrize("name", ["force_pi_press", "force_loop_hybrid", "b1_force_dynamic"])
def test_the_fold_is_what_makes_a_force_reading_law_agree(name):
    """The law's columns B (τ = τ₀ + B λ) and D (ż = ż₀ + D λ) at unit forces, folded into the solve: without them
    the measured force is the one before the solve and the rates are far off."""
    from contactdyn.model.pipeline.pack import READS_FORCES

    system, modes, phase, t, x0 = case(name)
    pipe = Pipeline(system, modes, phase)
    x = states(x0, 2)[1]
    ref = interpreted_evaluate(system, t, x, modes, phase).xdot
    assert np.abs(pipe.rhs(t, x) - ref).max() <= RTOL * np.abs(ref).max()
    pipe.packed.ints[READS_FORCES] = 0
    assert np.abs(pipe.rhs(t, x) - ref).max() > 1e-3 * np.abs(ref).max()


@pytest.mark.parametrize("name", ["case3b_force_press_clip", "cart_push_apart_clip"])
def test_through_motors_the_drives_are_the_interpreted_ones(name):
    """A force-reading law through an elastic drive whose voltage clips after the fold (case 3 b's press at 10 V: the
    clips' re-check), and A7 through DC motors with the reference carried by the cart (its column folded), one
    joint clipping at some states: per drive the applied force, voltage and clip of the interpreted call's full
    command, and its command τ."""
    from contactdyn.model.pipeline.pack import D_CMD, W_DIAG, diag_starts

    system, modes, phase, t, x0 = case(name)
    pipe = Pipeline(system, modes, phase)
    p = pipe.packed
    clipped = 0
    for x in states(x0, 8):
        ev = interpreted_evaluate(system, t, x, modes, phase)
        p.work[p.ints[W_DIAG]] = 1.0  # the diagnostics on: the command τ recorded
        pipe.rhs(t, x)
        p.work[p.ints[W_DIAG]] = 0.0
        d = pipe.values()["drives"]
        scale = np.abs(ev.tau).max()
        np.testing.assert_allclose(d["applied"][:system.nv], ev.tau, rtol=0, atol=RTOL * scale)
        np.testing.assert_allclose(d["u"], ev.u, rtol=0, atol=RTOL * np.abs(ev.u).max())
        at = diag_starts(p.ints)[D_CMD]
        np.testing.assert_allclose(p.work[at:at + system.nv], ev.tau_cmd, rtol=0,
                                   atol=RTOL * np.abs(ev.tau_cmd).max())
        clipped += int(d["clipped"].any())
    assert clipped > 0  # the case reaches the clip


def test_the_carried_column_is_what_makes_the_push_agree():
    """case1_cart's push apart: A7 reads a_d, which the cart's acceleration moves (an unknown of the solve). The
    compiled call agrees with the interpreted call; its solve stage swapped for the one without a fold (the carried
    column b Q̈_b left out of the command, the reference still riding the cart) it is far from it."""
    from contactdyn.model.pipeline.pack import A_SOLVE, CARRIER, READS_FORCES
    from contactdyn.model.pipeline.pipeline import stage_addresses

    system, modes, phase, t, x0 = case("cart_push_apart")
    pipe = Pipeline(system, modes, phase)
    x = states(x0, 2)[1]
    ref = interpreted_evaluate(system, t, x, modes, phase).xdot
    assert np.abs(pipe.rhs(t, x) - ref).max() <= RTOL * np.abs(ref).max()
    ints = pipe.packed.ints
    folded, kept = ints[A_SOLVE], (ints[CARRIER], ints[READS_FORCES])
    ints[CARRIER], ints[READS_FORCES] = -1, 0
    stage_addresses(ints)  # (nothing folds: the solve stage solve_direct)
    ints[CARRIER], ints[READS_FORCES] = kept
    assert ints[A_SOLVE] != folded
    lagged = pipe.rhs(t, x)
    assert np.abs(lagged - ref).max() > 1e-6 * np.abs(ref).max()


def test_many_states_in_one_call_are_the_single_calls():
    from contactdyn.model.pipeline.pipeline import rates_at

    system, modes, phase, t, x0 = case("writer_rigid_stick")
    pipe = Pipeline(system, modes, phase)
    xs = states(x0, 3)
    p = pipe.packed
    batch, done = rates_at(np.full(3, t), np.array(xs), p.ints, p.reals, p.work, p.events)
    assert done == 3
    for x, row in zip(xs, batch, strict=True):
        assert np.array_equal(row, pipe.rhs(t, x))


def test_a_mode_out_of_scope_is_declined_with_its_reason(uncompilable_controller, monkeypatch):
    """A controller numba cannot compile packs (a declared Python stage, named); a mode the pipeline does not pack
    (here a robot whose terms rigid_body would not compute, made so) is declined, its reason named; a run's runner
    stops there with a SimulationError (compiled or interpreted: nothing else runs it instead)."""
    from contactdyn import parse_scene
    from contactdyn.errors import SimulationError
    from contactdyn.hybrid.pipeline_mode import mode_runner
    from contactdyn.robot.robot import Robot
    from contactdyn.simulate import prepare

    chain = {"model": "chain", "environment": [{"k": 5e4, "b": 1500.0}]}
    system, modes, phase, _ = prepare(parse_scene({
        "duration": 0.05, "robot": {"urdf": "cylindrical3", "active_joints": ["q3"], "q0": [0.999]},
        "contact": {"tip": {"point": [1.0, 0.0, 0.2], "normal": {"direction": [0, 0, 1], **chain}}},
        "controller": {"kind": uncompilable_controller.name}}))
    modes = [m.with_(touching=True) for m in modes]
    assert Pipeline(system, modes, phase).python_stages[0].startswith(
        "controller 'uncompilable_ctl' is a Python stage (numba cannot compile")
    monkeypatch.setattr(Robot, "rigid_table", property(lambda robot: None))
    with pytest.raises(ValueError, match="a robot rigid_body does not compute"):
        Pipeline(system, modes, phase)
    for compiled in (True, False):
        with pytest.raises(SimulationError, match="the model cannot run this mode: .*a robot rigid_body does not"):
            mode_runner(system, compiled=compiled)(modes, phase)


_INTERPRETED = """
import json, sys
sys.path.insert(0, {bench!r})
from pipeline_proto import case, states
from contactdyn.model.pipeline.pipeline import Pipeline
out = {{}}
for name in {names!r}:
    system, modes, phase, t, x0 = case(name)
    pipe = Pipeline(system, modes, phase)
    out[name] = [pipe.rhs(t, x).tolist() for x in states(x0, 2)]
print(json.dumps(out))
"""
#: interpreted and compiled agree bit for bit but where a law calls exp: numpy's (interpreted) and the C library's
#: (compiled) differ by an ulp in ~0.4 % of arguments (docs/one_source.md)
LIBM = {"b1_stribeck"}


def test_the_same_source_interpreted_gives_the_compiled_rates():
    """NUMBA_DISABLE_JIT=1: the pipeline's functions, the chains', the laws (stage, friction, the user's controllers,
    the built-in laws by address, the drive kinds: DC motors with a wheel and a clip, the elastic transmission; joint
    friction, a held command, a carried reference, a circle, a launch, the energy audit) all run as Python, the same
    source; ẋ equals the compiled call's bit for bit (and the interpreted call's in this process, the pipeline's
    twins)."""
    names = ["b1_stribeck", "writer_rigid_stick", "b1_limit", "cart_chains_touch", "cubic_press", "impedance_press",
             "cart_motors", "case3a_touch", "real_cell_clip", "writer_motors_voltage", "writer5dof_ops_write",
             "force_pi_press", "force_loop_hybrid", "b1_force_dynamic", "b1_position_dynamic", "b1_joint_pd",
             "b1_task_force", "case3b_force_press_clip", "cart_push_apart_clip", "case3a_force_press",
             "b1_joints_mixed", "b1_sampled", "cart_push_carried", "ur5_circle", "ur5_launch", "b1_energy"]
    env = {**os.environ, "NUMBA_DISABLE_JIT": "1", "PYTHONPATH": str(BENCH.parent)}
    done = subprocess.run([sys.executable, "-c", _INTERPRETED.format(bench=str(BENCH), names=names)], env=env,
                          capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr[-2000:]
    interpreted = json.loads(done.stdout.strip().splitlines()[-1])
    assert set(interpreted) == set(names)
    for name in names:
        system, modes, phase, t, x0 = case(name)
        pipe = Pipeline(system, modes, phase)
        for x, got in zip(states(x0, 2), interpreted[name], strict=True):
            compiled, ref = pipe.rhs(t, x), interpreted_evaluate(system, t, x, modes, phase).xdot
            if name in LIBM:
                assert np.abs(np.array(got) - compiled).max() <= 1e-15 * np.abs(compiled).max()
            else:
                assert np.array_equal(np.array(got), compiled), name
            assert np.abs(np.array(got) - ref).max() <= RTOL * np.abs(ref).max()
