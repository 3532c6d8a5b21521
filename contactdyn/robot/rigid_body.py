"""The robot's rigid-body terms inside the one pipeline's call, as Pinocchio's ``computeAllTerms`` gives them.

The call needs, per right-hand side, H(q) (CRBA), h(q, q̇) (RNEA at q̈ = 0, with the model's gravity), the
joint Jacobians (WORLD, 6 × nv) and its frame's joint placement, velocity and acceleration at q̈ = 0 (local,
[linear, angular]). Pinocchio's binding call costs ~2.3 µs at 5 DOF, most of it the crossing and the terms we
do not read; for a tree of one-DOF revolute and prismatic joints (every URDF arm of ours and of
example-robot-data's fixed-base arms) :func:`rigid_terms` computes the same in the one pipeline's call, with
Pinocchio's algorithms and conventions (Featherstone's, in each joint's frame; H from the composite inertias
about the world origin). :func:`rigid_terms` writes them into the arrays it is given (M, nle, g, J and the
joint's placement, velocity and acceleration); the one pipeline's :mod:`contactdyn.model.pipeline.robot_terms` runs
the same algorithms into its own arrays. Any other joint
(free-flyer, spherical, an unbounded revolute's (cos, sin)) leaves the terms to Pinocchio (:func:`rigid_table`
returns None).
Checked against Pinocchio to rounding in tests/test_rigid_body.py. Units: [m], [rad], [kg], SI throughout.
The helpers only compiled code calls carry no CPython wrapper (``no_cpython_wrapper``: numba builds none, ~10 %
of a first run's compile of the leaves, contactdyn.numerics.twins).
"""

from __future__ import annotations

import numpy as np

from ..numerics.compile_cache import njit

__all__ = ["rigid_table", "forest_table", "rigid_terms", "frame_motion_into"]

REVOLUTE, PRISMATIC = 0.0, 1.0
#: one row per joint (row 0, the universe: −gravity [m/s²] in AXIS): parent, kind, velocity index, the axis in
#: the joint's frame, the joint's placement in its parent's at q = 0 (rotation by rows, translation [m]), the
#: body's mass [kg], centre of mass [m] and rotational inertia about it [kg·m²] (by rows), the armature
PARENT, KIND, IDX_V, AXIS, PLACEMENT_R, PLACEMENT_P, MASS, LEVER, INERTIA, ARMATURE, WIDTH = \
    0, 1, 2, 3, 6, 15, 18, 19, 22, 31, 32
_AXES = {"X": (1.0, 0.0, 0.0), "Y": (0.0, 1.0, 0.0), "Z": (0.0, 0.0, 1.0)}


def _kind_and_axis(joint) -> tuple[float, tuple] | None:
    """(kind, axis) of a one-DOF revolute or prismatic joint model, else None."""
    name = joint.shortname().removeprefix("JointModel")
    if joint.nq != 1 or joint.nv != 1:
        return None
    if name in ("RX", "RY", "RZ", "PX", "PY", "PZ"):
        return (REVOLUTE if name[0] == "R" else PRISMATIC), _AXES[name[1]]
    if name in ("RevoluteUnaligned", "PrismaticUnaligned"):
        return (REVOLUTE if name[0] == "R" else PRISMATIC), tuple(float(a) for a in joint.extract().axis)
    return None


