"""The pipeline's first stage: the robot's terms and its frames' kinematics at (q, q̇), over the packed arrays.

H [kg·m²], h and g [N·m or N] and the joint Jacobians (WORLD, 6 × nv) by :mod:`contactdyn.robot.rigid_body`'s
algorithms (as its ``rigid_terms``, every joint's placement and motion kept); then each packed frame's J (6 × nv,
LOCAL_WORLD_ALIGNED, linear rows first), J̇q̇ (6) [m/s², rad/s²], p [m], ṗ = J q̇ [m/s] and R, by
:func:`frame_motion`, the arithmetic of ``contactdyn.compiled.plan_phi.frame_motion`` over the joints' table W
(the model may not import the compiled twin; wiring the pipeline in moves that function here and plan_phi
imports it: one source).
"""

from __future__ import annotations

import numpy as np

from ...numerics.compile_cache import njit
from ...robot.rigid_body import WIDTH, _inertia, _jacobians, _kinematics, _nonlinear
from .pack import (
    FI_JOINT,
    FI_N_SUPPORT,
    FI_SUPPORT,
    FI_W,
    FR_W,
    I_FRAMES,
    N_FRAMES,
    NEEDS_GRAVITY,
    NJ,
    NQ,
    NV,
    R_FRAMES,
    R_RIGID,
    section,
)

__all__ = ["robot_terms", "frame_terms", "frame_motion"]


@njit(cache=True)
def robot_terms(x, ints, reals):
    """(H (nv, nv), h (nv), g (nv, or empty when nobody asks), J (6, nv) per joint column, W: every joint's world
    rotation and position, velocity and acceleration at q̈ = 0 (rigid_body's table))."""
    nv, nQ = ints[NV], ints[NQ]
    table = section(reals, ints[R_RIGID], ints[NJ], WIDTH)
    L, W = _kinematics(x[:nv], x[nQ:nQ + nv], table)
    H, h, J = np.zeros((nv, nv)), np.zeros(nv), np.zeros((6, nv))
    g = np.zeros(nv if ints[NEEDS_GRAVITY] else 0)
    _nonlinear(table, L, W, h)
    _jacobians(table, W, J)
    _inertia(table, W, J, H, g)
    return H, h, g, J, W


@njit(cache=True)
def frame_terms(x, ints, reals, W, Jw):
    """Per packed frame: J (nf, 6, nv), J̇q̇ (nf, 6), p (nf, 3) [m], ṗ (nf, 3) [m/s], R (nf, 3, 3)."""
    nv, nQ, nf = ints[NV], ints[NQ], ints[N_FRAMES]
    rows = section(ints, ints[I_FRAMES], nf, FI_W)
    consts = section(reals, ints[R_FRAMES], nf, FR_W)
    FJ, Fa, Fp, Fv, FR = np.zeros((nf, 6, nv)), np.zeros((nf, 6)), np.zeros((nf, 3)), np.zeros((nf, 3)), \
        np.zeros((nf, 3, 3))
    for k in range(nf):
        support = ints[rows[k, FI_SUPPORT]:rows[k, FI_SUPPORT] + rows[k, FI_N_SUPPORT]]
        frame_motion(W, rows[k, FI_JOINT], Jw, consts[k], support, FJ[k], Fa[k], Fp[k], FR[k])
        for r in range(3):
            pd = 0.0
            for c in range(nv):
                pd += FJ[k, r, c] * x[nQ + c]
            Fv[k, r] = pd
    return FJ, Fa, Fp, Fv, FR


@njit(cache=True)
def frame_motion(W, j, Jw, frame, support, J6, a6, p, Rf):
    """J6, a6, p, Rf of a frame on joint j (W[j]: its R by rows, p, v, a at q̈ = 0), placed by ``frame`` = [r,
    rotation by rows] in the joint's frame: plan_phi.frame_motion's arithmetic, written into the given arrays."""
    r0, r1, r2 = frame[0], frame[1], frame[2]
    for i in range(3):
        p[i] = W[j, 9 + i] + W[j, 3 * i] * r0 + W[j, 3 * i + 1] * r1 + W[j, 3 * i + 2] * r2
        for k in range(3):
            Rf[i, k] = W[j, 3 * i] * frame[3 + k] + W[j, 3 * i + 1] * frame[6 + k] + W[j, 3 * i + 2] * frame[9 + k]
    for c in support:
        wx, wy, wz = Jw[3, c], Jw[4, c], Jw[5, c]
        J6[0, c] = Jw[0, c] + (wy * p[2] - wz * p[1])
        J6[1, c] = Jw[1, c] + (wz * p[0] - wx * p[2])
        J6[2, c] = Jw[2, c] + (wx * p[1] - wy * p[0])
        J6[3, c], J6[4, c], J6[5, c] = wx, wy, wz
    vj, aj = W[j, 12:18], W[j, 18:24]
    wx, wy, wz = vj[3], vj[4], vj[5]
    vx = vj[0] + (wy * r2 - wz * r1)  # the point's velocity, in the joint's frame [m/s]
    vy = vj[1] + (wz * r0 - wx * r2)
    vz = vj[2] + (wx * r1 - wy * r0)
    ax = aj[0] + (aj[4] * r2 - aj[5] * r1) + (wy * vz - wz * vy)  # its classical acceleration [m/s²]
    ay = aj[1] + (aj[5] * r0 - aj[3] * r2) + (wz * vx - wx * vz)
    az = aj[2] + (aj[3] * r1 - aj[4] * r0) + (wx * vy - wy * vx)
    for i in range(3):
        a6[i] = W[j, 3 * i] * ax + W[j, 3 * i + 1] * ay + W[j, 3 * i + 2] * az
        a6[3 + i] = W[j, 3 * i] * aj[3] + W[j, 3 * i + 1] * aj[4] + W[j, 3 * i + 2] * aj[5]
