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
"""

from __future__ import annotations

import math

import numpy as np

from ...numerics.compile_cache import njit
from ...numerics.linalg import lu_solve, put, residual_ok
from .pack import NQ, NV, R_MREST

__all__ = ["kkt_solve", "solve_linear", "least_squares", "NOT_FINITE", "REGULAR", "LEAST_SQUARES"]

NOT_FINITE, REGULAR, LEAST_SQUARES = 0, 1, 2  #: a solve's outcome: no solve (non-finite), LU, least squares
#: [-] an LU pivot at most this × the largest |entry| of A is zero: A is singular (redundant rows: stuck joints and a
#: stuck contact holding the same motion), solved by least squares. Rounding leaves such a pivot ~1e-15 of it, and
#: LU's answer then passes the residual test with a null-space part that flips between calls (the holds' share of
#: the force), which the step control cannot follow; a regular KKT matrix's smallest pivot is ~1e-2 of it.
SINGULAR_PIVOT = 1e-12


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
