"""The pipeline's KKT stage over arrays: the assembly of [[M, −Cᵀ], [G, 0]] [Q̈; λ] = [f; −γ] and its solve.

M is the robot's H [kg·m²] with the rotors reflected through rigid gears on its diagonal (``.drives.inertias``)
and the diagonal inertias of the bodies, chain masses and motor coordinates [kg, kg·m²] (the packed ``M_rest``);
G the rows, C their force columns (a slide's tilt), γ [m/s²] their velocity-product and Baumgarte terms
(the rows: :mod:`contactdyn.model.constraints`); a force-reading controller's B (τ = τ₀ + B λ,
:mod:`.force_fold`) folded through its drives into the force columns, a carried reference's column into M's. The solve
is :func:`solve_linear`, ``constraints.solve_linear`` over arrays: ``numerics.linalg.lu_solve`` (partial pivoting)
with its residual test, else (a singular matrix: redundant rows, consistent as two sticks holding
one body or not as two tables 1 mm apart) the same minimum-norm least squares (LAPACK's gelsd, rcond 1e-12), its
outcome LEAST_SQUARES (an Evaluation's ``regular`` False). Only a KKT system with a non-finite
entry (a law's nan or inf) is left unsolved (NOT_FINITE): the call declines (status 0).

Redundant holds (stuck joints and a stuck contact holding the same motion) are statically indeterminate: their forces
can change by a split that moves nothing (n with Cᵀ n = 0). The least norm picks one split, blind to the holds'
limits; :func:`coulomb_split` then picks, where the least norm leaves a hold outside its limit, the split nearest to
it with every hold inside (Coulomb's: a hold breaks only when no split keeps it): along one such direction, the
nearest; along several, that rule along each in turn.
"""

from __future__ import annotations

import math

import numpy as np

from ...numerics.compile_cache import njit
from ...numerics.linalg import lu_solve, null_basis, put, residual_ok
from .pack import (
    CI_BONDED,
    CI_FRICTION,
    CI_NORMAL_ROW,
    CI_NT,
    CI_REALS,
    CI_STICK_ROW,
    CI_W,
    CR_MU_S,
    EV_FN,
    EV_W,
    FRICTION_STICK,
    I_CONTACTS,
    I_LIMITS,
    LI_SIDE,
    LI_W,
    N_CONTACTS,
    N_HELD,
    N_LIMITS,
    N_SLIDING,
    NQ,
    NV,
    R_JOINTS,
    R_MREST,
    section,
)

__all__ = ["kkt_solve", "solve_linear", "least_squares", "coulomb_split", "hold_interval", "NOT_FINITE", "REGULAR",
           "LEAST_SQUARES"]

NOT_FINITE, REGULAR, LEAST_SQUARES = 0, 1, 2  #: a solve's outcome: no solve (non-finite), LU, least squares
#: [-] an LU pivot at most this × the largest |entry| of A is zero: A is singular (redundant rows: stuck joints and a
#: stuck contact holding the same motion), solved by least squares. Rounding leaves such a pivot ~1e-15 of it, and
#: LU's answer then passes the residual test with a null-space part that flips between calls (the holds' share of
#: the force), which the step control cannot follow; a regular KKT matrix's smallest pivot is ~1e-2 of it.
SINGULAR_PIVOT = 1e-12
#: [-] an elimination pivot of Cᵀ (the rows' force columns) at most this × its largest |entry| is zero: a split that
#: moves nothing
NULL_RANK = 1e-10
#: [-] a split is chosen this far inside each limit (× μ_s F_n, × τ_s, × the largest |λ| for a pressing force): at its
#: binding limit the event value keeps its sign, not a rounding's
SPLIT_MARGIN = 1e-9
_NEGLIGIBLE = 1e-12  #: [-] a unit split's share of a row below this is none (its bound would be rounding's)
SPLIT_PASSES = 8  #: rounds over the split directions at most, where the splits span more than one (coulomb_split)


