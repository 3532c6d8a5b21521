"""task_pd's ``kd_normal``: damping of the tip's velocity along a force set-point's direction,
τ = Jᵀ(−F_d n − D_n (n·ẋ) n) + ..., zero at rest so the set-point is kept."""

from __future__ import annotations

import numpy as np

from contactdyn.laws.controllers.base import ControlInput
from contactdyn.laws.controllers.pd import TaskPD, TaskPDConfig


def _input(v_tip: np.ndarray) -> ControlInput:
    rng = np.random.default_rng(3)
    nv = 4
    J = rng.normal(size=(3, nv))
    z = np.zeros(nv)
    return ControlInput(0.0, z, z, np.eye(nv), z, None, np.zeros(3), v_tip, J, np.zeros(3), None, None, None,
                        {}, {"pencil": (5.0, 0.0)}, {"pencil": np.array([0.0, 0.0, 1.0])}, np.zeros(0))


def _law(kd_normal: float) -> TaskPD:
    axes = np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])
    return TaskPD(TaskPDConfig(np.array([800.0]), np.array([40.0]), axes, "none", kd_normal=kd_normal), 4)


def test_normal_damping_is_minus_d_times_the_normal_velocity_through_j_transpose():
    v_tip = np.array([0.3, -0.2, 0.07])  # [m/s]
    inp = _input(v_tip)
    tau_damped, _ = _law(2000.0).command(inp)
    tau_plain, _ = _law(0.0).command(inp)
    np.testing.assert_allclose(tau_damped - tau_plain, inp.J.T @ np.array([0.0, 0.0, -2000.0 * 0.07]), atol=1e-12)


def test_normal_damping_leaves_the_set_point_at_rest_and_ignores_tangential_motion():
    for v_tip in (np.zeros(3), np.array([0.3, -0.2, 0.0])):
        inp = _input(v_tip)
        np.testing.assert_allclose(_law(2000.0).command(inp)[0], _law(0.0).command(inp)[0], atol=1e-12)
