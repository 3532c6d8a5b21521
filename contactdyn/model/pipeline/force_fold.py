"""The controller's terms of one call: τ, its states' rates ż, and the fold of a force-reading law.

A controller of the ABI reads, beyond the state, the phase's set-points as arrays in the phase's order (F_d [N],
Ḟ_d [N/s], direction n, the measured force of each set-point's key [N]: a contact's normal force as the chains give
it before the solve), and, when it reads forces (``uses_forces``), the contacts' generalized force on the joints
τ_c = f + h [N·m or N], each set-point's surface point [m] and velocity [m/s] and whether its contact touches
(``ControlInput.SET_POINT_ARRAYS``).

A force-reading law is affine in the row forces λ the solve returns: τ = τ₀ + B λ, ż = ż₀ + D λ. B and D are the
law's own differences at unit forces, computed here by calling the same compiled command once more per row that
reaches the law (:func:`_fold_columns`: +1 N on the measured normal force of a
contact's normal row, the row's force column on τ_c where it reaches a coordinate beyond the robot). The KKT solve
folds B into its force columns through the drives (:func:`solve_through_drives`:
gain_i B_i on each unclipped drive's target coordinate, the clips re-checked at the solved command, ≤ nv + 2
passes), and :func:`fold_rates` adds D λ to ż after it.

A reference carried by a body (``[phase.reference] body``) makes the command affine in the body's acceleration
Q̈_b too (its a_d gains axis · Q̈_b): τ += b Q̈_b, ż += d Q̈_b, with (b, d) the law's difference at a_d + axis
(:func:`_carried_column`), folded into M's column of the body the same way.
"""

from __future__ import annotations

import numpy as np

from ...laws.controllers.abi import FIELD, KEY_FORCE, KEY_P, KEY_TOUCH, KEY_V, KEY_W, LAYOUT_HEAD
from ...numerics.compile_cache import njit
from ...numerics.linalg import put
from .actuation import abi_buffer, abi_call, carry, drive_command, drives, reference, set_points
from .contacts import surface_point
from .drives import DI_W, DW_CLIPPED, DW_W, fold_on_targets
from .kkt import REGULAR, kkt_solve
from .pack import (
    ANY_MOTOR,
    CARRIER,
    CI_REALS,
    CI_TOUCHING,
    CI_W,
    EV_FN,
    EV_W,
    I_CONTACTS,
    I_DRIVES,
    I_FOLD,
    I_KEYS,
    N_CONTACTS,
    N_DRIVES,
    N_FORCES,
    N_ROWS,
    N_Z,
    NQ,
    NV,
    R_CARRIER,
    R_DRIVES,
    R_FOLD,
    R_KEYS,
    READS_FORCES,
    TIP_FRAME,
    W_DIAG,
    W_DRIVES,
    Z_AT,
    section,
)

__all__ = ["controller_terms", "key_fields", "carried_coordinate", "solve_through_drives", "fold_rates"]

F_SET, F_RATE, F_DIR, F_READ, F_TAU_C, F_SURFACE_P, F_SURFACE_V, F_TOUCH, F_AD, F_KEYS = (
    FIELD[k] for k in ("force_set", "force_rate", "force_dir", "force_read", "tau_contact", "surface_p", "surface_v",
                       "touch", "a_d", "keys"))


@njit(cache=True, inline="always")
def _at(lay, k):
    """Where field k starts in the buffer, and its size (0: absent). (Callers pass k as np.int64: a literal would
    compile this once per field.)"""
    return lay[LAYOUT_HEAD + 2 * k], lay[LAYOUT_HEAD + 1 + 2 * k] - lay[LAYOUT_HEAD + 2 * k]


