"""The force-reading dynamic laws read off as a matrix (contactdyn.compiled.plan_law) equal the readable law."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from test_controllers import hybrid_doc

from contactdyn import parse_scene
from contactdyn.compiled.plan_law import CompiledLaw, compiled_law, plan_command, plan_inputs
from contactdyn.compiled.plan_rhs import controller_input
from contactdyn.compiled.rhsplan import ModePlan
from contactdyn.model.constraints import force_columns
from contactdyn.model.dynamics import carried_command
from contactdyn.model.phases import start_phase
from contactdyn.scene.scene_file import load_scene
from contactdyn.simulate import prepare


def _plan_states(scene, count: int = 4):
    """A plan of the phase with the force-reading controller, every contact touching, and (t, x, Js, φ, o, τ_c)
    at random states near the start."""
    system, modes, phase, x0 = prepare(scene)
    index = next(i for i, ctl in enumerate(system.controllers) if ctl.uses_forces)
    if index:
        phase = start_phase(system, index, 0.0, x0, phase)
    modes = [replace(m, touching=True) for m in modes]
    plan = ModePlan(system, modes, phase)
    nv = system.nv
    rng = np.random.default_rng(7)
    out = []
    for _ in range(count):
        x = x0 + 1e-3 * rng.normal(size=x0.size)
        t = rng.uniform(0.0, 0.5)
        phi = plan.phi_at(t, x)
        Js = [phi[i:i + 3 * nv].reshape(3, nv) for i in plan.i_J]
        o = plan.P.dot(phi)[plan.m * plan.m + plan.m:]
        out.append((t, x, Js, phi, o, rng.normal(size=nv)))
    return plan, out


def _inputs(scene, count: int = 4):
    """The phase's controller and its ControlInputs at random states near the start, every contact touching."""
    plan, states = _plan_states(scene, count)
    make = controller_input(plan)
    nQ, nv = plan.system.nQ, plan.system.nv
    return plan.phase, [make(t, x, x[:nv], x[nQ:nQ + nv], Js, phi, o, tau_c) for t, x, Js, phi, o, tau_c in states]


def _scenes():
    yield "case3_b_force (A10, cancel measured)", load_scene("case3_b_force")
    yield "case3_a_position (A7, force reference)", load_scene("case3_a_position")
    yield "case1_cart (A7, carried reference, tangential set-point)", load_scene("case1_cart")
    for cancel in ("target", "measured"):
        yield f"hybrid (cancel {cancel})", parse_scene(hybrid_doc(cancel=cancel, friction=0.3))
    doc = hybrid_doc(cancel="target")
    doc["controller"] = {"kind": "force_dynamic", "kf": 20.0}
    doc["phase"][0].pop("reference")
    yield "force_dynamic (A10, cancel target)", parse_scene(doc)


@pytest.mark.parametrize(("what", "scene"), list(_scenes()), ids=[w for w, _ in _scenes()])
def test_probed_law_equals_the_readable_command(what, scene):
    phase, inputs = _inputs(scene)
    ctl = phase.controller
    law = CompiledLaw(ctl)
    for inp in inputs:
        tau, zdot = ctl.command(inp)
        tau_m, zdot_m = law.command(inp)
        assert law.M is not None, law.reason
        scale = 1.0 + np.abs(tau).max()
        assert np.max(np.abs(tau_m - tau)) <= 1e-12 * scale
        if zdot is not None:
            assert np.max(np.abs(zdot_m - zdot)) <= 1e-12 * (1.0 + np.abs(zdot).max())
        # the fold's force columns: +1 N on each measured normal force, and a column reaching beyond the robot
        names = [k for k in inp.forces if "." not in k]
        meta = [(name, "n", 0) for name in names] + [(names[0], "t", 0)]
        cols = [np.zeros(len(tau) + 1) for _ in names] + [np.r_[np.ones(len(tau)), 1.0]]
        B, Dz = force_columns(inp, ctl, tau, zdot, meta, cols, len(tau))
        B_m, Dz_m = law.force_columns(inp, tau, zdot, meta, cols, len(tau))
        assert np.max(np.abs(B_m - B)) <= 1e-12 * (1.0 + np.abs(B).max())
        if Dz is not None:
            assert np.max(np.abs(Dz_m - Dz)) <= 1e-12 * (1.0 + np.abs(Dz).max())
        carried = carried_command(inp, phase, tau, zdot)
        carried_m = carried_command(inp, phase, tau, zdot, law)
        assert (carried is None) == (carried_m is None)
        if carried is not None:
            assert np.max(np.abs(carried_m[1] - carried[1])) <= 1e-12 * (1.0 + np.abs(carried[1]).max())


def test_a_law_that_is_not_affine_in_its_inputs_is_declined():
    """A clip inside the tip targets: the matrix is refused and the readable command runs."""
    phase, inputs = _inputs(load_scene("case3_b_force"), count=1)
    ctl = phase.controller

    class Clipped(type(ctl)):
        def tip_targets(self, inp):
            a, f_swap, zdot = super().tip_targets(inp)
            return np.clip(a, -1e-3, 1e-3), f_swap, zdot

    clipped = object.__new__(Clipped)
    clipped.__dict__.update(ctl.__dict__)
    law = CompiledLaw(clipped)
    inp = inputs[0]
    tau, _ = law.command(inp)
    assert law.M is None and "not affine" in law.reason
    assert np.array_equal(tau, clipped.command(inp)[0])