@njit(cache=True)
def kkt_solve(ints, reals, H, f, G, C, gamma, fold, fold_q, iq):
    """(Q̈ [m/s², rad/s²], λ [N], :func:`solve_linear`'s outcome): the KKT system's solve, or with no rows (no carried
    column, no articulated body, no riding mass) H q̈ = f and the other coordinates' f / m (H: M's rigid-body block, NF
    × NF: the robot's joints, then the articulated bodies' coordinates; nQ × nQ with a chain's mass riding a turning
    surface, :func:`.contacts.add_riding`). ``fold`` (nQ, rows, or no columns): a force-reading controller's B through
    its drives (τ = τ₀ + B λ, :mod:`.force_fold`), subtracted from the force columns; ``fold_q`` (nQ): its part per unit
    acceleration of coordinate ``iq`` (a reference carried by that body; -1 none), subtracted from M's column iq
    (M − fold_q)."""
    nv, nQ, nr = ints[NV], ints[NQ], gamma.size
    m_rest = reals[ints[R_MREST]:ints[R_MREST] + nQ - nv]
    if nr == 0 and iq < 0 and H.shape[0] == nv:
        qdd = np.empty(nQ)
        b = f[:nv].copy()
        z, outcome = solve_linear(H, b)
        put(qdd, 0, z)
        for i in range(nQ - nv):
            qdd[nv + i] = f[nv + i] / m_rest[i]
        return qdd, np.empty(0), outcome
    m = nQ + nr
    A = np.zeros((m, m))
    for r in range(H.shape[0]):  # (element by element: a 2-D slice assignment compiles numba's shape check)
        for c in range(H.shape[0]):
            A[r, c] = H[r, c]
    for i in range(nQ - nv):  # (0 on an articulated body's coordinates: its H_b is H's block)
        A[nv + i, nv + i] += m_rest[i]
    for c in range(nQ if iq >= 0 else 0):
        A[c, iq] -= fold_q[c]
    for r in range(nr):
        for c in range(nQ):
            A[c, nQ + r] = -C[r, c]
            A[nQ + r, c] = G[r, c]
        for c in range(fold.shape[0] if fold.shape[1] else 0):
            A[c, nQ + r] -= fold[c, r]
    b = np.empty(m)
    put(b, 0, f)
    for r in range(nr):
        b[nQ + r] = -gamma[r]
    z, outcome = solve_linear(A, b)
    return z[:nQ], z[nQ:], outcome


@njit(cache=True)
def solve_linear(A, b):
    """(z, outcome) of A z = b as ``constraints.solve_linear``: LU's z where it passes the residual test (REGULAR),
    else the minimum-norm least squares (LEAST_SQUARES: A singular, the system consistent or not); LU's z where an
    entry of A or b is not finite (NOT_FINITE: no least squares, the call declines)."""
    z = lu_solve(A, b, SINGULAR_PIVOT * largest(A))
    if residual_ok(A, z, b):
        return z, REGULAR
    if not finite(A, b):
        return z, NOT_FINITE
    return least_squares(A, b), LEAST_SQUARES


@njit(cache=True)
def largest(A):
    """The largest |entry| of A."""
    m = 0.0
    for i in range(A.shape[0]):
        for j in range(A.shape[1]):
            m = max(m, abs(A[i, j]))
    return m


@njit(cache=True)
def finite(A, b):
    """Every entry of A and b finite (a law's nan or inf: no least squares, the call declines)."""
    for i in range(b.size):
        if not math.isfinite(b[i]):
            return False
        for j in range(b.size):
            if not math.isfinite(A[i, j]):
                return False
    return True


@njit(cache=True)
def least_squares(A, b):
    """The minimum-norm least-squares z of A z = b (LAPACK's gelsd, singular values below 1e-12 of the largest
    dropped: ``constraints.solve_linear``'s fallback): redundant rows that agree solved exactly, rows that disagree
    (the same row, other γ) in the least-squares sense."""
    return np.linalg.lstsq(A, b, 1e-12)[0]


