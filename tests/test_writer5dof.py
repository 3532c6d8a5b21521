"""The 5-DOF writer (case 2, Fig. 3): 2-D friction opposite the slip, pencil direction held."""

from __future__ import annotations

import numpy as np

from contactdyn import Robot, simulate


def test_writer5dof_draws_with_friction_opposite_slip_and_holds_the_pencil():
    r = simulate("case2_writer5dof", {"duration": 1.2, "solver.output_rate": 100.0})
    F_f, v = r["contact.pencil.F_f"], r["contact.pencil.v_slip"]
    speed = np.linalg.norm(v, axis=1)
    sliding = (speed > 1e-6) & (r["contact.pencil.stuck"] == 0)
    assert sliding.sum() > 20  # it really draws
    cos = np.sum(F_f * v, axis=1)[sliding] / (np.linalg.norm(F_f, axis=1)[sliding] * speed[sliding])
    assert np.allclose(cos, -1.0, atol=1e-12)  # eqs 21-24: F_f = -mu F v/|v|
    F_n = r["contact.pencil.F_n"]
    assert np.allclose(np.linalg.norm(F_f, axis=1)[sliding], 0.4 * F_n[sliding], rtol=1e-12)
    assert np.all(np.abs(F_n - 5.0) < 1.0)  # the 5 N pressure holds within the surface's ringing
    robot = Robot.load("writer5dof")
    target = np.array(r.scene["controller"]["tool_target"])
    target /= np.linalg.norm(target)
    angles = [np.arccos(np.clip(robot.frame_placement(q, "tip").rotation[:, 2] @ target, -1, 1)) for q in r["q"]]
    assert max(angles) < 0.02  # [rad] the pencil keeps its 0.2 rad tilt
