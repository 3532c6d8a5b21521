"""A plan's call after Pinocchio, compiled: a dynamic tip law through the drives, folded or not.

For a mode whose controller is a force-reading tip law read off as a matrix M
(:mod:`contactdyn.plan_law`) and whose drives are a matrix L (:mod:`contactdyn.plan_drives`),
everything a call does after φ is small dense algebra:

    y = P φ = [A, b, o]                          the KKT system and the affine outputs
    u ← o's measured forces;  [a*, f_swap, ż] = M u      the law's tip targets
    τ_c = Σ_f J_fᵀ w_f;   τ = computed torque   (contactdyn.controllers.computed_torque)
    rows λ the law reads:  B = ∂τ/∂λ (+ A's column of a row reaching beyond the robot)
    A[:nQ, λ] −= L_τ B;   b[:nQ] += L[:nQ] [τ, x, 1];   z = A⁻¹ b;   ż += D_z λ
    ẋ = [Q̇, Q̈, ẏ] with ż in its slots

:func:`call` runs it in one compiled function (numba). The fold itself (:func:`fold_solve`) is
the one :mod:`contactdyn.plan_fold` runs for the output and the carried references. A call
where a voltage clips, or whose solve is singular or not finite, returns status 1 and goes the
plan's readable way (:mod:`contactdyn.plan_rhs`): the clip and the least-squares fallback stay
written once, there. Built when the plan's law has read M (its first call).
"""

from __future__ import annotations

import numpy as np
from numba import njit
from scipy import sparse

from .controllers import computed_torque as law
from .linalg import lu_solve, mm, mtv, mv
from .plan_law import CompiledLaw, compiled_law, plan_inputs

__all__ = ["fold_solve", "kernel_of", "call"]

OK, DECLINED = 0, 1  #: :func:`call`'s status
#: the constants of a plan's call, packed by :func:`pack` into one float and one int buffer (two arguments: a
#: compiled function's call costs ~0.06 µs per argument): float arrays, then int arrays, by these indices
P_VAL, M_, U_X, L_, L_TAU, D_A, D_F, D_Z, ROTOR, D_CTL, K_NULL = range(11)  # floats (P: CSR values)
P_COL, P_ROW, INTS, FRAMES, FORCES, COLS, REACH = range(11, 18)  # ints (P: CSR columns, row starts)
#: INTS: m nQ nv i_h i_J i_dr tip u_f zs swap n_lim o_y0 o_y1 x_z0 x_z1 w0 (see :func:`call`)


def pack(floats: list, ints: list) -> tuple[np.ndarray, np.ndarray]:
    """(fb, ib): the float arrays one after another in fb, the int arrays in ib after a table of
    (offset, rows, columns) per array, floats first (a vector has one row)."""
    floats = [np.atleast_2d(np.asarray(a, dtype=float)) for a in floats]
    ints = [np.atleast_2d(np.asarray(a, dtype=np.int64)) for a in ints]
    table, offset = [], 0
    for a in floats:
        table += [offset, *a.shape]
        offset += a.size
    offset = 3 * (len(floats) + len(ints))
    for a in ints:
        table += [offset, *a.shape]
        offset += a.size
    fb = np.concatenate([a.ravel() for a in floats]) if floats else np.zeros(0)
    ib = np.concatenate([np.array(table, dtype=np.int64)] + [a.ravel() for a in ints])
    return fb, ib


@njit(cache=True)
def _mat(fb, ib, k):
    """Float array k of :func:`pack`'s buffers, as a (rows, columns) view."""
    o, r, c = ib[3 * k], ib[3 * k + 1], ib[3 * k + 2]
    return fb[o:o + r * c].reshape((r, c))


@njit(cache=True)
def _vec(buf, ib, k):
    """Array k of :func:`pack`'s buffers (``buf``: fb for a float array, ib for an int array), flat."""
    o, r, c = ib[3 * k], ib[3 * k + 1], ib[3 * k + 2]
    return buf[o:o + r * c]


@njit(cache=True)
def fold_solve(A, b, L, L_tau, tau, x, B, cols, nQ):
    """(z, y₀, Y): z of A z = b with the drives' forces at the command τ + B z[cols] [N·m or N] folded into
    rows :nQ (A, b changed in place; L: [forces; u/u_max] = L [τ, x, 1]; z nan where A is singular), and
    the drive values y₀ = L [τ, x, 1], Y = L_τ B: y₀ + Y z[cols] at the solved command (the voltages' clip
    test reads its rows nQ:)."""
    nv, n = tau.size, x.size
    txo = np.empty(nv + n + 1)
    txo[:nv] = tau
    txo[nv:nv + n] = x
    txo[-1] = 1.0
    y0 = mv(L, txo)
    Y = mm(L_tau, B)
    for k in range(cols.size):
        for i in range(nQ):
            A[i, cols[k]] -= Y[i, k]
    for i in range(nQ):
        b[i] += y0[i]
    return lu_solve(A, b), y0, Y