@njit(cache=True)
def coulomb_split(ints, reals, events, C, lam, first_limit, first_joint):
    """λ [N, N·m] of a singular solve (the least norm's) with its redundant holds split by their limits: where λ leaves
    a hold outside its limit (a stuck contact's force outside μ_s F_n, a held joint's torque past τ_s, an unbonded
    normal row's or a pressing limit's force pulling), a split that moves nothing (n: Cᵀ n = 0, so the generalized
    force and the motion are unchanged) that puts every hold inside its limit (by SPLIT_MARGIN). With one such
    direction, λ + s n with the s nearest 0 that does; where no s does (the hold breaks), the s between the two
    limits that met as the last split went (lo > hi: each out by as much), so that the event values pass zero where
    the split ends, both its holds' together. With k > 1 (an orthonormal basis n_1 … n_k), that rule along each n_i in
    turn, from the forces the last one left, for at most SPLIT_PASSES rounds or until every hold is inside. λ itself
    where it is inside already. Also whether λ was split."""
    if _inside(ints, reals, events, lam, first_limit, first_joint):
        return lam, False  # (no split sought)
    basis = null_basis(C.T.copy(), NULL_RANK)  # (Cᵀ n = 0)
    out, split = lam, False
    for _ in range(SPLIT_PASSES):
        for n in basis:
            s, found = _split_along(ints, reals, events, out, n, first_limit, first_joint)
            if found:
                out, split = out + s * n, True
        if basis.shape[0] < 2 or _inside(ints, reals, events, out, first_limit, first_joint):
            break  # (one direction: one pass is the rule)
    return out, split


@njit(cache=True)
def _inside(ints, reals, events, lam, first_limit, first_joint):
    """Does λ keep every hold inside its limit?"""
    return _hold_limits(ints, reals, events, lam, np.zeros(lam.size), first_limit, first_joint,
                        np.array([-np.inf, np.inf]))


@njit(cache=True)
def _split_along(ints, reals, events, lam, n, first_limit, first_joint):
    """(s, found): :func:`coulomb_split`'s rule along the one direction n from λ: the s nearest 0 that puts every hold
    inside its limit, else the s between the two limits that met; found False where neither is (no bound)."""
    bounds = np.array([-np.inf, np.inf])  # [lo, hi] of s
    _hold_limits(ints, reals, events, lam, n, first_limit, first_joint, bounds)
    lo, hi = bounds[0], bounds[1]
    if lo <= hi:
        return min(max(0.0, lo), hi), True
    if math.isfinite(lo) and math.isfinite(hi):  # past the last split: the two limits that met there, equally out
        return 0.5 * (lo + hi), True
    return 0.0, False


