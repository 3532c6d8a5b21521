"""The task PD law's arithmetic (:mod:`contactdyn.laws.controllers.pd`, ``task_pd``), compiled once for every path.

    f = Σ_i a_i (kp_i a_i·(x_d − p) + kd_i a_i·(ẋ_d − ṗ))  −  Σ_k (F_d,k n_k + kd_normal (n_k·ṗ) n_k)     [N]
    m = K_o e − D_o ω_h                                                                           [N·m]
    τ = Jᵀ f + J_ωᵀ m − kd_joint q̇ + τ_ff                                                          [N·m or N]

a_i the position axes (the PD terms only where the phase has a reference), n_k the set-points' directions,
ω = J_ω q̇ the tip's angular velocity [rad/s] (LOCAL_WORLD_ALIGNED), τ_ff the feedforward (g(q), h(q, q̇) or
nothing). The moment m (none without an orientation to hold):

* tool-axis hold: e = a × d, a = R_tip a_tip the tool direction in the world, d its target; ω_h = ω⊥ = ω −
  (ω·a) a (the roll about the tool is left free);
* full orientation R_d: e = ½ Σ_c r_c × r_d,c = ½ vee(R_d Rᵀ − R R_dᵀ) (r_c, r_d,c the columns of R = R_tip and
  R_d), in the world; ω_h = ω. With R = exp(θ [k]ₓ) R_d, e = −sin θ k: the moment turns the tip back about the
  error's own axis with K_o sin θ ≈ K_o θ [N·m/rad · rad]. It is the gradient of the potential K_o (1 − cos θ)
  (= ½ K_o tr(I − R_dᵀ R)), so with D_o > 0 the orientation loop is passive and an arm without gravity settles at
  R_d. Chosen over the log map (e = −θ k) because it is smooth everywhere (the log map's axis is undefined at
  θ = π), needs no trigonometry, equals it to O(θ³), and is the tool-axis moment a × d summed over the three
  axes (halved).

Written once here and compiled by numba: the readable law (``TaskPD.command``) and the one pipeline's call
(:mod:`contactdyn.model.pipeline.actuation`) both run :func:`torque`. Arguments are C-contiguous float64 arrays; "none"
is an empty array (no reference: x_d, v_d of size 0; no orientation: R_tip (0, 3) and tool_axis, target, R_d
empty; no feedforward: tau_ff of size 0).
"""

from __future__ import annotations

import numpy as np

from ...numerics.compile_cache import njit
from ...numerics.linalg import cross3, mtv, mv

__all__ = ["orientation_error", "moment", "torque"]


@njit(cache=True)
def orientation_error(R, R_d):
    """e = ½ Σ_c r_c × r_d,c = ½ vee(R_d Rᵀ − R R_dᵀ) (world; −sin θ k for R = exp(θ [k]ₓ) R_d) [rad, to O(θ³)]."""
    e = np.zeros(3)
    for c in range(3):  # (by component, e += r_c × r_d,c: cross3 on the columns would compile it again, for 'A')
        e[0] += R[1, c] * R_d[2, c] - R[2, c] * R_d[1, c]
        e[1] += R[2, c] * R_d[0, c] - R[0, c] * R_d[2, c]
        e[2] += R[0, c] * R_d[1, c] - R[1, c] * R_d[0, c]
    return 0.5 * e


@njit(cache=True)
def moment(R_tip, omega, tool_axis, target, R_d, ko, do):
    """m [N·m] of the module docstring at the tip's rotation R_tip and angular velocity ω [rad/s] (world): the
    full-orientation hold where R_d has rows, else the tool-axis hold; ko [N·m/rad], do [N·m·s/rad]."""
    if R_d.shape[0]:
        return ko * orientation_error(R_tip, R_d) - do * omega
    a = mv(R_tip, tool_axis)  # the tool direction (world)
    omega_perp = omega - (omega[0] * a[0] + omega[1] * a[1] + omega[2] * a[2]) * a
    return ko * cross3(a, target) - do * omega_perp


@njit(cache=True)
def torque(v, J, J_ang, p_tip, v_tip, x_d, v_d, set_points, R_tip, axes, forced, kp, kd, tool_axis, target, R_d,
           ko, do, kd_joint, kd_normal, tau_ff):
    """τ [N·m or N] of the module docstring: v = q̇; J, J_ang the tip's linear and angular Jacobian rows (3, nv)
    (J_ang (0, nv) without an orientation); p_tip [m], v_tip [m/s]; x_d, v_d the reference [m, m/s]; set_points
    F_d [N] along the rows of ``forced`` (nf, 3); axes (k, 3) with kp [N/m], kd [N·s/m] per axis; kd_joint
    [N·m·s/rad], kd_normal [N·s/m]; tau_ff the feedforward [N·m or N]."""
    f = np.zeros(3)
    if x_d.size:
        for i in range(axes.shape[0]):
            a = axes[i]
            dp = a[0] * (x_d[0] - p_tip[0]) + a[1] * (x_d[1] - p_tip[1]) + a[2] * (x_d[2] - p_tip[2])
            dv = a[0] * (v_d[0] - v_tip[0]) + a[1] * (v_d[1] - v_tip[1]) + a[2] * (v_d[2] - v_tip[2])
            f += (kp[i] * dp + kd[i] * dv) * a
    for k in range(forced.shape[0]):
        n = forced[k]
        f -= (set_points[k] + kd_normal * (n[0] * v_tip[0] + n[1] * v_tip[1] + n[2] * v_tip[2])) * n
    tau = mtv(J, f)
    if R_tip.shape[0]:
        tau += mtv(J_ang, moment(R_tip, mv(J_ang, v), tool_axis, target, R_d, ko, do))
    if kd_joint != 0.0:
        tau -= kd_joint * v
    if tau_ff.size:
        tau += tau_ff
    return tau
