"""The drives' law as a matrix on the compiled path (plan_drives.py); a task law through motors as data."""

from __future__ import annotations

import numpy as np
import pytest

from contactdyn.compiled.plan_drives import CompiledDrives
from contactdyn.compiled.rhsplan import ModePlan
from contactdyn.model.dynamics import drive_command
from contactdyn.scene.scene_file import load_scene
from contactdyn.simulate import prepare


def _plan(scene: str, overrides: dict | None = None):
    system, modes, phase, x0 = prepare(load_scene(scene, overrides))
    plan = ModePlan(system, modes, phase)
    assert plan.ok, plan.reason
    return system, plan, x0


@pytest.mark.parametrize("scene", ["case3_a_position", "case2_writer_motors", "case1_cart"])  # elastic, rigid, cart
def test_the_drive_matrix_is_the_readable_law_below_the_limits_and_declines_where_a_voltage_clips(scene):
    system, plan, x0 = _plan(scene, {"robot.drive.u_max": 6.0})
    drives = CompiledDrives(plan)
    rng = np.random.default_rng(3)
    specs = system.drives.specs[:system.nv]
    u_scale = np.array([6.0 * s.n_torque * s.C_M / s.R for s in specs])  # the command that takes 6 V [N·m or N]
    clipped = unclipped = 0
    for _ in range(40):
        x = x0 + rng.normal(scale=0.05, size=system.n)
        tau = rng.normal(scale=0.7, size=system.nv) * u_scale
        readable = drives.readable(x, tau)
        fast = drives.fast(x, tau)
        if system.drives.apply(drive_command(system, tau, x), x, system.nQ, np.zeros(system.nQ)).saturated.any():
            clipped += 1
            assert fast is None
        else:
            unclipped += 1
            assert fast is not None
            np.testing.assert_allclose(fast, readable, rtol=0, atol=1e-11 * (1.0 + np.abs(readable).max()))
    assert clipped and unclipped  # both branches ran


def test_a_task_law_through_motors_needs_no_controller_call_while_no_voltage_clips(monkeypatch):
    system, plan, x0 = _plan("case3_a_position")  # the approach: task PD through an elastic drive
    assert plan.affine_ctl and plan.law_via_drives
    t = plan.phase.t_start + 0.3
    ref = system.evaluate(t, x0, plan.modes, plan.phase).xdot

    def no_call(inp):
        raise AssertionError("the controller was called")

    monkeypatch.setattr(plan.phase.controller, "command", no_call)
    got = plan.rhs(t, x0.copy())
    np.testing.assert_allclose(got, ref, rtol=0, atol=1e-11 * (1.0 + np.abs(ref).max()))
