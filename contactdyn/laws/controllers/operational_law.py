"""The operational_space law's arithmetic (:mod:`.operational`), compiled once for every path.

    J_t = W J_tip,   W = [S 0; 0 E]       S: the position axes and force directions (rows),
                                          E = [e1; e2]: a basis of the plane ⊥ the tool direction a = R_tip a_tip
    Λ⁻¹ = J_t H⁻¹ J_tᵀ
    τ = J_tᵀ (Λ (a* − J̇_t q̇ + k_null ẋ_t) + f) − k_null H q̇ + h       [N·m or N]

a* [m/s², rad/s²] and f [N] as the module :mod:`~contactdyn.laws.controllers.operational` says: per position
axis n, a* = n·ẍ_d and f = kp n·(x_d − p) + kd n·(ẋ_d − ṗ) (f = −kd n·ṗ without a reference); per force
direction n, a* = 0 and f = −F_d − kd_normal n·ṗ; on the tilt, a* = E (ko (a × d) − do ω), f = 0.
k_null = 0 where the task has as many directions as the arm has joints.

Written once here and compiled by numba: the readable law (``OperationalSpace.torque``) and the one pipeline's
call (:mod:`contactdyn.model.pipeline.control_laws`) both run :func:`torque`. Λ⁻¹ = Yᵀ Y with Y = L⁻¹ J_tᵀ,
H = L Lᵀ (:func:`~contactdyn.numerics.linalg.cholesky`), Λ (…) by :func:`~.linalg.lu_solve`: loops, not numba's
LAPACK bindings. Arguments are C-contiguous float64
arrays; "none" is an empty array (no reference: x_d, v_d, a_d of size 0; no tool axis: ``tool_axis``,
``target`` of size 0 and R_tip (0, 3)). :func:`torque` also returns the task's Hadamard ratio
det(Λ⁻¹) / Π diag(Λ⁻¹), which the caller checks against :data:`SINGULAR` (in Python: the error is
raised there).
"""

from __future__ import annotations

import math

import numpy as np

from ...numerics.compile_cache import njit
from ...numerics.linalg import cholesky, forward_solve, lu_solve, mm, mtm, mtv

__all__ = ["perpendicular", "hadamard_ratio", "torque", "SINGULAR"]

#: smallest det(Λ⁻¹) / Π diag(Λ⁻¹) (Hadamard ratio in (0, 1]: the product of sin² of the angles, in the
#: metric H⁻¹, between each task direction and the ones before it) the law accepts; below it the task is
#: singular: one direction within ~1e-4 rad of the others, Λ and the torques beyond what the arm can give
#: (the writing task runs at 2e-4 on the UR10, 0.013 on the Panda and the 5-DOF writer, 0.27 on the UR5)
SINGULAR = 1e-8  # (here, with the compiled code that reads it: contactdyn.numerics.compile_cache)


@njit(cache=True)
def perpendicular(a):
    """(e1, a × e1): an orthonormal basis of the plane perpendicular to the unit 3-vector a."""
    if abs(a[0]) < 0.9:
        e1 = np.array([0.0, a[2], -a[1]])  # a × x
    else:
        e1 = np.array([-a[2], 0.0, a[0]])  # a × y
    e1 /= math.sqrt(e1[0] * e1[0] + e1[1] * e1[1] + e1[2] * e1[2])
    return e1, np.cross(a, e1)


@njit(cache=True)
def hadamard_ratio(S):
    """det(S) / Π diag(S) of a symmetric positive definite S (the product of its elimination pivots over its
    diagonal, no pivoting); 0 where a pivot is not positive (S singular or indefinite), nan with a nan in S."""
    n = S.shape[0]
    U = S.copy()
    ratio = 1.0
    for k in range(n):
        if not U[k, k] > 0.0:
            return U[k, k] * 0.0  # 0, or nan
        ratio *= U[k, k] / S[k, k]
        for i in range(k + 1, n):
            f = U[i, k] / U[k, k]
            for j in range(k + 1, n):
                U[i, j] -= f * U[k, j]
    return ratio


@njit(cache=True)
def _task_terms(v_tip, p_tip, x_d, v_d, a_d, set_points, axes, forced, kp, kd, kd_normal, m):
    """(a* [m/s²], f [N]) on the position axes, then the force directions (m entries, the rest 0: the tilt's).
    Per component, each n·y summed as :func:`~contactdyn.numerics.linalg.mv` sums it (no temporaries)."""
    k, nf = axes.shape[0], forced.shape[0]
    a_task, f = np.zeros(m), np.zeros(m)
    for i in range(k):
        n = axes[i]
        if x_d.size:
            acc_a = acc_x = acc_v = 0.0
            for j in range(3):
                acc_a += n[j] * a_d[j]
                acc_x += n[j] * (x_d[j] - p_tip[j])
                acc_v += n[j] * (v_d[j] - v_tip[j])
            a_task[i] = acc_a
            f[i] = kp[i] * acc_x + kd[i] * acc_v
        else:
            acc_v = 0.0
            for j in range(3):
                acc_v += n[j] * v_tip[j]
            f[i] = -kd[i] * acc_v
    for i in range(nf):
        acc_v = 0.0
        for j in range(3):
            acc_v += forced[i, j] * v_tip[j]
        f[k + i] = -set_points[i] - kd_normal * acc_v
    return a_task, f


