"""Case 2 with the paper's DC motors (sims/case2_writer_motors.toml): the impact's momentum law with the rotors."""

from __future__ import annotations

import numpy as np
import pytest

from contactdyn.hybrid import transitions
from contactdyn.model.system import System
from contactdyn.scene.scene_file import load_scene
from contactdyn.simulate import run_system

MU = 0.4
M_E = 10.0  # [kg] the struck surface mass (sec. 5.2)
ROTOR = 160.0 * 65.12 * 0.000452  # [kg·m²] N N* J reflected on each joint (sec. 5.2)


def momentum_solve(H: np.ndarray, Jz: np.ndarray, Jx: np.ndarray, qd_minus: np.ndarray, d: float):
    """Sliding impact on a model (b) surface, closed form: unknowns q̇⁺ (2), ż⁺, FΔt.
    H(q̇⁺ − q̇⁻) = (J_zᵀ − μ d J_xᵀ) FΔt,  m_e ż⁺ = −FΔt,  J_z q̇⁺ = ż⁺ (the surface is at rest before)."""
    A = np.zeros((4, 4))
    A[:2, :2] = H
    A[:2, 3] = -(Jz - MU * d * Jx)
    A[2, 2], A[2, 3] = M_E, 1.0
    A[3, :2], A[3, 2] = Jz, -1.0
    z = np.linalg.solve(A, np.concatenate([H @ qd_minus, [0.0, 0.0]]))
    return z[:2], z[2], z[3]


def test_case2_with_motors_obeys_the_momentum_law_with_the_rotors(monkeypatch):
    """The run's impact, at the state it happened in, satisfies (H + N N* J)(q̇⁺ − q̇⁻) = J_zᵀ FΔt +
    J_xᵀ F_fΔt, m_e ż⁺ = −FΔt, J_z q̇⁺ = ż⁺ and F_fΔt = −μ FΔt d to 1e-12. Two causes make FΔt
    ~17x the torque-driven scene's: the rotors in the momentum law (the links alone would take
    2.6x less from the same q̇⁻) and a faster touch (the PD lags more behind the heavier arm)."""
    system = System(load_scene("case2_writer_motors", {"duration": 0.97}))
    seen = []
    impact = transitions.impact

    def spy(system, t, x, modes, contact, *limits):  # the impact law, recording the state it was applied at
        out = impact(system, t, x, modes, contact, *limits)
        seen.append((x.copy(), out[1]))
        return out

    monkeypatch.setattr(transitions, "impact", spy)
    r = run_system(system)
    assert len(seen) == 1 and len(r.impacts) == 1
    x, imp = seen[0]
    q, qd_minus, qd_plus = x[:2], imp.v_before[:2], imp.v_after[:2]
    system.robot.update(q, qd_minus)
    Jtip = system.robot.frame_terms(system.tip_fid).jacobian
    Jx, Jz = Jtip[0], Jtip[2]
    H = system.robot.H + ROTOR * np.eye(2)
    P_n, P_t = imp.normal_impulse, float(imp.friction_impulse[0])
    scale = np.max(np.abs(H @ qd_minus))  # [N·m·s]
    np.testing.assert_allclose(H @ (qd_plus - qd_minus), Jz * P_n + Jx * P_t, rtol=0, atol=1e-12 * scale)
    assert M_E * imp.v_after[2] == pytest.approx(-P_n, rel=1e-12)
    assert Jz @ qd_plus == pytest.approx(imp.v_after[2], rel=1e-12)
    assert not imp.jammed and P_t == pytest.approx(-MU * P_n * np.sign(Jx @ qd_minus), rel=1e-12)
    # the closed form from q̇⁻ alone gives the same impulse; without the rotors it is much smaller
    d = float(np.sign(Jx @ qd_minus))
    _, _, P_closed = momentum_solve(H, Jz, Jx, qd_minus, d)
    assert P_closed == pytest.approx(P_n, rel=1e-12)
    _, _, P_links = momentum_solve(system.robot.H, Jz, Jx, qd_minus, d)
    print(f"\ncase 2 with motors: FΔt = {P_n:.4f} N·s, F_fΔt = {P_t:.4f} N·s; links alone from the same "
          f"q̇⁻: {P_links:.4f} N·s; tip velocity at the touch {Jtip[[0, 2]] @ qd_minus} m/s")
    assert P_n > 2.0 * P_links
