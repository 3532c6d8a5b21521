"""The tip targets of the task-space dynamic laws (A7, A10, hybrid: :mod:`.dynamic`), compiled once for every path.

    A10 / hybrid, per force set-point i on a touching contact (normal n_i, nominal k_i, b_i, m_i):
        s = n·(p_s − p) [m],  ṡ = n·(ṗ_s − ṗ) [m/s],  μ = F − F_d,  F* = F_d + z_i [N]
        s̈* = (F* − b ṡ − k s) / m   (m > 0),   else (Ḟ_d − K_F μ − k ṡ) / b
        a* −= s̈* n,   ż_i = −K_F μ,   f_swap += (F − F*) n
      a contact not touching adds n nᵀ to P (a free direction, its integral frozen); then
        a* += P (ẍ_d − K_p (p − x_d) − K_v (ṗ − ẋ_d))   (hybrid),   P (−K_v ṗ)   (A10)
    A7 in task space:  a* = ẍ_d − K_p (p − x_d) − K_v (ṗ − ẋ_d)   (−K_v ṗ without a reference), the reference
      pressed F_d / k beyond the surface along each touching set-point's n (``force_reference``).

The readable laws (``ForceDynamic.tip_targets``, ``PositionDynamic.tip_targets``) call these functions with their
inputs as arrays (per set-point, in the phase's order), and the one pipeline calls them on its controller buffer
(:mod:`contactdyn.model.pipeline.control_laws`): one source. Arguments are C-contiguous float64 arrays; kp, kv
[1/s², 1/s] one per world axis (3); "no reference" is x_d, v_d, a_d of size 0; env (ns, 3) the nominal k [N/m],
b [N·s/m], m [kg] per set-point; touch 1.0 / 0.0 per set-point.
"""

from __future__ import annotations

import numpy as np

from ...numerics.compile_cache import njit
from ...numerics.linalg import dot3, mv

__all__ = ["force_targets", "position_targets", "pressing_reference"]


@njit(cache=True)
def force_targets(P, p_tip, v_tip, x_d, v_d, a_d, kp, kv, kf, normals, touch, p_s, v_s, F_d, dF_d, F, z, env,
                  tracks_position):
    """(a* [m/s²], f_swap [N], ż [N/s]) of A10 (``tracks_position`` False) or the hybrid law (True)."""
    ns = normals.shape[0]
    P = P.copy()
    a_force, f_swap, zdot = np.zeros(3), np.zeros(3), np.zeros(ns)
    for i in range(ns):
        n = normals[i]
        if touch[i] == 0.0:  # like a free direction, integral frozen
            for r in range(3):
                for c in range(3):
                    P[r, c] += n[r] * n[c]
            continue
        k, b, m = env[i, 0], env[i, 1], env[i, 2]
        s, sd = dot3(n, p_s[i] - p_tip), dot3(n, v_s[i] - v_tip)  # penetration [m], its rate [m/s]
        mu = F[i] - F_d[i]  # force error [N]
        target = F_d[i] + z[i]  # F* [N]
        if m > 0.0:
            sdd = (target - b * sd - k * s) / m
        else:  # Ḟ* = Ḟ_d + Q(μ)
            sdd = (dF_d[i] - kf * mu - k * sd) / b
        a_force -= sdd * n
        zdot[i] = -kf * mu
        f_swap += (F[i] - target) * n
    if tracks_position:
        a_pos = a_d - kp * (p_tip - x_d) - kv * (v_tip - v_d)
    else:
        a_pos = -kv * v_tip
    return mv(P, a_pos) + a_force, f_swap, zdot


@njit(cache=True)
def pressing_reference(x_d, v_d, a_d, normals, touch, p_s, v_s, F_d, dF_d, k):
    """(x_d, ẋ_d, ẍ_d) pressed along each touching set-point's n: x_d·n = p_s·n − F_d/k, ẋ_d·n = ṗ_s·n − Ḟ_d/k,
    ẍ_d·n = 0 (the surface's acceleration and F̈_d/k left out)."""
    R = np.empty((3, 3))
    R[0], R[1], R[2] = x_d, v_d, a_d
    target = np.zeros(3)
    for i in range(normals.shape[0]):
        if touch[i] == 0.0:
            continue
        n = normals[i]
        target[0] = dot3(n, p_s[i]) - F_d[i] / k[i]
        target[1] = dot3(n, v_s[i]) - dF_d[i] / k[i]
        d = target - mv(R, n)
        for r in range(3):
            for c in range(3):
                R[r, c] += d[r] * n[c]
    return R[0].copy(), R[1].copy(), R[2].copy()


@njit(cache=True)
def position_targets(p_tip, v_tip, x_d, v_d, a_d, kp, kv, pressing, normals, touch, p_s, v_s, F_d, dF_d, k):
    """a* [m/s²] of A7 in task space (``pressing``: the force reference, k [N/m] per set-point)."""
    if x_d.size == 0:
        return -kv * v_tip
    if pressing:
        x_d, v_d, a_d = pressing_reference(x_d, v_d, a_d, normals, touch, p_s, v_s, F_d, dF_d, k)
    return a_d - kp * (p_tip - x_d) - kv * (v_tip - v_d)