@njit(cache=True, inline="always")
def _set_point_fields(t, x, ints, reals, work, h, f, events, buf, lay):
    """The set-points' fields of the buffer (those the layout has)."""
    ns, nr = ints[N_FORCES], ints[N_ROWS]
    F_d, dirs, rate = set_points(t, ints, reals)
    chain = ints[ints[I_FOLD] + ns + nr:ints[I_FOLD] + 2 * ns + nr]  # per set-point its chain (-1: a normal one)
    owner = ints[ints[I_FOLD] + 2 * ns + nr:ints[I_FOLD] + 3 * ns + nr]  # and its contact
    shift = section(reals, ints[R_FOLD], ns, 3)
    cs = section(ints, ints[I_CONTACTS], ints[N_CONTACTS], CI_W)
    at_set, n_set = _at(lay, np.int64(F_SET))
    at_rate, n_rate = _at(lay, np.int64(F_RATE))
    at_dir, n_dir = _at(lay, np.int64(F_DIR))
    at_read, n_read = _at(lay, np.int64(F_READ))
    at_p, n_p = _at(lay, np.int64(F_SURFACE_P))
    at_v, n_v = _at(lay, np.int64(F_SURFACE_V))
    at_touch, n_touch = _at(lay, np.int64(F_TOUCH))
    for s in range(ns):
        if n_set:
            buf[at_set + s] = F_d[s]
        if n_rate:
            buf[at_rate + s] = rate[s]
        for i in range(3 if n_dir else 0):
            buf[at_dir + 3 * s + i] = dirs[s, i]
        ci = owner[s]
        if n_read:  # the chains' force before the solve: the normal force, or a tangential chain's interface force
            buf[at_read + s] = events[EV_W * ci + EV_FN] if chain[s] < 0 else work[ints[W_DIAG] + 1 + chain[s]]
        row = cs[ci]
        cr = reals[row[CI_REALS]:]
        if n_p:  # the undeformed surface's point and velocity (a chain's: its anchor)
            p_env, v_env = surface_point(x, ints, row, cr)
            for i in range(3):
                buf[at_p + 3 * s + i] = p_env[i] + shift[s, i]
                buf[at_v + 3 * s + i] = v_env[i]
        if n_touch:
            buf[at_touch + s] = 1.0 if row[CI_TOUCHING] else 0.0
    at_tc, n_tc = _at(lay, np.int64(F_TAU_C))
    for c in range(n_tc):
        buf[at_tc + c] = f[c] + h[c]  # the contacts' generalized force on the joints (f holds −h)
    return n_read, n_tc


@njit(cache=True, inline="always")
def key_fields(x, ints, reals, work, events, buf, lay):
    """A declared Python stage's "keys" field (empty for a compiled law): per key of the readable ControlInput's
    dictionaries (I_KEYS) its measured force before the solve [N] (the contact's normal force, or the tangential
    chain's interface force), whether its contact touches, its surface point [m] and velocity [m/s]
    (a chain's: its anchor, the surface's point shifted by u·offset)."""
    at, n = _at(lay, np.int64(F_KEYS))
    nk = n // KEY_W
    keys, shift = section(ints, ints[I_KEYS], nk, 2), section(reals, ints[R_KEYS], nk, 3)
    cs = section(ints, ints[I_CONTACTS], ints[N_CONTACTS], CI_W)
    for k in range(nk):
        ci, chain = keys[k, 0], keys[k, 1]
        row = cs[ci]
        o = at + KEY_W * k
        buf[o + KEY_FORCE] = events[EV_W * ci + EV_FN] if chain < 0 else work[ints[W_DIAG] + 1 + chain]
        buf[o + KEY_TOUCH] = 1.0 if row[CI_TOUCHING] else 0.0
        p_env, v_env = surface_point(x, ints, row, reals[row[CI_REALS]:])
        for i in range(3):
            buf[o + KEY_P + i] = p_env[i] + shift[k, i]
            buf[o + KEY_V + i] = v_env[i]