@njit(cache=True)
def _tilt_terms(R_tip, tool_axis, target, J_ang, v, ko, do, W, a_task, nS):
    """The tilt's rows of W (e1, e2 on the angular columns) and its a* = E (ko (a × d) − do ω) [rad/s²] into
    a_task[nS:nS + 2], a = R_tip a_tip [-], in scalars: each value summed and multiplied as mv, perpendicular,
    np.cross and ``(e * w).sum()`` do it (no temporaries)."""
    a0 = a1 = a2 = 0.0
    for j in range(3):
        a0 += R_tip[0, j] * tool_axis[j]
        a1 += R_tip[1, j] * tool_axis[j]
        a2 += R_tip[2, j] * tool_axis[j]
    if abs(a0) < 0.9:  # (perpendicular)
        e10, e11, e12 = 0.0, a2, -a1
    else:
        e10, e11, e12 = -a2, 0.0, a0
    norm = math.sqrt(e10 * e10 + e11 * e11 + e12 * e12)
    e10, e11, e12 = e10 / norm, e11 / norm, e12 / norm
    e20, e21, e22 = a1 * e12 - a2 * e11, a2 * e10 - a0 * e12, a0 * e11 - a1 * e10
    om0 = om1 = om2 = 0.0  # ω = J_ω q̇ [rad/s]
    for j in range(v.size):
        om0 += J_ang[0, j] * v[j]
        om1 += J_ang[1, j] * v[j]
        om2 += J_ang[2, j] * v[j]
    w0 = ko * (a1 * target[2] - a2 * target[1]) - do * om0
    w1 = ko * (a2 * target[0] - a0 * target[2]) - do * om1
    w2 = ko * (a0 * target[1] - a1 * target[0]) - do * om2
    W[nS, 3], W[nS, 4], W[nS, 5] = e10, e11, e12
    W[nS + 1, 3], W[nS + 1, 4], W[nS + 1, 5] = e20, e21, e22
    acc = 0.0
    acc += e10 * w0
    acc += e11 * w1
    acc += e12 * w2
    a_task[nS] = acc
    acc = 0.0
    acc += e20 * w0
    acc += e21 * w1
    acc += e22 * w2
    a_task[nS + 1] = acc


@njit(cache=True)
def torque(v, H, h, J_tip, drift_tip, p_tip, v_tip, x_d, v_d, a_d, set_points, R_tip, axes, forced, kp, kd,
           tool_axis, target, ko, do, k_null, kd_normal):
    """(τ [N·m or N], the Hadamard ratio of Λ⁻¹) of the module docstring. J_tip, drift_tip: the tip's linear rows
    (3, nv), (3,) [m/s²], or with a tool axis the 6 rows [J; J_ω], [J̇q̇; J̇_ω q̇] in Pinocchio's order;
    axes (k, 3), forced (nf, 3) the position and force rows of S; kp, kd [N/m, N·s/m] per axis; ko [1/s²],
    do [1/s], k_null [1/s] (0: no null-space damping), kd_normal [N·s/m]. The sums are :mod:`~contactdyn.numerics.
    linalg`'s (mv, mtv), written in place: a call of the one pipeline runs this (few temporaries)."""
    nS = axes.shape[0] + forced.shape[0]
    m = nS + (2 if tool_axis.size else 0)
    a_task, f = _task_terms(v_tip, p_tip, x_d, v_d, a_d, set_points, axes, forced, kp, kd, kd_normal, m)
    W = np.zeros((m, J_tip.shape[0]))  # the task's rows on the tip's [linear; angular] motion
    for j in range(3):  # (element by element: no slice assignment's broadcast and checks)
        for i in range(axes.shape[0]):
            W[i, j] = axes[i, j]
        for i in range(forced.shape[0]):
            W[axes.shape[0] + i, j] = forced[i, j]
    if tool_axis.size:
        _tilt_terms(R_tip, tool_axis, target, J_tip[3:], v, ko, do, W, a_task, nS)
    Jt = mm(W, J_tip)
    rhs = a_task  # a* − J̇_t q̇ (+ k_null ẋ_t)
    for i in range(m):
        acc = 0.0
        for j in range(W.shape[1]):
            acc += W[i, j] * drift_tip[j]
        rhs[i] = rhs[i] - acc
    if k_null > 0.0:
        for i in range(m):
            acc = 0.0
            for j in range(v.size):
                acc += Jt[i, j] * v[j]
            rhs[i] += k_null * acc
    Y = forward_solve(cholesky(H), np.ascontiguousarray(Jt.T))  # L⁻¹ J_tᵀ, H = L Lᵀ
    L_inv = mtm(Y, Y)  # Λ⁻¹ = J_t H⁻¹ J_tᵀ
    ft = lu_solve(L_inv, rhs)  # Λ (a* − J̇_t q̇ + k_null ẋ_t) + f
    for i in range(m):
        ft[i] = ft[i] + f[i]
    tau = mtv(Jt, ft)
    for i in range(tau.size):
        tau[i] = tau[i] + h[i]
    if k_null > 0.0:
        for i in range(tau.size):
            acc = 0.0
            for j in range(v.size):
                acc += H[i, j] * v[j]
            tau[i] -= k_null * acc
    return tau, hadamard_ratio(L_inv)