def rigid_table(model) -> np.ndarray | None:
    """:func:`rigid_terms`'s table of a Pinocchio model, or None where a joint is not one it computes."""
    nj = model.njoints
    if nj < 2 or model.nq != model.nv:
        return None
    table = np.zeros((nj, WIDTH))
    table[0, AXIS:AXIS + 3] = -np.asarray(model.gravity.linear)
    for j in range(1, nj):
        joint = model.joints[j]
        kind_axis = _kind_and_axis(joint)
        if kind_axis is None:
            return None
        placement, inertia = model.jointPlacements[j], model.inertias[j]
        table[j, PARENT], table[j, IDX_V] = model.parents[j], joint.idx_v
        table[j, KIND], table[j, AXIS:AXIS + 3] = kind_axis
        table[j, PLACEMENT_R:PLACEMENT_R + 9] = placement.rotation.ravel()
        table[j, PLACEMENT_P:PLACEMENT_P + 3] = placement.translation
        table[j, MASS] = inertia.mass
        table[j, LEVER:LEVER + 3] = inertia.lever
        table[j, INERTIA:INERTIA + 9] = inertia.inertia.ravel()
        table[j, ARMATURE] = model.armature[joint.idx_v]
    return table


def forest_table(table: np.ndarray, bodies: list[tuple[np.ndarray, int]]) -> tuple[np.ndarray, list[int]]:
    """One table for the robot and other trees fixed in the world (articulated bodies): each body's joints (its
    table's rows after the universe, ``bodies``: (its table, its first coordinate's index in Q)) appended after the
    robot's, their parents re-indexed (a root's parent the universe, row 0) and IDX_V their indices in Q; (the
    table, per body the row of its joint 1). The trees share the universe's row (the robot's gravity): H, h and J
    of the forest are the robot's and each body's side by side (no joint supports another tree's)."""
    rows, starts = [table], []
    at = table.shape[0]
    for own, first in bodies:
        extra = own[1:].copy()
        parents = extra[:, PARENT]
        extra[:, PARENT] = np.where(parents > 0, parents + at - 1, 0.0)
        extra[:, IDX_V] += first
        rows.append(extra)
        starts.append(at)
        at += extra.shape[0]
    return np.vstack(rows), starts


@njit(cache=True)
def rigid_terms(q, v, table, j0, M, nle, g, R, pj, vj, aj, J):
    """Pinocchio's ``computeAllTerms`` terms at (q, q̇) [rad or m, rad/s or m/s] the pipeline reads, written in place:
    M (full) [kg·m²], nle, g (if g.size; the generalized gravity) [N·m or N], J (WORLD joint Jacobians, 6 × nv)
    and joint j0's world rotation R and position pj [m], and its velocity vj [m/s, rad/s] and acceleration aj at
    q̈ = 0 [m/s², rad/s²] (in its frame, [linear, angular])."""
    nj = table.shape[0]
    L, W = _kinematics(q, v, table)
    _nonlinear(table, L, W, nle)
    _jacobians(table, W, J)
    _inertia(table, W, J, M, g)
    for i in range(3):
        pj[i] = W[j0, 9 + i]
        for k in range(3):
            R[i, k] = W[j0, 3 * i + k]
    for i in range(6):
        vj[i] = W[j0, 12 + i]
        aj[i] = W[j0, 18 + i]
    return nj


@njit(cache=True)
def _kinematics(q, v, table):
    """Per joint, L = its placement in its parent's [R (9, by rows), p (3)] and W = [world R (9), p (3), v (6),
    a at q̈ = 0 (6), a − gravity (6), the RNEA force (6)], velocities and forces in the joint's frame."""
    nj = table.shape[0]
    L, W = np.empty((nj, 12)), np.zeros((nj, 36))
    W[0, 0] = W[0, 4] = W[0, 8] = 1.0
    for i in range(3):
        W[0, 24 + i] = table[0, AXIS + i]  # the universe's acceleration: −gravity
    for j in range(1, nj):
        par, iv = int(table[j, PARENT]), int(table[j, IDX_V])
        ux, uy, uz = table[j, AXIS], table[j, AXIS + 1], table[j, AXIS + 2]
        _placement(table, j, q[iv], L)
        for r in range(3):  # oMi = oMi[parent] · liMi
            for c in range(3):
                W[j, 3 * r + c] = W[par, 3 * r] * L[j, c] + W[par, 3 * r + 1] * L[j, 3 + c] \
                    + W[par, 3 * r + 2] * L[j, 6 + c]
            W[j, 9 + r] = W[par, 9 + r] + W[par, 3 * r] * L[j, 9] + W[par, 3 * r + 1] * L[j, 10] \
                + W[par, 3 * r + 2] * L[j, 11]
        for base in (12, 18, 24):  # the parent's v, a, a_gf seen in this joint's frame (liMi.actInv)
            _act_inv(L, j, W, par, base)
        w = v[iv]
        sl, sa = (0.0, w) if table[j, KIND] == REVOLUTE else (w, 0.0)  # S q̇: [linear, angular] scale of the axis
        W[j, 12] += sl * ux
        W[j, 13] += sl * uy
        W[j, 14] += sl * uz
        W[j, 15] += sa * ux
        W[j, 16] += sa * uy
        W[j, 17] += sa * uz
        _add_cross(W, j, sl * ux, sl * uy, sl * uz, sa * ux, sa * uy, sa * uz)  # + v × S q̇ on a and a_gf
        _rnea_force(table, j, W)
    return L, W


