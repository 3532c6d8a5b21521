"""The pipeline's first stage: the robot's terms and its frames' kinematics at (q, q̇), over the packed arrays.

H [kg·m²], h and g [N·m or N] and the joint Jacobians (WORLD, 6 × nf) by :mod:`contactdyn.robot.rigid_body`'s
algorithms (as its ``rigid_terms``, every joint's placement and motion kept), over the rigid-body table's nf = NF
columns: the robot's nv, then the articulated bodies' coordinates (one forest,
:func:`contactdyn.robot.rigid_body.forest_table`; nf = nv without one); then each packed frame's J (6 × nf,
LOCAL_WORLD_ALIGNED, linear rows first), J̇q̇ (6) [m/s², rad/s²], p [m], ṗ = J q̇ [m/s] and R, by
:func:`frame_motion` over the joints' table W (:func:`contactdyn.robot.rigid_body.frame_motion_into`: one
source). The controller sees the robot alone (:func:`robot_part`: H, h, g and the frames' J over its nv joints).
A free body's rows of the table and its frames' placements are its chart's (:func:`table_at`, ``FI_CHART``: chart
B's where x's chart slot holds 1, as ``ArticulatedBody.chart_of`` reads it), so one packed mode runs in either chart.
"""

from __future__ import annotations

import numpy as np

from ...numerics.compile_cache import njit
from ...robot.rigid_body import WIDTH, _inertia, _jacobians, _kinematics, _nonlinear, frame_motion_into
from .pack import (
    CHT_N,
    CHT_REALS,
    CHT_ROW,
    CHT_SLOT,
    CHT_W,
    FI_CHART,
    FI_JOINT,
    FI_N_SUPPORT,
    FI_SUPPORT,
    FI_W,
    FR_W,
    I_CHARTS,
    I_FRAMES,
    N_CHARTS,
    N_FRAMES,
    NEEDS_GRAVITY,
    NF,
    NJ,
    NQ,
    NV,
    R_FRAMES,
    R_FRAMES_B,
    R_RIGID,
    section,
)

__all__ = ["robot_terms", "table_at", "in_chart_b", "frame_terms", "frame_motion", "robot_part"]


@njit(cache=True)
def robot_terms(x, ints, reals):
    """(H (nf, nf), h (nf), g (nf, or empty when nobody asks), J (6, nf) per joint column, W: every joint's world
    rotation and position, velocity and acceleration at q̈ = 0 (rigid_body's table)); nf = NF, the table's
    columns (the robot's, then the articulated bodies')."""
    nf, nQ = ints[NF], ints[NQ]
    table = table_at(x, ints, reals)
    L, W = _kinematics(x[:nf], x[nQ:nQ + nf], table)
    H, h, J = np.zeros((nf, nf)), np.zeros(nf), np.zeros((6, nf))
    g = np.zeros(nf if ints[NEEDS_GRAVITY] else 0)
    _nonlinear(table, L, W, h)
    _jacobians(table, W, J)
    _inertia(table, W, J, H, g)
    return H, h, g, J, W


@njit(cache=True)
def table_at(x, ints, reals):
    """The rigid-body table at the state x: the packed one (chart A's), each free body's rows replaced by its chart
    B's while x is in chart B (a copy then; the packed table itself while every free body is in chart A)."""
    table = section(reals, ints[R_RIGID], ints[NJ], WIDTH)
    charts = section(ints, ints[I_CHARTS], ints[N_CHARTS], CHT_W)
    if not any_in_chart_b(x, charts):
        return table
    out = table.copy()
    for k in range(charts.shape[0]):
        if in_chart_b(x, charts[k, CHT_SLOT]):
            turned = section(reals, charts[k, CHT_REALS], charts[k, CHT_N], WIDTH)
            for r in range(charts[k, CHT_N]):  # (element by element: no 2-D slice assignment's shape check)
                for c in range(WIDTH):
                    out[charts[k, CHT_ROW] + r, c] = turned[r, c]
    return out


@njit(cache=True, inline="always")
def any_in_chart_b(x, charts):
    """Is any free body of ``charts`` (the packed rows, CHT_W wide) in chart B at the state x?"""
    for k in range(charts.shape[0]):
        if in_chart_b(x, charts[k, CHT_SLOT]):
            return True
    return False


@njit(cache=True, inline="always")
def in_chart_b(x, slot):
    """Is the free body whose chart is x[slot] in chart B? (int() of the slot, as ``ArticulatedBody.chart_of``.)"""
    return slot >= 0 and int(x[slot]) != 0


@njit(cache=True)
def frame_terms(x, ints, reals, W, Jw):
    """Per packed frame: J (nf, 6, NF) (its columns the rigid-body table's), J̇q̇ (nf, 6), p (nf, 3) [m], ṗ (nf, 3)
    [m/s], R (nf, 3, 3); then one zero frame (row nf: what a translating body's touching point has of the table)."""
    nc, nQ, nf = ints[NF], ints[NQ], ints[N_FRAMES]
    rows = section(ints, ints[I_FRAMES], nf, FI_W)
    consts = section(reals, ints[R_FRAMES], nf, FR_W)
    turned = section(reals, ints[R_FRAMES_B], nf if ints[N_CHARTS] else 0, FR_W)  # (chart B's placements)
    FJ, Fa, Fp, Fv, FR = np.zeros((nf + 1, 6, nc)), np.zeros((nf + 1, 6)), np.zeros((nf + 1, 3)), \
        np.zeros((nf + 1, 3)), np.zeros((nf + 1, 3, 3))
    for k in range(nf):
        support = ints[rows[k, FI_SUPPORT]:rows[k, FI_SUPPORT] + rows[k, FI_N_SUPPORT]]
        placement = turned[k] if in_chart_b(x, rows[k, FI_CHART]) else consts[k]
        frame_motion(W, rows[k, FI_JOINT], Jw, placement, support, FJ[k], Fa[k], Fp[k], FR[k])
        for r in range(3):
            pd = 0.0
            for c in range(nc):
                pd += FJ[k, r, c] * x[nQ + c]
            Fv[k, r] = pd
    return FJ, Fa, Fp, Fv, FR


@njit(cache=True)
def frame_motion(W, j, Jw, frame, support, J6, a6, p, Rf):
    """J6, a6, p, Rf of a frame on joint j (W[j]: its R by rows, p, v, a at q̈ = 0), placed by ``frame`` = [r,
    rotation by rows] in the joint's frame: robot.rigid_body.frame_motion_into."""
    frame_motion_into(W[j, 0:9].reshape((3, 3)), W[j, 9:12], W[j, 12:18], W[j, 18:24], Jw, frame, support, J6, a6, p,
                      Rf)


@njit(cache=True)
def robot_part(ints, H, h, g, FJ):
    """What the controller reads of the terms: (H, h, g, FJ) of the robot alone (its nv joints' block, its frames'
    columns); the arrays themselves when the table is the robot's (NF = nv)."""
    nv = ints[NV]
    if ints[NF] == nv:
        return H, h, g, FJ
    return H[:nv, :nv].copy(), h[:nv].copy(), g[:min(nv, g.size)].copy(), FJ[:, :, :nv].copy()
