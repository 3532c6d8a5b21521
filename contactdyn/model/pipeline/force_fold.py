"""The controller's terms of one call: τ, its states' rates ż, and the fold of a force-reading law.

A controller of the ABI reads, beyond the state, the phase's set-points as arrays in the phase's order (F_d [N],
Ḟ_d [N/s], direction n, the measured force of each set-point's key [N]: a contact's normal force as the chains give
it before the solve), and, when it reads forces (``uses_forces``), the contacts' generalized force on the joints
τ_c = f + h [N·m or N], each set-point's surface point [m] and velocity [m/s] and whether its contact touches
(``ControlInput.SET_POINT_ARRAYS``, the readable model's ``set_force_inputs``).

A force-reading law is affine in the row forces λ the solve returns: τ = τ₀ + B λ, ż = ż₀ + D λ. B and D are the
law's own differences at unit forces, computed here by calling the same compiled command once more per row that
reaches the law (:func:`contactdyn.model.constraints.force_columns`: +1 N on the measured normal force of a
contact's normal row, the row's force column on τ_c where it reaches a coordinate beyond the robot). The KKT solve
folds B into its force columns (:func:`.kkt.kkt_solve`, ideal torque drives: the command's gain is 1), and
:func:`fold_rates` adds D λ to ż after it.
"""

from __future__ import annotations

import numpy as np

from ...laws.controllers.abi import FIELD, LAYOUT_HEAD
from ...numerics.compile_cache import njit
from .actuation import abi_buffer, abi_call, command, reference, set_points
from .pack import (
    CI_BODY,
    CI_REALS,
    CI_TOUCHING,
    CI_W,
    CR_AXIS,
    CR_POINT,
    CTL_ABI,
    CTL_KIND,
    EV_FN,
    EV_W,
    I_CONTACTS,
    I_FOLD,
    N_CONTACTS,
    N_FORCES,
    N_ROWS,
    N_Z,
    NQ,
    NV,
    READS_FORCES,
    TIP_FRAME,
    Z_AT,
    section,
)

__all__ = ["controller_terms", "fold_rates", "folded_command"]

F_SET, F_RATE, F_DIR, F_READ, F_TAU_C, F_SURFACE_P, F_SURFACE_V, F_TOUCH = (
    FIELD[k] for k in ("force_set", "force_rate", "force_dir", "force_read", "tau_contact", "surface_p", "surface_v",
                       "touch"))


@njit(cache=True)
def _at(lay, k):
    """Where field k starts in the buffer, and its size (0: absent)."""
    return lay[LAYOUT_HEAD + 2 * k], lay[LAYOUT_HEAD + 1 + 2 * k] - lay[LAYOUT_HEAD + 2 * k]


@njit(cache=True)
def _set_point_fields(t, x, ints, reals, h, f, events, buf, lay):
    """The set-points' fields of the buffer (those the layout has)."""
    nQ, ns = ints[NQ], ints[N_FORCES]
    F_d, dirs, rate = set_points(t, ints, reals)
    sp = ints[ints[I_FOLD]:ints[I_FOLD] + ns]  # per set-point its contact (normal), -1 a tangential chain's
    cs = section(ints, ints[I_CONTACTS], ints[N_CONTACTS], CI_W)
    at_set, n_set = _at(lay, F_SET)
    at_rate, n_rate = _at(lay, F_RATE)
    at_dir, n_dir = _at(lay, F_DIR)
    at_read, n_read = _at(lay, F_READ)
    at_p, n_p = _at(lay, F_SURFACE_P)
    at_v, n_v = _at(lay, F_SURFACE_V)
    at_touch, n_touch = _at(lay, F_TOUCH)
    for s in range(ns):
        if n_set:
            buf[at_set + s] = F_d[s]
        if n_rate:
            buf[at_rate + s] = rate[s]
        for i in range(3 if n_dir else 0):
            buf[at_dir + 3 * s + i] = dirs[s, i]
        ci = sp[s]
        if ci < 0:
            continue
        if n_read:
            buf[at_read + s] = events[EV_W * ci + EV_FN]  # the chains' normal force, before the solve
        row = cs[ci]
        cr = reals[row[CI_REALS]:]
        body = row[CI_BODY]
        for i in range(3 if n_p else 0):  # the undeformed surface's point and velocity (Contact.surface)
            buf[at_p + 3 * s + i] = cr[CR_POINT + i] + cr[CR_AXIS + i] * x[body] if body >= 0 else cr[CR_POINT + i]
            buf[at_v + 3 * s + i] = cr[CR_AXIS + i] * x[nQ + body] if body >= 0 else 0.0
        if n_touch:
            buf[at_touch + s] = 1.0 if row[CI_TOUCHING] else 0.0
    at_tc, n_tc = _at(lay, F_TAU_C)
    for c in range(n_tc):
        buf[at_tc + c] = f[c] + h[c]  # the contacts' generalized force on the joints (f holds −h)
    return n_read, n_tc