@njit(cache=True)
def call(phi, x, u, fb, ib, out):
    """The status of the module docstring's call, its [ẋ, z, o, τ] written into ``out`` (τ: the solved joint
    command [N·m or N; V], what the drives make of it); fb, ib: the plan's constants (:func:`pack`); u: the
    law's inputs' time part (plan_law.plan_inputs), U_X its state part's map. INTS: sizes and offsets (zs the
    ż rows of M u, −1 none; x_z0:x_z1 the law's states in x and ẋ; tip the tip's p, ṗ in φ; u_f the forces in
    u; w0 the frame forces in z); FRAMES: each frame's J offset in φ;
    FORCES: o's measured forces in u's order; COLS: the folded columns of A (the rows' λ, then a carrying
    body's Q̈_b), with D_A, D_F, D_Z per column; REACH: the rows whose A column beyond the robot joins B."""
    m, nQ, nv, i_h, i_J, i_dr, tip, u_f, zs, swap, n_lim, o_y0, o_y1, x_z0, x_z1, w0 = _vec(ib, ib, INTS)
    m2 = m * m
    p_val, p_col, p_row = _vec(fb, ib, P_VAL), _vec(ib, ib, P_COL), _vec(ib, ib, P_ROW)
    y = np.empty(p_row.size - 1)  # y = P φ, P sparse by rows
    for i in range(y.size):
        acc = 0.0
        for k in range(p_row[i], p_row[i + 1]):
            acc += p_val[k] * phi[p_col[k]]
        y[i] = acc
    A = y[:m2].copy().reshape((m, m))
    b = y[m2:m2 + m].copy()
    o = y[m2 + m:]
    U = _mat(fb, ib, U_X)  # [U_x, u_c]: the law's inputs' state part
    uu = u + mv(U[:, :x.size], x) + U[:, x.size]
    uu[:6] = phi[tip:tip + 6]  # p_tip [m], ṗ_tip [m/s]
    forces = _vec(ib, ib, FORCES)
    for k in range(forces.size):
        uu[u_f + k] = o[forces[k]]
    targets = mv(_mat(fb, ib, M_), uu)
    H = phi[:nv * nv].reshape((nv, nv)).T + _mat(fb, ib, D_CTL)  # φ holds H column by column
    J = phi[i_J:i_J + 3 * nv].reshape((3, nv))
    tau_c = np.zeros(nv)
    frames = _vec(ib, ib, FRAMES)
    for f in range(frames.size):
        tau_c += mtv(phi[frames[f]:frames[f] + 3 * nv].reshape((3, nv)), b[w0 + 3 * f:w0 + 3 * f + 3])
    Jp = law.pinv(J)
    rotor = _vec(fb, ib, ROTOR)
    f_swap = targets[3:6] if swap else targets[0:0]
    tau = law.torque(H, rotor, phi[i_h:i_h + nv], tau_c, J, Jp, phi[i_dr:i_dr + 3], x[nQ:nQ + nv],
                     targets[:3], f_swap, _vec(fb, ib, K_NULL)[0])
    B = law.increments(H, rotor, J, Jp, _mat(fb, ib, D_A), _mat(fb, ib, D_F))
    reach = _vec(ib, ib, REACH)
    for k in range(reach.size):
        for i in range(nv):
            B[i, reach[k]] += A[i, nQ + reach[k]]
    cols = _vec(ib, ib, COLS)
    z, y0, Y = fold_solve(A, b, _mat(fb, ib, L_), _mat(fb, ib, L_TAU), tau, x, B, cols, nQ)
    if not np.isfinite(z.dot(z)):
        return DECLINED
    folded = z[cols]
    if n_lim and np.abs(y0[nQ:] + mv(Y[nQ:], folded)).max() > 1.0:
        return DECLINED
    n = x.size
    xd, z_out, o_out = out[:n], out[n:n + m], out[n + m:n + m + o.size]
    xd[:nQ] = x[nQ:2 * nQ]
    xd[nQ:2 * nQ] = z[:nQ]
    xd[2 * nQ:] = y[o_y0:o_y1]
    if zs >= 0:
        xd[x_z0:x_z1] = targets[zs:] + mv(_mat(fb, ib, D_Z), folded)
    z_out[:] = z
    o_out[:] = o
    out[n + m + o.size:] = tau + mv(B, folded)
    return OK


