"""The tip targets of the task-space dynamic laws (A7, A10, hybrid: :mod:`.dynamic`), compiled once for every path.

    A10 / hybrid, per force set-point i on a touching contact (normal n_i, nominal k_i, b_i, m_i):
        s = n·(p_s − p) [m],  ṡ = n·(ṗ_s − ṗ) [m/s],  μ = F − F_d,  F* = F_d + z_i [N]
        s̈* = (F* − b ṡ − k s) / m   (m > 0),   else (Ḟ_d − K_F μ − k ṡ) / b
        a* −= s̈* n,   ż_i = −K_F μ,   f_swap += (F − F*) n
      a contact not touching adds n nᵀ to P (a free direction, its integral frozen); then
        a* += P (ẍ_d − K_p (p − x_d) − K_v (ṗ − ẋ_d))   (hybrid),   P (−K_v ṗ)   (A10)
    A7 in task space:  a* = ẍ_d − K_p (p − x_d) − K_v (ṗ − ẋ_d)   (−K_v ṗ without a reference), the reference
      pressed F_d / k beyond the surface along each touching set-point's n (``force_reference``).
    A7 in joint space: q̈* = q̈_d − K_p (q − q_d) − K_v (q̇ − q̇_d)   (−K_v q̇ without a reference), per joint.

The readable laws (``ForceDynamic.tip_targets``, ``PositionDynamic.tip_targets`` and ``command``) call these
functions with their inputs as arrays (per set-point, in the phase's order), and the one pipeline calls them on its
controller buffer (:mod:`contactdyn.model.pipeline.control_laws`): one source. Arguments are C-contiguous float64
arrays; kp, kv [1/s², 1/s] one per world axis (3), or per joint (nv) in joint space; "no reference" is x_d, v_d, a_d
of size 0; env (ns, 3) the nominal k [N/m], b [N·s/m], m [kg] per set-point; touch 1.0 / 0.0 per set-point.
"""

from __future__ import annotations

import numpy as np

from ...numerics.compile_cache import njit
from ...numerics.linalg import dot3, put

__all__ = ["force_targets", "position_targets", "pressing_reference", "joint_targets"]


@njit(cache=True)
def force_targets(P, p_tip, v_tip, x_d, v_d, a_d, kp, kv, kf, normals, touch, p_s, v_s, F_d, dF_d, F, z, env,
                  tracks_position):
    """(a* [m/s²], f_swap [N], ż [N/s]) of A10 (``tracks_position`` False) or the hybrid law (True). Written per
    component, without temporaries (the law runs per call and once more per fold row: its small arrays were most
    of its cost); the order of operations is the vector form's of the module docstring, so the values are too."""
    ns = normals.shape[0]
    a, f_swap, zdot = np.zeros(3), np.zeros(3), np.zeros(ns)  # a holds the force part first
    d = np.empty(3)
    for i in range(ns):
        if touch[i] == 0.0:  # like a free direction (n nᵀ added to P below), integral frozen
            continue
        n = normals[i]
        k, b, m = env[i, 0], env[i, 1], env[i, 2]
        for r in range(3):
            d[r] = p_s[i, r] - p_tip[r]
        s = dot3(n, d)  # penetration [m]
        for r in range(3):
            d[r] = v_s[i, r] - v_tip[r]
        sd = dot3(n, d)  # its rate [m/s]
        mu = F[i] - F_d[i]  # force error [N]
        target = F_d[i] + z[i]  # F* [N]
        if m > 0.0:
            sdd = (target - b * sd - k * s) / m
        else:  # Ḟ* = Ḟ_d + Q(μ)
            sdd = (dF_d[i] - kf * mu - k * sd) / b
        zdot[i] = -kf * mu
        for r in range(3):
            a[r] -= sdd * n[r]
            f_swap[r] += (F[i] - target) * n[r]
    for r in range(3):  # a* = P' a_pos + a_force, P' = P + Σ_free n nᵀ (each entry summed in the set-points' order)
        acc = 0.0
        for c in range(3):
            p_rc = P[r, c]
            for i in range(ns):
                if touch[i] == 0.0:
                    p_rc += normals[i, r] * normals[i, c]
            if tracks_position:
                a_pos = a_d[c] - kp[c] * (p_tip[c] - x_d[c]) - kv[c] * (v_tip[c] - v_d[c])
            else:
                a_pos = -kv[c] * v_tip[c]
            acc += p_rc * a_pos
        a[r] = acc + a[r]
    return a, f_swap, zdot


@njit(cache=True)
def pressing_reference(x_d, v_d, a_d, normals, touch, p_s, v_s, F_d, dF_d, k):
    """(x_d, ẋ_d, ẍ_d) pressed along each touching set-point's n: x_d·n = p_s·n − F_d/k, ẋ_d·n = ṗ_s·n − Ḟ_d/k,
    ẍ_d·n = 0 (the surface's acceleration and F̈_d/k left out). Row by row (each row's update reads that row only):
    the vector form's values without its temporaries."""
    R = np.empty((3, 3))
    for r, row in enumerate((x_d, v_d, a_d)):  # (put: no array assignment, see numerics.linalg.put)
        put(R[r], 0, row)
    for i in range(normals.shape[0]):
        if touch[i] == 0.0:
            continue
        n = normals[i]
        for r in range(3):
            target = dot3(n, p_s[i]) - F_d[i] / k[i] if r == 0 else dot3(n, v_s[i]) - dF_d[i] / k[i] if r == 1 \
                else 0.0
            acc = 0.0
            for c in range(3):
                acc += R[r, c] * n[c]
            d = target - acc
            for c in range(3):
                R[r, c] += d * n[c]
    return R[0], R[1], R[2]


@njit(cache=True)
def position_targets(p_tip, v_tip, x_d, v_d, a_d, kp, kv, pressing, normals, touch, p_s, v_s, F_d, dF_d, k):
    """a* [m/s²] of A7 in task space (``pressing``: the force reference, k [N/m] per set-point)."""
    if x_d.size == 0:
        return -kv * v_tip
    if pressing:
        x_d, v_d, a_d = pressing_reference(x_d, v_d, a_d, normals, touch, p_s, v_s, F_d, dF_d, k)
    return a_d - kp * (p_tip - x_d) - kv * (v_tip - v_d)


@njit(cache=True)
def joint_targets(q, v, q_d, v_d, a_d, kp, kv):
    """q̈* [rad/s² or m/s²] of A7 in joint space at q [rad or m], q̇ (kp [1/s²], kv [1/s] per joint; no reference:
    q_d of size 0). Per component: numpy's elementwise values."""
    qdd = np.empty(q.size)
    if q_d.size == 0:
        for i in range(q.size):
            qdd[i] = -kv[i] * v[i]
        return qdd
    for i in range(q.size):
        qdd[i] = a_d[i] - kp[i] * (q[i] - q_d[i]) - kv[i] * (v[i] - v_d[i])
    return qdd