def test_joint_space_position_law_is_declined():
    doc = hybrid_doc()
    doc["controller"] = {"kind": "position_dynamic", "space": "joint"}
    doc["phase"][0] = {"name": "main"}
    phase, _ = _inputs(parse_scene(doc), count=1)
    law = CompiledLaw(phase.controller)
    assert law.reason is not None and "task-space" in law.reason


@pytest.mark.parametrize(("what", "scene"), list(_scenes()), ids=[w for w, _ in _scenes()])
def test_plan_command_reads_the_same_inputs_off_the_plans_slots(what, scene):
    """plan_command builds u from φ, o and x (no ControlInput): the same u, τ and ż as the law at the plan's
    ControlInput, to the bit."""
    plan, states = _plan_states(scene)
    make = controller_input(plan)
    law, fast = compiled_law(plan), plan_command(plan)
    inputs = plan_inputs(plan, law)
    nQ, nv = plan.system.nQ, plan.system.nv
    for t, x, Js, phi, o, tau_c in states:
        inp = make(t, x, x[:nv], x[nQ:nQ + nv], Js, phi, o, tau_c)
        assert law.M is not None, law.reason
        assert np.array_equal(inputs(t, x, phi, o), law.inputs(inp))
        tau, zdot = law.command(inp)
        tau_f, zdot_f, H, J = fast(t, x, Js, phi, o, tau_c)
        assert np.array_equal(tau_f, tau) and np.array_equal(H, inp.H) and np.array_equal(J, inp.J)
        assert (zdot is None and zdot_f is None) or np.array_equal(zdot_f, zdot)


def test_plan_command_waits_for_the_matrix_and_declines_a_readable_law():
    plan, states = _plan_states(load_scene("case3_b_force"), count=1)
    law = compiled_law(plan)
    fast = plan_command(plan)
    M, law.M = law.M, None  # as before the first call of the mode
    assert fast(*states[0]) is None
    law.M = M
    assert fast(*states[0]) is not None
    doc = hybrid_doc()
    doc["controller"] = {"kind": "position_dynamic", "space": "joint"}
    doc["phase"][0] = {"name": "main"}
    joint_plan, _ = _plan_states(parse_scene(doc), count=1)
    assert plan_command(joint_plan) is None


def test_reference_rows_are_reference_at_bitwise():
    """plan_law's reference as one product over the moves' profiles equals Reference.at bitwise (same sums in the
    same order) for 1–3 moves of every non-circle kind and one circle, before, during and after them."""
    from contactdyn.compiled.plan_law import reference_rows
    from contactdyn.laws.trajectory import Move, Reference

    rng = np.random.default_rng(0)
    kinds = ["trapezoid", "triangle", "velocity_ramp", "constant_velocity", "step", "exponential"]
    circle = Move(np.array([0.01, 0.02, 0.0]), 0.5, 2.0, "circle", 0.1, np.array([0.0, 0.0, 1.0]), 1.5)
    one_circle = Reference(np.array([0.3, 0.1, 0.0]), (circle,))
    for t in np.linspace(-1.0, 5.0, 61):
        assert np.array_equal(reference_rows(one_circle)(t), np.concatenate(one_circle.at(t)))
    for _ in range(20):
        moves = tuple(Move(rng.normal(size=3), float(rng.uniform(0, 2)), float(rng.uniform(0.1, 2)),
                           kinds[rng.integers(len(kinds))], float(rng.uniform(0.05, 0.5)))
                      for _ in range(rng.integers(1, 4)))
        ref = Reference(rng.normal(size=3), moves)
        rows = reference_rows(ref)
        for t in np.linspace(-1.0, 5.0, 61):
            assert np.array_equal(rows(t), np.concatenate(ref.at(t)))


def test_write_time_part_writes_the_reference_and_the_ramps():
    """The compiled tip laws' time part (plan_law.write_time_part, in the kernel's call): u[6:15] the reference's
    rows by its tables (a product of moves or one circle; a fixed reference, kind −1, leaves them), then
    (F_d, Ḟ_d) of each ramp from u[i_set], each Ramp.at's bitwise; nothing else of u changes."""
    from contactdyn.compiled.plan_law import NO_REFERENCE, reference_tables, write_time_part
    from contactdyn.laws.trajectory import Move, Ramp, Reference, ramp_table

    circle = Move(np.array([0.01, 0.02, 0.0]), 0.5, 2.0, "circle", 0.1, np.array([0.0, 0.0, 1.0]), 1.5)
    moves = (Move(np.array([0.1, 0.0, -0.2]), 0.2, 1.0, "trapezoid", 0.25),
             Move(np.array([0.0, 0.05, 0.0]), 0.0, 0.3, "exponential"))
    ramps = [Ramp(100.0, 0.1, 0.2, "exponential"), Ramp(-5.0, 0.3, 0.5, "linear", 2.0)]
    table = ramp_table(ramps)
    for ref in (Reference(np.array([0.3, 0.1, 0.0]), (circle,)), Reference(np.array([-1.0, 0.2, 0.5]), moves), None):
        tables = reference_tables(ref) if ref is not None else NO_REFERENCE
        for t in np.linspace(-0.5, 3.0, 36):
            u = np.full(24, 7.0)
            write_time_part(t, *tables, table, u, 17)
            expected = np.full(24, 7.0)
            if ref is not None:
                expected[6:15] = np.concatenate(ref.at(t))
            expected[17:21] = [*ramps[0].at(t), *ramps[1].at(t)]
            assert np.array_equal(u, expected), t