@njit(cache=True, no_cpython_wrapper=True)
def _placement(table, j, qj, L):
    """L[j] = the joint's placement at q = 0 times its motion by qj [rad or m]."""
    ux, uy, uz = table[j, AXIS], table[j, AXIS + 1], table[j, AXIS + 2]
    R0 = table[j, PLACEMENT_R:PLACEMENT_R + 9]
    if table[j, KIND] == REVOLUTE:  # Rodrigues
        c, s = np.cos(qj), np.sin(qj)
        t = 1.0 - c
        m = ((t * ux * ux + c, t * ux * uy - s * uz, t * ux * uz + s * uy),
             (t * ux * uy + s * uz, t * uy * uy + c, t * uy * uz - s * ux),
             (t * ux * uz - s * uy, t * uy * uz + s * ux, t * uz * uz + c))
        d = (0.0, 0.0, 0.0)
    else:
        m = ((1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0))
        d = (ux * qj, uy * qj, uz * qj)
    for r in range(3):
        for c_ in range(3):
            L[j, 3 * r + c_] = R0[3 * r] * m[0][c_] + R0[3 * r + 1] * m[1][c_] + R0[3 * r + 2] * m[2][c_]
        L[j, 9 + r] = table[j, PLACEMENT_P + r] + R0[3 * r] * d[0] + R0[3 * r + 1] * d[1] + R0[3 * r + 2] * d[2]


@njit(cache=True, no_cpython_wrapper=True)
def _act_inv(L, j, W, par, base):
    """W[j, base:base + 6] = liMi⁻¹ · W[par, base:base + 6] (a motion: linear Rᵀ(v − p × ω), angular Rᵀ ω)."""
    vx, vy, vz = W[par, base], W[par, base + 1], W[par, base + 2]
    wx, wy, wz = W[par, base + 3], W[par, base + 4], W[par, base + 5]
    px, py, pz = L[j, 9], L[j, 10], L[j, 11]
    lx, ly, lz = vx - (py * wz - pz * wy), vy - (pz * wx - px * wz), vz - (px * wy - py * wx)
    for r in range(3):
        W[j, base + r] = L[j, r] * lx + L[j, 3 + r] * ly + L[j, 6 + r] * lz
        W[j, base + 3 + r] = L[j, r] * wx + L[j, 3 + r] * wy + L[j, 6 + r] * wz


@njit(cache=True, no_cpython_wrapper=True)
def _add_cross(W, j, sx, sy, sz, tx, ty, tz):
    """a and a_gf of joint j += v × (s, t), the motion cross product with the joint's own motion S q̇ = (s, t)."""
    vx, vy, vz, wx, wy, wz = W[j, 12], W[j, 13], W[j, 14], W[j, 15], W[j, 16], W[j, 17]
    c = (wy * sz - wz * sy + vy * tz - vz * ty, wz * sx - wx * sz + vz * tx - vx * tz,
         wx * sy - wy * sx + vx * ty - vy * tx, wy * tz - wz * ty, wz * tx - wx * tz, wx * ty - wy * tx)
    for i in range(6):
        W[j, 18 + i] += c[i]
        W[j, 24 + i] += c[i]


