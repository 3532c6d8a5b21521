"""Issue 29's pipeline, the small mode kinds (contactdyn/model/pipeline/): joint friction, a held sampled command,
a reference carried by a body, a circle move, a 2-D slide launching from rest, the energy audit. Their ẋ against
the interpreted call (run_agreement.interpreted_evaluate) is test_pipeline_proto's (every case of
benchmarks/pipeline_proto.py); here: their event values against the interpreted call's, and what each kind
changes."""

from __future__ import annotations

import sys
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

BENCH = Path(__file__).resolve().parent.parent / "benchmarks"
sys.path.insert(0, str(BENCH))
from pipeline_proto import case, states  # noqa: E402
from run_agreement import interpreted_evaluate  # noqa: E402

from contactdyn.model.pipeline.pipeline import Pipeline  # noqa: E402

RTOL = 1e-12  #: as test_pipeline_proto's: measured ≤ 2e-15 on these cases


@pytest.mark.parametrize("name", ["b1_joints_stuck", "b1_joints_mixed", "b1_joints_limit", "b1_joints_slide",
                                  "b1_sampled_joints"])
def test_the_joints_event_values_are_the_interpreted_ones(name):
    """Holding torques of the stuck joints (none for a joint on its limit: the limit's row holds it), the sliding
    joints' speeds, the limits' torques."""
    system, modes, phase, t, x0 = case(name)
    pipe = Pipeline(system, modes, phase)
    for x in states(x0, 3):
        pipe.rhs(t, x)
        got, ev = pipe.values(), interpreted_evaluate(system, t, x, modes, phase)
        assert set(got["joint_hold"]) == set(ev.joint_hold)
        for i, hold in ev.joint_hold.items():
            assert got["joint_hold"][i] == pytest.approx(hold, abs=RTOL * (1.0 + abs(hold)))
        assert got["joint_speed"] == {i: x[system.nQ + i] for i, m in phase.joint_modes if m != 0}
        for i, torque in ev.limit_torque.items():
            assert got["limit"][i] == pytest.approx(torque, abs=RTOL * (1.0 + abs(torque)))
    assert pipe.failed_calls == 0


def test_a_sampled_law_acts_by_its_held_command():
    """τ is the state's held slots (SampledController.command): another held command gives another Q̈, the
    interpreted call's; the held slots' rates stay 0."""
    system, modes, phase, t, x0 = case("b1_sampled")
    pipe = Pipeline(system, modes, phase)
    nQ, nv = system.nQ, system.nv
    held = 2 * nQ + phase.z_slice.start + phase.controller.held.start
    x = x0.copy()
    x[held:held + nv] = 0.0
    base = pipe.rhs(t, x)
    x[held] = 1.0  # 1 N·m more on joint 0
    more = pipe.rhs(t, x)
    assert np.all(more[2 * nQ + phase.z_slice.start:][:nv] == 0.0)
    assert np.abs(more[nQ:2 * nQ] - base[nQ:2 * nQ]).max() > 1e-3
    ev = interpreted_evaluate(system, t, x, modes, phase)
    assert np.allclose(more[nQ:2 * nQ], ev.xdot[nQ:2 * nQ], rtol=0, atol=RTOL * np.abs(ev.xdot).max())


def test_a_joint_on_its_limit_has_no_stuck_row():
    system, modes, phase, _, _ = case("b1_joints_limit")
    kinds = [(kind, i) for _, kind, i in Pipeline(system, modes, phase).packed.row_meta]
    assert kinds[-2:] == [("limit", 1), ("joint", 0)]


def test_the_carried_reference_rides_on_the_cart():
    """case1_cart's push under task PD: the reference carried by the cart (x_d += axis Q_b, v_d += axis Q̇_b) gives
    the interpreted call's rates; the same mode with the carrier dropped from the packed arrays does not."""
    from contactdyn.model.pipeline.pack import CARRIER

    system, modes, phase, t, x0 = case("cart_push_carried")
    assert phase.carrier is not None
    pipe = Pipeline(system, modes, phase)
    ref = interpreted_evaluate(system, t, x0, modes, phase).xdot
    assert np.abs(pipe.rhs(t, x0) - ref).max() <= RTOL * np.abs(ref).max()
    pipe.packed.ints[CARRIER] = -1
    assert np.abs(pipe.rhs(t, x0) - ref).max() > 1e-3 * np.abs(ref).max()


def test_a_carried_reference_for_a_law_that_reads_its_acceleration_runs_folded():
    """case1_cart's push without motors, apart: A7 reads a_d (once declined: its carried column was not packed);
    now packed and folded (force_fold's column at a_d + axis), the rates the interpreted call's."""
    from pipeline_proto import _scene, states

    from contactdyn.model.pipeline.pack import unsupported
    from contactdyn.simulate import prepare

    def no_motors(doc):
        del doc["robot"]["drive"], doc["body"]["cart"]["drive"]

    system, modes, phase, x0 = prepare(_scene("sims/case1_cart.toml", no_motors))
    push = system.start_phase(1, 1.0, x0, phase)
    assert unsupported(system, modes, push) == ""
    pipe = Pipeline(system, modes, push)
    for x in states(x0, 3):
        ref = interpreted_evaluate(system, 1.0123, x, modes, push).xdot
        assert np.abs(pipe.rhs(1.0123, x) - ref).max() <= RTOL * np.abs(ref).max()