@njit(cache=True, inline="always")
def _bump_key_force(ints, buf, lay, ci, by):
    """+by [N] on the "keys" field's force of contact ci's normal (a Python stage's ``forces[name]``)."""
    at, n = _at(lay, np.int64(F_KEYS))
    keys = section(ints, ints[I_KEYS], n // KEY_W, 2)
    for k in range(n // KEY_W):
        if keys[k, 0] == ci and keys[k, 1] < 0:
            buf[at + KEY_W * k + KEY_FORCE] += by


@njit(cache=True, inline="always")
def _fold_columns(ints, reals, buf, lay, tau, zdot, C, B, D):
    """B and D: the law's differences per unit force of each row that reaches it."""
    nv, ns, nr = ints[NV], ints[N_FORCES], ints[N_ROWS]
    sp = ints[ints[I_FOLD]:ints[I_FOLD] + ns]
    row_contact = ints[ints[I_FOLD] + ns:ints[I_FOLD] + ns + nr]
    at_read, n_read = _at(lay, np.int64(F_READ))
    at_tc, _ = _at(lay, np.int64(F_TAU_C))
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
        if ci >= 0:
            _bump_key_force(ints, buf, lay, ci, 1.0)
        for c in range(nv if fed_back else 0):
            buf[at_tc + c] = tc0[c] + C[j, c]
        if abi_call(ints, reals, buf, lay, tau_j, zdot_j) != 1:
            return False
        for i in range(nv):
            B[i, j] = tau_j[i] - tau[i]
        for i in range(zdot.size):
            D[i, j] = zdot_j[i] - zdot[i]
        put(buf, at_read, read0)  # (put: no array assignment, see numerics.linalg.put)
        put(buf, at_tc, tc0)
        if ci >= 0:
            _bump_key_force(ints, buf, lay, ci, -1.0)
    return True


@njit(cache=True, inline="always")
def _carried_column(ints, reals, buf, lay, tau, zdot, bq, dq):
    """(b, d): the law's differences at one unit [m/s²] more of a_d along the carrier's axis."""
    at, n = _at(lay, np.int64(F_AD))
    axis = reals[ints[R_CARRIER]:ints[R_CARRIER] + 3]
    a0 = buf[at:at + n].copy()
    for k in range(n):
        buf[at + k] = a0[k] + axis[k]
    tau_b, zdot_b = np.empty(tau.size), np.empty(zdot.size)
    ok = abi_call(ints, reals, buf, lay, tau_b, zdot_b) == 1
    for i in range(tau.size):
        bq[i] = tau_b[i] - tau[i]
    for i in range(zdot.size):
        dq[i] = zdot_b[i] - zdot[i]
    put(buf, at, a0)
    return ok


@njit(cache=True)
def controller_terms(t, x, ints, reals, work, H, h, g, FJ, Fa, Fp, Fv, FR, f, C, events):
    """(τ [N·m or N], ż, B (nv, rows), D (states, rows), b (nv), d (states)) of the phase's controller of the ABI at
    (t, x) (the kinds compiled in are .actuation's stages): b and d per unit acceleration of a body carrying the
    reference (zero without one); τ NaN where the law failed (:meth:`Pipeline.failed_call` then raises the law's
    error)."""
    nv, nr, nz = ints[NV], ints[N_ROWS], ints[N_Z]
    zdot = np.zeros(nz)
    fold = ints[READS_FORCES] != 0 and nr > 0
    B, D = np.zeros((nv, nr if fold else 0)), np.zeros((nz, nr if fold else 0))
    bq, dq = np.zeros(nv), np.zeros(nz)
    fi = ints[TIP_FRAME]
    x_d, v_d, a_d = reference(t, ints, reals)
    carry(x, ints, reals, x_d, v_d)
    buf, lay = abi_buffer(t, x, ints, reals, H, h, g, FJ[fi], Fa[fi], Fp[fi], Fv[fi], FR[fi], x_d, v_d, a_d)
    _set_point_fields(t, x, ints, reals, work, h, f, events, buf, lay)
    key_fields(x, ints, reals, work, events, buf, lay)
    tau = np.zeros(nv)
    if abi_call(ints, reals, buf, lay, tau, zdot) != 1 or \
            (fold and not _fold_columns(ints, reals, buf, lay, tau, zdot, C, B, D)) or \
            (ints[CARRIER] >= 0 and a_d.size and not _carried_column(ints, reals, buf, lay, tau, zdot, bq, dq)):
        tau[:] = np.nan
    return tau, zdot, B, D, bq, dq


@njit(cache=True)
def carried_coordinate(ints, bq):
    """The coordinate of the body carrying the reference where the command depends on its acceleration (b ≠ 0),
    else -1 (no carried term)."""
    for i in range(bq.size if ints[CARRIER] >= 0 else 0):
        if bq[i] != 0.0:
            return ints[CARRIER]
    return -1


@njit(cache=True)
def solve_through_drives(x, ints, reals, work, M, f, G, C, gamma, tau, B, bq):
    """(ok, the drives' applied forces [N·m or N], Q̈, λ, the solve's outcome): the command through the drives into f,
    then the KKT solve (:func:`.kkt.kkt_solve`; its outcome :func:`.kkt.solve_linear`'s). With a fold (B's columns, or a
    carried column b ≠ 0): each pass applies τ₀ (the clips decided at the last full
    command), folds B and b through the unclipped drives (:func:`.drives.fold_on_targets`), solves, and re-applies the
    full command τ₀ + B λ + b Q̈_b, until the clips agree (≤ nv + 2 passes); τ becomes the full command, the drives'
    outputs in ``work`` are the full command's. ok False where a drive kind's law failed."""
    nv, nQ, n = ints[NV], ints[NQ], ints[N_DRIVES]
    iq = carried_coordinate(ints, bq)
    folding = B.shape[1] > 0 or iq >= 0
    cmd = drive_command(x, ints, reals, tau)
    if not folding:  # the command known before the solve: one pass (the drives, then the solve)
        ok, applied = drives(x, ints, reals, work, cmd, cmd, f)
        qdd, lam, outcome = kkt_solve(ints, reals, M, f, G, C, gamma, B, bq, np.int64(-1))  # (-1: compiled again)
        return ok, applied, qdd, lam, outcome
    sat, full, fk = cmd, cmd, f
    rows = section(ints, ints[I_DRIVES], n, DI_W)
    out = work[ints[W_DRIVES]:]
    clipped = np.zeros(n)
    ok, applied = True, cmd
    qdd, lam, outcome = np.zeros(nQ), np.zeros(gamma.size), REGULAR
    for _ in range(nv + 2):
        fk = f.copy()
        ok, applied = drives(x, ints, reals, work, cmd, sat, fk)
        if not ok:
            return False, applied, qdd, lam, outcome
        fold, fold_q = np.zeros((nQ, B.shape[1])), np.zeros(nQ)
        fold_on_targets(rows, reals[ints[R_DRIVES]:], out, B, bq, fold, fold_q)
        qdd, lam, outcome = kkt_solve(ints, reals, M, fk, G, C, gamma, fold, fold_q, iq)
        full = cmd.copy()
        for i in range(nv):
            s = 0.0
            for j in range(B.shape[1]):
                s += B[i, j] * lam[j]
            full[i] += s
            if iq >= 0:
                full[i] += bq[i] * qdd[iq]
        if not ints[ANY_MOTOR]:  # ideal sources: nothing clips, the full command acts as it is (one pass)
            applied = full
            break
        for i in range(n):
            clipped[i] = out[DW_W * i + DW_CLIPPED]
        ok, applied = drives(x, ints, reals, work, full, full, np.zeros(nQ))
        if not ok:
            return False, applied, qdd, lam, outcome
        same = True
        for i in range(n):
            same = same and clipped[i] == out[DW_W * i + DW_CLIPPED]
        if same:
            break
        sat = full
    put(f, 0, fk)
    put(tau, 0, full[:nv])
    return ok, applied, qdd, lam, outcome


@njit(cache=True)
def fold_rates(ints, lam, zdot, D, ydot, dq, qdd, iq):
    """ż + D λ (+ d Q̈_b, a carried reference's: iq ≥ 0) into the controller's slots of ẏ."""
    at = ints[Z_AT]
    for i in range(zdot.size):
        s = zdot[i]
        for j in range(D.shape[1]):
            s += D[i, j] * lam[j]
        ydot[at + i] = s + dq[i] * qdd[iq] if iq >= 0 else s