@njit(cache=True, no_cpython_wrapper=True)
def _inertia_times(table, j, vx, vy, vz, wx, wy, wz):
    """The body's spatial inertia (its frame) times a motion (v, ω): (m (v − c × ω), I_c ω + c × that)."""
    m, c0, c1, c2 = table[j, MASS], table[j, LEVER], table[j, LEVER + 1], table[j, LEVER + 2]
    I = table[j, INERTIA:INERTIA + 9]
    hx, hy, hz = m * (vx - (c1 * wz - c2 * wy)), m * (vy - (c2 * wx - c0 * wz)), m * (vz - (c0 * wy - c1 * wx))
    return (hx, hy, hz, I[0] * wx + I[1] * wy + I[2] * wz + c1 * hz - c2 * hy,
            I[3] * wx + I[4] * wy + I[5] * wz + c2 * hx - c0 * hz,
            I[6] * wx + I[7] * wy + I[8] * wz + c0 * hy - c1 * hx)


@njit(cache=True, no_cpython_wrapper=True)
def _rnea_force(table, j, W):
    """W[j, 30:36] = I a_gf + v ×* (I v), the body's force of the RNEA at q̈ = 0 (gravity in a_gf)."""
    vx, vy, vz, wx, wy, wz = W[j, 12], W[j, 13], W[j, 14], W[j, 15], W[j, 16], W[j, 17]
    hx, hy, hz, nx, ny, nz = _inertia_times(table, j, vx, vy, vz, wx, wy, wz)
    Hx, Hy, Hz, Nx, Ny, Nz = _inertia_times(table, j, W[j, 24], W[j, 25], W[j, 26], W[j, 27], W[j, 28], W[j, 29])
    W[j, 30] = Hx + wy * hz - wz * hy
    W[j, 31] = Hy + wz * hx - wx * hz
    W[j, 32] = Hz + wx * hy - wy * hx
    W[j, 33] = Nx + wy * nz - wz * ny + vy * hz - vz * hy
    W[j, 34] = Ny + wz * nx - wx * nz + vz * hx - vx * hz
    W[j, 35] = Nz + wx * ny - wy * nx + vx * hy - vy * hx


@njit(cache=True)
def _nonlinear(table, L, W, nle):
    """nle = Sᵀ f per joint, the forces carried to the parents (liMi · f) from the leaves in."""
    for j in range(table.shape[0] - 1, 0, -1):
        par, iv = int(table[j, PARENT]), int(table[j, IDX_V])
        o = 33 if table[j, KIND] == REVOLUTE else 30
        nle[iv] = table[j, AXIS] * W[j, o] + table[j, AXIS + 1] * W[j, o + 1] + table[j, AXIS + 2] * W[j, o + 2]
        if par == 0:
            continue
        fx, fy, fz, nx, ny, nz = W[j, 30], W[j, 31], W[j, 32], W[j, 33], W[j, 34], W[j, 35]
        Fx = L[j, 0] * fx + L[j, 1] * fy + L[j, 2] * fz
        Fy = L[j, 3] * fx + L[j, 4] * fy + L[j, 5] * fz
        Fz = L[j, 6] * fx + L[j, 7] * fy + L[j, 8] * fz
        px, py, pz = L[j, 9], L[j, 10], L[j, 11]
        W[par, 30] += Fx
        W[par, 31] += Fy
        W[par, 32] += Fz
        W[par, 33] += L[j, 0] * nx + L[j, 1] * ny + L[j, 2] * nz + py * Fz - pz * Fy
        W[par, 34] += L[j, 3] * nx + L[j, 4] * ny + L[j, 5] * nz + pz * Fx - px * Fz
        W[par, 35] += L[j, 6] * nx + L[j, 7] * ny + L[j, 8] * nz + px * Fy - py * Fx


