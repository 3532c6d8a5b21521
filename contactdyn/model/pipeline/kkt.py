"""The pipeline's KKT stage over arrays: the assembly of [[M, −Cᵀ], [G, 0]] [Q̈; λ] = [f; −γ] and its solve.

M is the robot's H [kg·m²] with the rotors reflected through rigid gears on its diagonal (``.drives.inertias``)
and the diagonal inertias of the bodies, chain masses and motor coordinates [kg, kg·m²] (the packed ``M_rest``);
G the rows, C their force columns (a slide's tilt), γ [m/s²] their velocity-product and Baumgarte terms
(:mod:`contactdyn.model.constraints`' ``kkt_solve``); a force-reading controller's B (τ = τ₀ + B λ,
:mod:`.force_fold`) folded through its drives into the force columns, a carried reference's column into M's. The solve
is ``numerics.linalg.lu_solve`` (partial pivoting) with the readable model's residual test; a singular matrix
whose rows are redundant but consistent (two sticks holding one body) is solved by the same minimum-norm least
squares as the readable model's (``constraints.solve_linear``); one still singular returns status 0 and the
caller takes the readable model.
"""

from __future__ import annotations

import math

import numpy as np

from ...numerics.compile_cache import njit
from ...numerics.linalg import lu_solve, put
from .pack import NQ, NV, R_MREST

__all__ = ["kkt_solve", "residual_ok", "least_squares"]


@njit(cache=True)
def residual_ok(A, z, b):
    """z is finite and ‖A z − b‖ ≤ 1e-9 (1 + ‖b‖) (constraints.solve_linear's test)."""
    r2 = b2 = 0.0
    for i in range(b.size):
        if not math.isfinite(z[i]):
            return False
        s = 0.0
        for j in range(b.size):
            s += A[i, j] * z[j]
        r2 += (s - b[i]) ** 2
        b2 += b[i] * b[i]
    return math.sqrt(r2) <= 1e-9 * (1.0 + math.sqrt(b2))


@njit(cache=True)
def kkt_solve(ints, reals, H, f, G, C, gamma, fold, fold_q, iq):
    """(Q̈ [m/s², rad/s²], λ [N], regular): the KKT system's solve, or with no rows (no carried column, no
    articulated body, no riding mass) H q̈ = f and the other coordinates' f / m (H: M's rigid-body block, NF × NF:
    the robot's joints, then the articulated bodies' coordinates; nQ × nQ with a chain's mass riding a turning
    surface, :func:`.contacts.add_riding`). ``fold`` (nQ, rows, or no columns): a force-reading
    controller's B through its drives (τ = τ₀ + B λ, :mod:`.force_fold`), subtracted from the force columns;
    ``fold_q`` (nQ): its part per unit acceleration of coordinate ``iq`` (a reference carried by that body; -1 none),
    subtracted from M's column iq (``constraints.kkt_solve``'s M − fold_q)."""
    nv, nQ, nr = ints[NV], ints[NQ], gamma.size
    m_rest = reals[ints[R_MREST]:ints[R_MREST] + nQ - nv]
    if nr == 0 and iq < 0 and H.shape[0] == nv:
        qdd = np.empty(nQ)
        b = f[:nv].copy()
        z = lu_solve(H, b)
        put(qdd, 0, z)
        for i in range(nQ - nv):
            qdd[nv + i] = f[nv + i] / m_rest[i]
        return qdd, np.empty(0), residual_ok(H, z, b)
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
    z = lu_solve(A, b)
    solved = residual_ok(A, z, b)
    if solved or not finite(A, b):
        return z[:nQ], z[nQ:], solved
    z = least_squares(A, b)  # redundant rows (two sticks holding one body): the minimum-norm forces
    return z[:nQ], z[nQ:], residual_ok(A, z, b)


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
    dropped: ``constraints.solve_linear``'s fallback): a consistent system with redundant rows solved exactly."""
    return np.linalg.lstsq(A, b, 1e-12)[0]
