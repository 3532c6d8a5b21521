"""The computed torque of the task-space dynamic laws (A7, A10, hybrid), compiled once for every path.

    q̈* = J⁺(a − J̇q̇) − (I − J⁺J) k_null q̇           (k_null only where the robot is redundant, nv > 3)
    τ  = H q̈* − r ∘ q̈* + h − τ_c + Jᵀ f_swap         [N·m or N]
    (A7 in joint space: q̈* the joint law's, :func:`joint_torque`)

H [kg·m²] the model's inertia, r the rotor inertia the law takes out (``inertia = "link"``; empty
for "model"), J the tip Jacobian (3, nv), J⁺ its pseudo-inverse (:func:`contactdyn.numerics.linalg.pinv`: singular
values below 1e-10 of the largest dropped, numpy.linalg.pinv's rcond). Written once here and
compiled by numba: the readable law (:mod:`contactdyn.laws.controllers.dynamic`) and the one pipeline's call
(:mod:`contactdyn.model.pipeline.control_laws`) both run these functions. Arguments are
C-contiguous float64 arrays; "none" is an empty array (r, f_swap: length 0, or (N, 0) for a stack).
"""

from __future__ import annotations

import numpy as np

from ...numerics.compile_cache import njit
from ...numerics.linalg import mm, mv, pinv

__all__ = ["pinv", "torque", "joint_torque", "pinv_stack", "torque_stack"]


@njit(cache=True)
def torque(H, rotor, h, tau_c, J, Jp, drift, v, a, f_swap, k_null):
    """τ of the module docstring [N·m or N] for the tip acceleration a [m/s²] (J̇q̇ = drift, q̇ = v). Per component
    (no temporaries but q̈* and τ), each sum in :func:`~contactdyn.numerics.linalg.mv`'s order: mv's values."""
    nv = J.shape[1]
    qdd = np.empty(nv)
    for i in range(nv):
        acc = 0.0
        for j in range(a.size):
            acc += Jp[i, j] * (a[j] - drift[j])
        qdd[i] = acc
    if k_null > 0.0 and nv > 3:
        qdd -= mv(np.eye(nv) - mm(Jp, J), k_null * v)
    return _inverse_dynamics(H, rotor, h, tau_c, J, f_swap, qdd)


@njit(cache=True)
def joint_torque(H, rotor, h, tau_c, qdd):
    """τ = H q̈* − r ∘ q̈* + h − τ_c [N·m or N] of A7 in joint space (q̈* from ``dynamic_law.joint_targets``)."""
    return _inverse_dynamics(H, rotor, h, tau_c, np.empty((0, qdd.size)), np.empty(0), qdd)


@njit(cache=True)
def _inverse_dynamics(H, rotor, h, tau_c, J, f_swap, qdd):
    """H q̈* − r ∘ q̈* + h − τ_c + Jᵀ f_swap [N·m or N], per component."""
    nv = qdd.size
    tau = np.empty(nv)
    for i in range(nv):
        acc = 0.0
        for j in range(nv):
            acc += H[i, j] * qdd[j]
        if rotor.size:
            acc -= rotor[i] * qdd[i]
        acc += h[i]
        acc -= tau_c[i]
        if f_swap.size:
            s = 0.0
            for j in range(f_swap.size):
                s += J[j, i] * f_swap[j]
            acc += s
        tau[i] = acc
    return tau


# ---- a stack of samples (the output's), one sample's arithmetic each ----------------------------
@njit(cache=True)
def pinv_stack(J):
    out = np.empty((J.shape[0], J.shape[2], J.shape[1]))
    for k in range(J.shape[0]):
        out[k] = pinv(np.ascontiguousarray(J[k]))
    return out


@njit(cache=True)
def torque_stack(H, rotor, h, tau_c, J, Jp, drift, v, a, f_swap, k_null):
    out = np.empty(h.shape)
    for k in range(h.shape[0]):
        out[k] = torque(np.ascontiguousarray(H[k]), rotor, h[k], tau_c[k], np.ascontiguousarray(J[k]),
                        np.ascontiguousarray(Jp[k]), drift[k], v[k], a[k], f_swap[k], k_null)
    return out