@njit(cache=True)
def _jacobians(table, W, J):
    """J's column of each joint: its motion subspace in WORLD at the origin, [R s + p × R t, R t]."""
    for j in range(1, table.shape[0]):
        iv = int(table[j, IDX_V])
        ax = (table[j, AXIS], table[j, AXIS + 1], table[j, AXIS + 2])
        wa = (W[j, 0] * ax[0] + W[j, 1] * ax[1] + W[j, 2] * ax[2], W[j, 3] * ax[0] + W[j, 4] * ax[1] + W[j, 5] * ax[2],
              W[j, 6] * ax[0] + W[j, 7] * ax[1] + W[j, 8] * ax[2])  # the axis in WORLD
        if table[j, KIND] == REVOLUTE:
            px, py, pz = W[j, 9], W[j, 10], W[j, 11]
            J[0, iv], J[1, iv], J[2, iv] = py * wa[2] - pz * wa[1], pz * wa[0] - px * wa[2], px * wa[1] - py * wa[0]
            J[3, iv], J[4, iv], J[5, iv] = wa[0], wa[1], wa[2]
        else:
            J[0, iv], J[1, iv], J[2, iv] = wa[0], wa[1], wa[2]
            J[3, iv] = J[4, iv] = J[5, iv] = 0.0


@njit(cache=True)
def _inertia(table, W, J, M, g):
    """M by the composite inertias about the world origin (mass, first moment m c, rotational inertia I_o), summed
    from the leaves in: M[k, j] = J_kᵀ (Y_j J_j) for k on j's support; g (if g.size) = J_jᵀ (Y_j a_g) likewise."""
    nj = table.shape[0]
    C = np.zeros((nj, 13))  # m, m c (3), I_o (9, by rows)
    for j in range(1, nj):
        m = table[j, MASS]
        Rw = W[j, 0:9]
        lx, ly, lz = table[j, LEVER], table[j, LEVER + 1], table[j, LEVER + 2]
        c = (W[j, 9] + Rw[0] * lx + Rw[1] * ly + Rw[2] * lz, W[j, 10] + Rw[3] * lx + Rw[4] * ly + Rw[5] * lz,
             W[j, 11] + Rw[6] * lx + Rw[7] * ly + Rw[8] * lz)  # the centre of mass in WORLD [m]
        cc = c[0] * c[0] + c[1] * c[1] + c[2] * c[2]
        C[j, 0] = m
        for r in range(3):
            C[j, 1 + r] = m * c[r]
            for k in range(3):  # R I_c Rᵀ + m (|c|² 1 − c cᵀ)
                s = 0.0
                for a in range(3):
                    s += Rw[3 * r + a] * (table[j, INERTIA + 3 * a] * Rw[3 * k] + table[j, INERTIA + 3 * a + 1]
                                          * Rw[3 * k + 1] + table[j, INERTIA + 3 * a + 2] * Rw[3 * k + 2])
                C[j, 4 + 3 * r + k] = s + m * ((cc if r == k else 0.0) - c[r] * c[k])
    for j in range(nj - 1, 0, -1):
        par = int(table[j, PARENT])
        if par > 0:
            for i in range(13):
                C[par, i] += C[j, i]
    for j in range(1, nj):
        iv = int(table[j, IDX_V])
        F = _composite_times(C, j, J[0, iv], J[1, iv], J[2, iv], J[3, iv], J[4, iv], J[5, iv])
        k = j
        while k > 0:
            ik = int(table[k, IDX_V])
            s = 0.0
            for i in range(6):
                s += J[i, ik] * F[i]
            M[ik, iv] = s
            M[iv, ik] = s
            k = int(table[k, PARENT])
        M[iv, iv] += table[j, ARMATURE]
        if g.size:
            G = _composite_times(C, j, table[0, AXIS], table[0, AXIS + 1], table[0, AXIS + 2], 0.0, 0.0, 0.0)
            g[iv] = J[0, iv] * G[0] + J[1, iv] * G[1] + J[2, iv] * G[2] + J[3, iv] * G[3] + J[4, iv] * G[4] \
                + J[5, iv] * G[5]


