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

from .controllers import computed_torque as law
from .linalg import lu_solve
from .plan_law import CompiledLaw, compiled_law, plan_inputs

__all__ = ["fold_solve", "kernel_of", "call"]

OK, DECLINED = 0, 1  #: :func:`call`'s status
INTS = "m nQ nv i_h i_J i_dr tip u_f u_z zs swap n_lim o_y0 o_y1 x_z0 x_z1 w0".split()  #: :func:`call`'s ints


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
    y0 = L.dot(txo)
    Y = L_tau.dot(B)
    for k in range(cols.size):
        for i in range(nQ):
            A[i, cols[k]] -= Y[i, k]
    for i in range(nQ):
        b[i] += y0[i]
    return lu_solve(A, b), y0, Y


@njit(cache=True)
def call(phi, x, u, P, M, L, L_tau, D_a, D_f, D_z, rotor, D_ctl, ints, frames, forces, cols, reach, k_null):
    """(status, ẋ, z, o) of the module docstring. ints: sizes and offsets (:data:`INTS`: zs the ż rows of
    M u, −1 none; x_z0:x_z1 the law's states in x and ẋ; tip the tip's p, ṗ in φ; u_f, u_z the forces and z
    in u; w0 the frame forces in z); frames: each frame's J offset in φ; forces: o's measured forces in u's
    order; cols: the folded columns of A (the rows' λ, then a carrying body's Q̈_b), with D_a, D_f, D_z per
    column; reach: the rows whose A column beyond the robot joins B."""
    m, nQ, nv, i_h, i_J, i_dr, tip, i_f, u_z = ints[0], ints[1], ints[2], ints[3], ints[4], ints[5], ints[6], \
        ints[7], ints[8]
    zs, swap, n_lim, o_y0, o_y1, x_z0, x_z1, w0 = ints[9], ints[10], ints[11], ints[12], ints[13], ints[14], \
        ints[15], ints[16]
    m2 = m * m
    y = P.dot(phi)
    A = y[:m2].copy().reshape((m, m))
    b = y[m2:m2 + m].copy()
    o = y[m2 + m:]
    u[:6] = phi[tip:tip + 6]  # p_tip [m], ṗ_tip [m/s]
    for k in range(forces.size):
        u[i_f + k] = o[forces[k]]
    u[u_z:u_z + x_z1 - x_z0] = x[x_z0:x_z1]  # the law's states z
    targets = M.dot(u)
    H = np.ascontiguousarray(phi[:nv * nv].reshape((nv, nv)).T) + D_ctl  # φ holds H column by column
    J = phi[i_J:i_J + 3 * nv].reshape((3, nv))
    tau_c = np.zeros(nv)
    for f in range(frames.size):
        tau_c += phi[frames[f]:frames[f] + 3 * nv].reshape((3, nv)).T.dot(b[w0 + 3 * f:w0 + 3 * f + 3])
    Jp = law.pinv(J)
    f_swap = targets[3:6] if swap else targets[0:0]
    tau = law.torque(H, rotor, phi[i_h:i_h + nv], tau_c, J, Jp, phi[i_dr:i_dr + 3], x[nQ:nQ + nv],
                     targets[:3], np.ascontiguousarray(f_swap), k_null)
    B = law.increments(H, rotor, J, Jp, D_a, D_f)
    for k in range(reach.size):
        for i in range(nv):
            B[i, reach[k]] += A[i, nQ + reach[k]]
    z, y0, Y = fold_solve(A, b, L, L_tau, tau, x, B, cols, nQ)
    xd = np.empty(x.size)
    if not np.isfinite(z.dot(z)):
        return DECLINED, xd, z, o
    folded = z[cols]
    if n_lim and np.abs(y0[nQ:] + Y[nQ:].dot(folded)).max() > 1.0:
        return DECLINED, xd, z, o
    xd[:nQ] = x[nQ:2 * nQ]
    xd[nQ:2 * nQ] = z[:nQ]
    xd[2 * nQ:] = y[o_y0:o_y1]
    if zs >= 0:
        xd[x_z0:x_z1] = targets[zs:] + D_z.dot(folded)
    return OK, xd, z, o


def kernel_of(plan, meta: list, reach: list[int] | None):
    """kernel(t, x, φ) -> (ẋ, z, o), or None for a call that goes the readable way (a clip, a singular solve,
    the law's M not read yet); None where the plan's mode is not one :func:`call` covers: a force-reading tip
    law by its matrix through compiled drives, no sliding friction, no slide launching from rest, and the rows'
    reach beyond the robot constant (``reach``, plan_fold's). ``meta``: the rows as
    the law's ``row_columns`` reads them."""
    ctl = compiled_law(plan)
    covered = (isinstance(ctl, CompiledLaw) and ctl.reason is None and plan.compiled_drives is not None
               and plan.friction_terms is None and plan.launch is None and (reach is not None or not plan.nr))
    if not covered:
        return None
    constants = None

    def kernel(t, x, phi):
        nonlocal constants
        if constants is None:
            if ctl.M is None:
                return None
            constants = _constants(plan, ctl, meta, reach or [], plan_inputs(plan, ctl))
        inputs, args = constants
        status, xd, z, o = call(phi, x, inputs(t, x, phi, None), *args)
        return None if status else (xd, z, o)

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
    ints = np.array([m, nQ, nv, plan.i_h, plan.i_J[tf], plan.i_dr[tf], inputs.tip, ctl.i_forces, inputs.i_z,
                     ctl.zs.start if ctl.zs is not None else -1, int(ctl.swap), len(drives.limited),
                     off + plan.o_y.start, off + plan.o_y.stop, plan.z_slice.start, plan.z_slice.stop, nQ + nr],
                    dtype=np.int64)  # in the order of INTS
    c = np.ascontiguousarray
    D_ctl = s._D_ctl if s._D_ctl is not None else np.zeros((nv, nv))
    args = (c(plan.P), c(ctl.M), c(drives.L), c(drives.L_tau), c(D_a), none if D_f is None else c(D_f),
            none if D_z is None else c(D_z), law._rotor_c, c(D_ctl, dtype=float), ints,
            np.array(plan.i_J, dtype=np.int64), np.array(inputs.forces, dtype=np.int64),
            np.array(cols, dtype=np.int64), np.array(reach, dtype=np.int64), float(law.config.k_null))
    return inputs, args