@njit(cache=True)
def _fold_columns(ints, reals, buf, lay, tau, zdot, C, B, D):
    """B and D: the law's differences per unit force of each row that reaches it (constraints.force_columns)."""
    nv, ns, nr = ints[NV], ints[N_FORCES], ints[N_ROWS]
    sp = ints[ints[I_FOLD]:ints[I_FOLD] + ns]
    row_contact = ints[ints[I_FOLD] + ns:ints[I_FOLD] + ns + nr]
    at_read, n_read = _at(lay, F_READ)
    at_tc, _ = _at(lay, F_TAU_C)
    read0, tc0 = buf[at_read:at_read + n_read].copy(), buf[at_tc:at_tc + nv].copy()
    tau_j, zdot_j = np.empty(nv), np.empty(zdot.size)
    for j in range(nr):
        fed_back = False
        for c in range(nv, C.shape[1]):
            fed_back = fed_back or C[j, c] != 0.0
        ci = row_contact[j]
        if ci < 0 and not fed_back:
            continue
        for s in range(n_read if ci >= 0 else 0):
            if sp[s] == ci:
                buf[at_read + s] = read0[s] + 1.0
        for c in range(nv if fed_back else 0):
            buf[at_tc + c] = tc0[c] + C[j, c]
        if abi_call(ints, reals, buf, lay, tau_j, zdot_j) != 1:
            return False
        for i in range(nv):
            B[i, j] = tau_j[i] - tau[i]
        for i in range(zdot.size):
            D[i, j] = zdot_j[i] - zdot[i]
        buf[at_read:at_read + n_read] = read0
        buf[at_tc:at_tc + nv] = tc0
    return True


@njit(cache=True)
def controller_terms(t, x, ints, reals, H, h, g, FJ, Fa, Fp, Fv, FR, f, C, events):
    """(τ [N·m or N], ż, B (nv, rows), D (states, rows)) of the phase's controller at (t, x); τ NaN where the law
    failed (the readable model then answers and its error surfaces there)."""
    nv, nr, nz = ints[NV], ints[N_ROWS], ints[N_Z]
    zdot = np.zeros(nz)
    fold = ints[READS_FORCES] != 0 and nr > 0
    B, D = np.zeros((nv, nr if fold else 0)), np.zeros((nz, nr if fold else 0))
    if ints[CTL_KIND] != CTL_ABI:
        return command(t, x, ints, reals, H, h, g, FJ, Fa, Fp, Fv, FR), zdot, B, D
    fi = ints[TIP_FRAME]
    x_d, v_d, a_d = reference(t, ints, reals)
    buf, lay = abi_buffer(t, x, ints, reals, H, h, g, FJ[fi], Fa[fi], Fp[fi], Fv[fi], FR[fi], x_d, v_d, a_d)
    _set_point_fields(t, x, ints, reals, h, f, events, buf, lay)
    tau = np.zeros(nv)
    if abi_call(ints, reals, buf, lay, tau, zdot) != 1 or \
            (fold and not _fold_columns(ints, reals, buf, lay, tau, zdot, C, B, D)):
        tau[:] = np.nan
    return tau, zdot, B, D


@njit(cache=True)
def fold_rates(ints, lam, zdot, D, ydot):
    """ż + D λ into the controller's slots of ẏ."""
    at = ints[Z_AT]
    for i in range(zdot.size):
        s = zdot[i]
        for j in range(D.shape[1]):
            s += D[i, j] * lam[j]
        ydot[at + i] = s


@njit(cache=True)
def folded_command(tau, applied, B, lam):
    """τ₀ + B λ [N·m or N]: a force-reading law's command at the solved forces, into τ and the joints' applied
    forces (ideal torque drives: the fold's only drives) in place; nothing without a fold."""
    for i in range(B.shape[0] if B.shape[1] else 0):
        s = 0.0
        for j in range(B.shape[1]):
            s += B[i, j] * lam[j]
        tau[i] += s
        applied[i] += s