def kernel_of(plan, meta: list, reach: list[int] | None):
    """kernel(t, x, φ) -> (ẋ, z, o), or None for a call that goes the readable way (a clip, a singular solve,
    the law's M not read yet); ``kernel.samples(ts, X)`` -> (Φ, O, Z, τ) of the output's samples, or None
    where one declines. None where the plan's mode is not one :func:`call` covers: a force-reading tip law by
    its matrix through compiled drives, no sliding friction, no slide launching from rest, and the rows' reach
    beyond the robot constant (``reach``, plan_fold's). ``meta``: the rows as the law's ``row_columns``
    reads them."""
    ctl = compiled_law(plan)
    covered = (isinstance(ctl, CompiledLaw) and ctl.reason is None and plan.compiled_drives is not None
               and plan.friction_terms is None and plan.launch is None and (reach is not None or not plan.nr))
    if not covered:
        return None
    s = plan.system
    n, m, no = s.n, plan.m, plan.P.shape[0] - plan.m * (plan.m + 1)
    size = n + m + no + s.nv
    constants = None

    def ready() -> bool:
        nonlocal constants
        if constants is None and ctl.M is not None:
            constants = _constants(plan, ctl, meta, reach or [], plan_inputs(plan, ctl))
        return constants is not None

    def kernel(t, x, phi):
        if not ready():
            return None
        inputs, (fb, ib) = constants
        out = np.empty(size)
        if call(phi, x, inputs.time_part(t), fb, ib, out):
            return None
        return out[:n], out[n:n + m], out[n + m:n + m + no]

    def samples(ts, X):
        if not ready():
            return None
        inputs, (fb, ib) = constants
        N = len(ts)
        tv = plan.time_terms.at_times(ts)
        Phi, out = np.empty((N, plan.P.shape[1])), np.empty((N, size))
        for k in range(N):
            Phi[k] = phi = plan.phi_at(ts[k], X[k], tv[k])
            if call(phi, X[k], inputs.time_part(ts[k]), fb, ib, out[k]):
                return None
        return Phi, out[:, n + m:n + m + no], out[:, n:n + m], out[:, n + m + no:]

    kernel.samples = samples
    return kernel


def _constants(plan, ctl, meta, reach, inputs) -> tuple:
    """(inputs, the constant arguments of :func:`call`) of a plan whose law has read M."""
    s, drives, law = plan.system, plan.compiled_drives, ctl.ctl
    nQ, nv, nr, m = s.nQ, s.nv, plan.nr, plan.m
    tf = plan.tip_frame
    off = m * m + m  # o's start in y
    D_a, D_f, D_z = ctl.row_columns(meta)
    cols = list(range(nQ, nQ + nr))
    if plan.phase.carrier is not None:  # a reference carried by body coordinate i_b: ∂/∂Q̈_b, one more column
        i_b, axis = plan.phase.carrier
        d = ctl.M[:, 12:15].dot(axis)  # the tip targets per unit [m/s²] of ẍ_d along the axis
        D_a = np.column_stack((D_a, d[:3]))
        D_f = None if D_f is None else np.column_stack((D_f, d[3:6]))
        D_z = None if D_z is None else np.column_stack((D_z, d[ctl.zs]))
        cols.append(i_b)
    none = np.empty((0, len(cols)))
    P = sparse.csr_matrix(plan.P)
    ints = [m, nQ, nv, plan.i_h, plan.i_J[tf], plan.i_dr[tf], inputs.tip, ctl.i_forces,
            ctl.zs.start if ctl.zs is not None else -1, int(ctl.swap), len(drives.limited),
            off + plan.o_y.start, off + plan.o_y.stop, plan.z_slice.start, plan.z_slice.stop, nQ + nr]
    D_ctl = s._D_ctl if s._D_ctl is not None else np.zeros((nv, nv))
    floats = [P.data, ctl.M, inputs.state_map(), drives.L, drives.L_tau, D_a, none if D_f is None else D_f,
              none if D_z is None else D_z, law._rotor_c, D_ctl, [law.config.k_null]]
    return inputs, pack(floats, [P.indices, P.indptr, ints, plan.i_J, inputs.forces, cols, reach])