@pytest.mark.parametrize("with_line", [False, True])
def test_a_circle_move_is_the_references_own(with_line):
    """The packed reference with a circle (alone: Reference.at's one-move sum; with a straight move after it) gives
    x_d, v_d, a_d of Reference.at bit for bit, before, along and after the circle."""
    from contactdyn.model.pipeline.actuation import reference

    system, modes, phase, t, x0 = case("writer5dof_circle")
    if not with_line:
        phase = replace(phase, reference=replace(phase.reference, moves=phase.reference.moves[:1]))
    assert [m.kind for m in phase.reference.moves] == ["circle", "trapezoid"][:1 + with_line]
    p = Pipeline(system, modes, phase).packed
    for tk in phase.t_start + np.array([-0.1, 0.0, 0.3, 0.8, 1.7, 2.9, 3.95, 4.0, 4.2]):
        got, want = reference(tk, p.ints, p.reals), phase.reference.at(tk)
        for g, w in zip(got, want, strict=True):
            assert np.array_equal(g, w), (tk, g, w)


@pytest.mark.parametrize("name", ["ur5_launch", "writer5dof_launch"])
def test_a_slide_launching_from_rest_takes_the_interpreted_direction(name):
    """At rest (positions near the case's, velocities 0) the UR5's pencil launches along a direction other than its
    reference (Newton converged), the 5-DOF writer's keeps its reference (Newton gives up: dφ/dθ ≥ 0); ẋ is the
    interpreted call's either way. The direction taken: where ẋ is not the slide's along r (from_rest False), it is
    the one the tip accelerates along, d = a_t / |a_t| (a_t = the tangents' J Q̈ at rest), and the slide along d gives
    the launched ẋ (to the Newton's tolerance)."""
    system, modes, phase, t, x0 = case(name)
    c, mode, nQ, nv = system.contacts[0], modes[0], system.nQ, system.nv
    along_r = mode.with_(from_rest=False)
    pipe, flat = Pipeline(system, modes, phase), Pipeline(system, [along_r], phase)
    turned = 0
    for x in states(x0, 5):
        x[nQ:2 * nQ] = 0.0
        got, ref = pipe.rhs(t, x), interpreted_evaluate(system, t, x, modes, phase).xdot
        assert np.abs(got - ref).max() <= RTOL * np.abs(ref).max()
        flat.use([along_r])
        if np.abs(flat.rhs(t, x) - got).max() <= RTOL * np.abs(got).max():
            continue  # along r
        system.robot.update(x[:nv], x[nQ:nQ + nv])
        a_t = np.asarray(c.tangents) @ (system.kinematics(c, x).J @ got[nQ:nQ + nv])
        d = a_t / np.linalg.norm(a_t)
        assert np.abs(d - mode.slip).max() > 1e-3
        flat.use([along_r.with_(slip=tuple(d))])
        assert np.abs(flat.rhs(t, x) - got).max() <= 1e-9 * np.abs(got).max()
        turned += 1
    assert turned == (2 if name == "ur5_launch" else 0)  # (the UR5: 2 of the 5 states)
    assert pipe.failed_calls == 0


@pytest.mark.parametrize("name", ["ur5_launch", "writer5dof_launch"])
def test_a_launch_already_past_the_stick_band_takes_no_trial_pass(name):
    """A slide launching from rest whose tip already slips along r faster than the stick band keeps r: launch_settled
    gives r back before any pass (from the frames alone) and the call is the launched mode's (from_rest False) bit for
    bit; at rest it does not (the Newton's passes follow)."""
    from contactdyn.model.pipeline.launch import launch_settled, launch_start
    from contactdyn.model.pipeline.robot_terms import frame_terms, robot_terms

    system, modes, phase, t, x0 = case(name)
    c, mode, nQ, nv = system.contacts[0], modes[0], system.nQ, system.nv
    pipe, launched = Pipeline(system, modes, phase), Pipeline(system, [mode.with_(from_rest=False)], phase)
    for speed in (0.0, 10.0 * system.slip_band):  # [m/s] the tip along r in the surface's plane
        x = x0.copy()
        x[nQ:2 * nQ] = 0.0
        system.robot.update(x[:nv], x[nQ:nQ + nv])
        J = system.kinematics(c, x).J
        x[nQ:nQ + nv] = np.linalg.pinv(J) @ (np.asarray(c.tangents).T @ np.asarray(mode.slip) * speed)
        p = pipe.packed
        trial, state = launch_start(p.ints, p.reals)
        _, _, _, Jw, W = robot_terms(x, p.ints, trial)
        FJ, Fa, Fp, Fv, FR = frame_terms(x, p.ints, trial, W, Jw)
        past = launch_settled(x, p.ints, state, trial, FJ, Fa, Fp, Fv, FR)
        assert past == (speed > 0.0)
        if past:
            assert np.array_equal(trial, p.reals)  # r exactly, not its cos/sin round trip
            assert np.array_equal(pipe.rhs(t, x), launched.rhs(t, x))
    assert pipe.failed_calls == 0


@pytest.mark.parametrize("name", ["b1_energy", "b1_energy_stuck", "b1_energy_stick", "b1_energy_massless",
                                  "writer_b_energy"])
def test_the_energy_audits_rates_are_the_interpreted_ones(name):
    """The drives' power and the dissipation (dampers, viscous and Coulomb sliding friction with and without a
    normal row, joint damping and sliding friction) against the interpreted call's, each to 1e-12 of itself."""
    system, modes, phase, t, x0 = case(name)
    pipe = Pipeline(system, modes, phase)
    e = 2 * system.nQ + system.energy_slot
    for x in states(x0, 4)[1:]:  # (moving: x0 of writer_b is at rest, no power)
        got, ref = pipe.rhs(t, x)[e:e + 2], interpreted_evaluate(system, t, x, modes, phase).xdot[e:e + 2]
        assert np.all(ref != 0.0)
        np.testing.assert_allclose(got, ref, rtol=RTOL, atol=0.0)