@njit(cache=True)
def _hold_limits(ints, reals, events, lam, n, first_limit, first_joint, bounds):
    """Whether λ keeps every hold inside its limit; ``bounds`` ([lo, hi]) narrowed to the s with λ + s n inside
    every one by SPLIT_MARGIN (the holds: :func:`coulomb_split`'s)."""
    inside, largest = True, 0.0
    for v in lam:
        largest = max(largest, abs(v))
    pull = SPLIT_MARGIN * largest  # [N or N·m] a pressing force's least, at a split
    cs = section(ints, ints[I_CONTACTS], ints[N_CONTACTS], CI_W)
    for ci in range(cs.shape[0]):
        row = cs[ci]
        rn = row[CI_NORMAL_ROW]
        c, d = (lam[rn], _share(n[rn])) if rn >= 0 else (events[EV_W * ci + EV_FN], 0.0)  # F_n(s) = c + s d [N]
        if rn >= 0 and not row[CI_BONDED]:
            inside = inside and c >= 0.0
            _at_least(c - pull, d, bounds)
        if row[CI_FRICTION] == FRICTION_STICK:
            mu, st = reals[row[CI_REALS] + CR_MU_S], row[CI_STICK_ROW]
            a0, b0 = lam[st], _share(n[st])
            a1, b1 = (lam[st + 1], _share(n[st + 1])) if row[CI_NT] > 1 else (0.0, 0.0)
            inside = inside and mu * c >= math.sqrt(a0 * a0 + a1 * a1)
            hold_interval(mu * (1.0 - SPLIT_MARGIN), c, d, a0, a1, b0, b1, bounds)
    lims = section(ints, ints[I_LIMITS], ints[N_LIMITS], LI_W)
    for k in range(lims.shape[0]):
        side = lims[k, LI_SIDE]
        inside = inside and side * lam[first_limit + k] >= 0.0
        _at_least(side * lam[first_limit + k] - pull, side * _share(n[first_limit + k]), bounds)
    static = ints[R_JOINTS] + ints[NV] + 2 * ints[N_SLIDING]  # (pack._joint_friction: the held joints' τ_s)
    for k in range(ints[N_HELD]):
        tau_s, held, b = reals[static + k], lam[first_joint + k], _share(n[first_joint + k])
        inside = inside and abs(held) <= tau_s
        _at_least(tau_s * (1.0 - SPLIT_MARGIN) - held, -b, bounds)
        _at_least(tau_s * (1.0 - SPLIT_MARGIN) + held, b, bounds)
    return inside


@njit(cache=True)
def _share(v):
    """A unit split's share of a row, 0 below _NEGLIGIBLE."""
    return v if abs(v) > _NEGLIGIBLE else 0.0


@njit(cache=True)
def _at_least(a, b, bounds):
    """``bounds`` ([lo, hi]) narrowed to the s with a + s b ≥ 0."""
    if b > 0.0:
        bounds[0] = max(bounds[0], -a / b)
    elif b < 0.0:
        bounds[1] = min(bounds[1], -a / b)
    elif a < 0.0:
        bounds[0], bounds[1] = np.inf, -np.inf


@njit(cache=True)
def hold_interval(mu, c, d, a0, a1, b0, b1, bounds):
    """``bounds`` ([lo, hi]) narrowed to the s with ‖a + s b‖ ≤ μ (c + s d): a stick's force inside its cone along a
    line of splits (a = (a0, a1), b = (b0, b1): the tangential force [N] and its share, a1 = b1 = 0 for one
    tangent; c, d: the normal force's [N]). The cone is convex, so the s form one interval: where
    q(s) = μ²(c + s d)² − ‖a + s b‖² ≥ 0 on the cone's upper half (c + s d ≥ 0)."""
    _at_least(c, d, bounds)
    bb = b0 * b0 + b1 * b1
    qa = mu * mu * d * d - bb
    qb = 2.0 * (mu * mu * c * d - (a0 * b0 + a1 * b1))
    qc = mu * mu * c * c - (a0 * a0 + a1 * a1)
    if abs(qa) <= 1e-14 * (mu * mu * d * d + bb):  # (q linear in s)
        _at_least(qc, qb, bounds)
        return
    disc = qb * qb - 4.0 * qa * qc
    if disc < 0.0:
        if qa < 0.0:  # (q < 0 everywhere: no s)
            bounds[0], bounds[1] = np.inf, -np.inf
        return
    root = -0.5 * (qb + math.copysign(math.sqrt(disc), qb))
    r1, r2 = root / qa, (qc / root if root != 0.0 else root / qa)
    r1, r2 = min(r1, r2), max(r1, r2)
    if qa < 0.0:  # q ≥ 0 between the roots
        bounds[0], bounds[1] = max(bounds[0], r1), min(bounds[1], r2)
    elif d > 0.0:  # q ≥ 0 outside them; the upper half is the ray the normal force grows along
        bounds[0] = max(bounds[0], r2)
    else:
        bounds[1] = min(bounds[1], r1)