@njit(cache=True, no_cpython_wrapper=True)
def _composite_times(C, j, vx, vy, vz, wx, wy, wz):
    """Composite inertia j (about the world origin) times a motion (v, ω) at the origin: (m v − mc × ω,
    mc × v + I_o ω)."""
    m, cx, cy, cz = C[j, 0], C[j, 1], C[j, 2], C[j, 3]
    hx, hy, hz = m * vx - (cy * wz - cz * wy), m * vy - (cz * wx - cx * wz), m * vz - (cx * wy - cy * wx)
    I = C[j, 4:13]
    return (hx, hy, hz, cy * vz - cz * vy + I[0] * wx + I[1] * wy + I[2] * wz,
            cz * vx - cx * vz + I[3] * wx + I[4] * wy + I[5] * wz,
            cx * vy - cy * vx + I[6] * wx + I[7] * wy + I[8] * wz)


@njit(cache=True, inline="always")
def frame_motion_into(R, pj, vj, aj, Jw, frame, support, J6, a6, p, Rf):
    """A frame's J6 (its support's columns), a6, p [m] and R_f written into the given arrays, in LOCAL_WORLD_ALIGNED
    as Pinocchio's getFrameJacobian (6 × nv, rows linear then angular) and getFrameClassicalAcceleration at q̈ = 0
    [m/s², rad/s²], from its joint's R, p_j, (v, ω), (a, α) (the joint's own [linear, angular]) and the joint
    Jacobians Jw (WORLD, at the origin); ``frame`` = [r, rotation by rows] in the joint's frame, ``support`` the
    joints' columns that move it: p = p_j + R r;  J's column c = [v_c + ω_c × p, ω_c];
    J̇q̇ = R (a + α × r + ω × (v + ω × r)) and R α."""
    r0, r1, r2 = frame[0], frame[1], frame[2]
    for i in range(3):
        p[i] = pj[i] + R[i, 0] * r0 + R[i, 1] * r1 + R[i, 2] * r2
        for k in range(3):
            Rf[i, k] = R[i, 0] * frame[3 + k] + R[i, 1] * frame[6 + k] + R[i, 2] * frame[9 + k]
    for c in support:
        wx, wy, wz = Jw[3, c], Jw[4, c], Jw[5, c]
        J6[0, c] = Jw[0, c] + (wy * p[2] - wz * p[1])
        J6[1, c] = Jw[1, c] + (wz * p[0] - wx * p[2])
        J6[2, c] = Jw[2, c] + (wx * p[1] - wy * p[0])
        J6[3, c], J6[4, c], J6[5, c] = wx, wy, wz
    wx, wy, wz = vj[3], vj[4], vj[5]
    vx = vj[0] + (wy * r2 - wz * r1)  # the point's velocity, in the joint's frame [m/s]
    vy = vj[1] + (wz * r0 - wx * r2)
    vz = vj[2] + (wx * r1 - wy * r0)
    ax = aj[0] + (aj[4] * r2 - aj[5] * r1) + (wy * vz - wz * vy)  # its classical acceleration [m/s²]
    ay = aj[1] + (aj[5] * r0 - aj[3] * r2) + (wz * vx - wx * vz)
    az = aj[2] + (aj[3] * r1 - aj[4] * r0) + (wx * vy - wy * vx)
    for i in range(3):
        a6[i] = R[i, 0] * ax + R[i, 1] * ay + R[i, 2] * az
        a6[3 + i] = R[i, 0] * aj[3] + R[i, 1] * aj[4] + R[i, 2] * aj[5]
