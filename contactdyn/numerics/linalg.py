"""Small dense solves without numpy's Python wrappers.

``numpy.linalg.solve`` checks its arguments in Python before calling its gufunc; on the 2–12-row
systems of a right-hand side call that check costs more than the solve (~3 µs of ~1 µs). The gufunc
itself is used here where numpy has it (private but stable since numpy 1.8), the public function
otherwise. Arguments must be float arrays of matching shapes; a singular matrix gives inf/nan, where
the fallback raises LinAlgError; callers test.

:func:`lu_solve`, :func:`cholesky`, :func:`forward_solve`, :func:`pinv`, the products :func:`mv`, :func:`mtv`,
:func:`mm` and :func:`mtm` are compiled (numba) for the compiled laws
(the one pipeline, laws.controllers.computed_torque,
:mod:`contactdyn.laws.controllers.operational_law`), written in loops: numba's LAPACK bindings cost
~0.15 s to load per process, and a BLAS call ~0.1 µs, more than a loop over these 3–12-row arrays.
:func:`put` copies a vector into a vector element by element (an array's slice assignment compiles numba's
shape check and its message, ~1.5–2 s once per process). :func:`dot3` is a 3-vector's dot product formed alike in
Python and compiled, on every machine (an interpreted run's numbers are the compiled run's).
:func:`cross3` is numpy's ``np.cross`` of two 3-vectors (the same operations, bit for bit) without its ~8 µs of
axis handling.
"""

from __future__ import annotations

import math
from fractions import Fraction

import numpy as np
from numba import types
from numba.extending import intrinsic, overload

from .compile_cache import njit

__all__ = ["solve_vector", "lu_solve", "residual_ok", "pinv", "mv", "mtv", "mm", "mtm", "cholesky",
           "forward_solve", "contiguous", "dot3", "fma", "cross3", "put", "null_basis"]

try:
    from numpy.linalg import _umath_linalg

    solve_vector = _umath_linalg.solve1  #: A z = b for a vector b
except (ImportError, AttributeError):  # pragma: no cover
    solve_vector = np.linalg.solve


def contiguous(a) -> np.ndarray:
    """``a`` as the compiled functions take it: a C-contiguous, writeable float64 array (no copy when it is one;
    numba compiles a function again for a read-only array, e.g. a scene's gains broadcast to the axes)."""
    a = np.ascontiguousarray(a, dtype=float)
    return a if a.flags.writeable else a.copy()


def dot3(a: np.ndarray, b: np.ndarray) -> float:
    """a·b of two 3-vectors: a₀b₀, then one fused multiply-add per term, in Python as compiled (not numpy's ``a @ b``:
    which BLAS kernel forms it, with or without FMA, depends on the machine)."""
    a0, a1, a2 = a.tolist()
    b0, b1, b2 = b.tolist()
    return fma(a2, b2, fma(a1, b1, a0 * b0))


_MATH_FMA = getattr(math, "fma", None)
_SPLIT = 134217729.0  #: 2²⁷ + 1
_TINY, _HUGE = 1e-280, 1e300  #: where the split and the product error are exact (no underflow, no overflow)


def fma(a: float, b: float, c: float) -> float:
    """a b + c rounded once (IEEE 754's fused multiply-add, as ``llvm.fma`` compiled; Python 3.13's ``math.fma``
    where there is one). a b is split exactly into p + e (Dekker's product) and ``math.fsum`` rounds p + e + c
    correctly; at magnitudes where the split is not exact, in rationals."""
    if _MATH_FMA is not None:
        return _MATH_FMA(a, b, c)
    p = a * b
    if a == 0.0 or b == 0.0:
        return p + c  # (exact: a zero product)
    if _TINY < abs(a) < _HUGE and _TINY < abs(b) < _HUGE and _TINY < abs(p) < _HUGE and abs(c) < _HUGE:
        r = math.fsum((p, _product_error(a, b, p), c))
    elif math.isfinite(a) and math.isfinite(b) and math.isfinite(c):
        exact = Fraction(a) * Fraction(b) + Fraction(c)
        try:
            r = float(exact)
        except OverflowError:
            return p + c  # (± inf)
        if r == 0.0 and exact != 0:
            return math.copysign(0.0, exact)  # (an underflow keeps the exact result's sign)
    else:  # (inf and nan as the fused operation gives them: a finite product's overflow does not count)
        return c if math.isfinite(a) and math.isfinite(b) else p + c
    return r if r != 0.0 else p + c  # (an exact zero's sign as IEEE gives it)


def _product_error(a: float, b: float, p: float) -> float:
    """e = a b − p exactly, p = a b rounded (Veltkamp's split of each factor into 26 + 27 bits)."""
    t = _SPLIT * a
    a_hi = t - (t - a)
    t = _SPLIT * b
    b_hi = t - (t - b)
    a_lo, b_lo = a - a_hi, b - b_hi
    return ((a_hi * b_hi - p) + a_hi * b_lo + a_lo * b_hi) + a_lo * b_lo



def cross3(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """a × b of two 3-vectors, as ``np.cross`` forms it (a₁b₂ − a₂b₁, …); compiled, the same operations."""
    a0, a1, a2 = a.tolist()
    b0, b1, b2 = b.tolist()
    return np.array((a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0))


@overload(cross3, inline="always")
def _cross3_compiled(a, b):
    def impl(a, b):
        return np.array([a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]])
    return impl


@overload(dot3)
def _dot3_compiled(a, b):
    """a₀b₀, then a fused multiply-add per term (:func:`dot3`'s, bit for bit)."""
    def impl(a, b):
        return _fma(a[2], b[2], _fma(a[1], b[1], a[0] * b[0]))
    return impl


@intrinsic
def _fma(typingctx, a, b, c):
    """a b + c rounded once (llvm.fma)."""
    def codegen(context, builder, signature, args):
        return builder.fma(*args)
    return types.float64(types.float64, types.float64, types.float64), codegen


@njit(cache=True)
def lu_solve(A, b, tiny=0.0):
    """z of A z = b by Gaussian elimination with partial pivoting (LAPACK's dgetf2 order); A, b unchanged;
    a pivot of magnitude at most ``tiny`` (0: a zero pivot; singular A) gives nan."""
    n = b.size
    LU = A.copy()
    z = b.copy()
    for k in range(n):
        p = k
        for i in range(k + 1, n):
            if abs(LU[i, k]) > abs(LU[p, k]):
                p = i
        if abs(LU[p, k]) <= tiny:
            return np.full(n, np.nan)
        if p != k:
            for j in range(n):
                LU[k, j], LU[p, j] = LU[p, j], LU[k, j]
            z[k], z[p] = z[p], z[k]
        for i in range(k + 1, n):
            if LU[i, k] == 0.0:  # (a KKT matrix is mostly zeros: nothing to eliminate)
                continue
            f = LU[i, k] / LU[k, k]
            for j in range(k + 1, n):
                LU[i, j] -= f * LU[k, j]
            z[i] -= f * z[k]
    for k in range(n - 1, -1, -1):
        s = z[k]
        for j in range(k + 1, n):
            s -= LU[k, j] * z[j]
        z[k] = s / LU[k, k]
    return z


@njit(cache=True)
def residual_ok(A, z, b):
    """z is finite and ‖A z − b‖ ≤ 1e-9 (1 + ‖b‖) (the KKT solve's test, contactdyn.model.pipeline.kkt)."""
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
def cholesky(A):
    """The lower-triangular L of A = L Lᵀ (A symmetric positive definite; nan where a pivot is not positive)."""
    n = A.shape[0]
    L = np.zeros((n, n))
    for j in range(n):
        s = A[j, j]
        for k in range(j):
            s -= L[j, k] * L[j, k]
        if not s > 0.0:
            return np.full((n, n), np.nan)
        L[j, j] = math.sqrt(s)
        for i in range(j + 1, n):
            s = A[i, j]
            for k in range(j):
                s -= L[i, k] * L[j, k]
            L[i, j] = s / L[j, j]
    return L


@njit(cache=True)
def forward_solve(L, B):
    """Y of L Y = B (L lower triangular, B a matrix) by forward substitution."""
    n, k = B.shape
    Y = np.empty((n, k))
    for c in range(k):
        for i in range(n):
            s = B[i, c]
            for j in range(i):
                s -= L[i, j] * Y[j, c]
            Y[i, c] = s / L[i, i]
    return Y


@njit(cache=True)
def pinv(J):
    """J⁺ (c, r) of J (r, c) by a one-sided Jacobi SVD of its shorter side (:func:`_jacobi_pinv`; (Jᵀ)⁺ = (J⁺)ᵀ:
    a 3×2 Jacobian rotates one pair of columns per sweep rather than three)."""
    if J.shape[1] < J.shape[0]:
        return _transposed(_jacobi_pinv(_transposed(J)))
    return _jacobi_pinv(J)


@njit(cache=True, no_cpython_wrapper=True)  # (only compiled code calls it: no CPython wrapper to build)
def _transposed(M):
    """Mᵀ, a new C-contiguous array, element by element. (numba's ``ascontiguousarray`` of ``M.T``, like its ``eye``,
    ``sum`` and ``max`` that :func:`_jacobi_pinv` no longer calls, compiles an implementation of its own: seconds of
    a cold first run. The numbers are the same.)"""
    r, c = M.shape
    T = np.empty((c, r))
    for i in range(r):
        for j in range(c):
            T[j, i] = M[i, j]
    return T


@njit(cache=True, no_cpython_wrapper=True)
def _jacobi_pinv(J):
    """J⁺ (c, r) of J (r, c), r ≤ c, by a one-sided Jacobi SVD of Jᵀ (its columns made orthogonal by
    plane rotations: Jᵀ V = [σ_k u_k], J⁺ = Σ_k u_k v_kᵀ / σ_k), singular values ≤ 1e-10 of the largest
    dropped (numpy.linalg.pinv's rcond); accurate to the precision of J, also near singular poses."""
    r, c = J.shape
    A = _transposed(J)  # (c, r): its columns are rotated
    V = np.zeros((r, r))
    square = 0.0  # ‖J‖² [J's unit²] summed row by row: numba's ``(J * J).sum()`` for a C-ordered or strided J (by
    # columns for a Fortran-ordered one: there the threshold below may differ from it in the last bit)
    for p in range(r):
        V[p, p] = 1.0
        for i in range(c):
            square += J[p, i] * J[p, i]
    floor = 1e-32 * square  # a column this small (‖a‖ ≤ 1e-16 ‖J‖) is a dropped singular value: left
    for _ in range(60):  # sweeps; converges quadratically (a few sweeps for r = 3)
        rotated = False
        for p in range(r - 1):
            for q in range(p + 1, r):
                alpha = beta = gamma = 0.0
                for i in range(c):
                    alpha += A[i, p] * A[i, p]
                    beta += A[i, q] * A[i, q]
                    gamma += A[i, p] * A[i, q]
                if min(alpha, beta) <= floor or abs(gamma) <= 1e-15 * math.sqrt(alpha * beta):
                    continue
                rotated = True
                zeta = (beta - alpha) / (2.0 * gamma)
                t = math.copysign(1.0, zeta) / (abs(zeta) + math.sqrt(1.0 + zeta * zeta))
                cs = 1.0 / math.sqrt(1.0 + t * t)
                sn = cs * t
                for i in range(c):
                    ap, aq = A[i, p], A[i, q]
                    A[i, p], A[i, q] = cs * ap - sn * aq, sn * ap + cs * aq
                for i in range(r):
                    vp, vq = V[i, p], V[i, q]
                    V[i, p], V[i, q] = cs * vp - sn * vq, sn * vp + cs * vq
        if not rotated:
            break
    sigma2 = np.zeros(r)
    for k in range(r):
        for i in range(c):
            sigma2[k] += A[i, k] * A[i, k]
    top = math.sqrt(_largest(sigma2)) if r else 0.0
    out = np.zeros((c, r))
    for k in range(r):
        if top > 0.0 and math.sqrt(sigma2[k]) > 1e-10 * top:
            for i in range(c):
                for j in range(r):
                    out[i, j] += A[i, k] * V[j, k] / sigma2[k]
    return out


@njit(cache=True)
def null_basis(A, tol):
    """An orthonormal basis of A's null space (m × n): (k, n), k = n − rank, its rows x with A x = 0. Gaussian
    elimination with full pivoting (a pivot at most ``tol`` × A's largest |entry| is zero), then per free column
    back substitution with that column's x = 1 and the other free ones 0, then Gram–Schmidt (one direction: only
    scaled to unit length). (Loops, not LAPACK's SVD: numba compiles its binding for ~10 s.)"""
    m, n = A.shape
    R, cols = A.copy(), np.empty(n, dtype=np.int64)
    for j in range(n):
        cols[j] = j
    big = 0.0
    for i in range(m):
        for j in range(n):
            big = max(big, abs(R[i, j]))
    rank = 0
    for k in range(min(m, n)):
        p, pi, pj = 0.0, k, k
        for i in range(k, m):
            for j in range(k, n):
                if abs(R[i, j]) > p:
                    p, pi, pj = abs(R[i, j]), i, j
        if p <= tol * big:
            break
        for j in range(n):  # rows k and pi
            R[k, j], R[pi, j] = R[pi, j], R[k, j]
        for i in range(m):  # columns k and pj
            R[i, k], R[i, pj] = R[i, pj], R[i, k]
        cols[k], cols[pj] = cols[pj], cols[k]
        for i in range(k + 1, m):
            f = R[i, k] / R[k, k]
            for j in range(k, n):
                R[i, j] -= f * R[k, j]
        rank += 1
    Y = np.zeros((n - rank, n))
    for free in range(n - rank):
        y = Y[free]
        y[rank + free] = 1.0
        for i in range(rank - 1, -1, -1):
            acc = R[i, rank + free]
            for j in range(i + 1, rank):
                acc += R[i, j] * y[j]
            y[i] = -acc / R[i, i]
        for prior in range(free):  # (Gram–Schmidt against the rows before)
            dot = 0.0
            for j in range(n):
                dot += Y[prior, j] * y[j]
            for j in range(n):
                y[j] -= dot * Y[prior, j]
        norm = 0.0
        for j in range(n):
            norm += y[j] * y[j]
        norm = math.sqrt(norm)
        for j in range(n):
            y[j] = y[j] / norm
    X = np.empty((n - rank, n))
    for free in range(n - rank):
        for j in range(n):
            X[free, cols[j]] = Y[free, j]
    return X


@njit(cache=True, no_cpython_wrapper=True)
def _largest(a):
    """max(a) of a non-empty 1-D array; NaN if one is NaN (numba's ``a.max()``, without its array machinery)."""
    top = a[0]
    for k in range(1, a.size):
        if math.isnan(top):
            break
        if math.isnan(a[k]) or a[k] > top:
            top = a[k]
    return top


@njit(["void(float64[::1], int64, float64[::1])", "void(float64[::1], int64, float64[:])"], cache=True)
def put(dst, at, src):
    """``dst[at:at + src.size] = src`` (1-D arrays), element by element: without numba's shape check, whose message
    compiles once per process (~1.5–2 s of a cold first run); the caller sizes ``dst``. (Its signatures given: a
    literal ``at`` would compile it again.)"""
    for i in range(src.size):
        dst[at + i] = src[i]


@njit(cache=True)
def mv(A, x):
    """A x."""
    out = np.zeros(A.shape[0])
    for i in range(A.shape[0]):
        acc = 0.0
        for j in range(A.shape[1]):
            acc += A[i, j] * x[j]
        out[i] = acc
    return out


@njit(cache=True)
def mtv(A, x):
    """Aᵀ x (:func:`mv`'s sums on the columns; not mv(A.T), which compiles mv again, for 'F')."""
    out = np.zeros(A.shape[1])
    for i in range(A.shape[1]):
        acc = 0.0
        for j in range(A.shape[0]):
            acc += A[j, i] * x[j]
        out[i] = acc
    return out


@njit(cache=True)
def mm(A, B):
    """A B."""
    out = np.zeros((A.shape[0], B.shape[1]))
    for i in range(A.shape[0]):
        for j in range(B.shape[1]):
            acc = 0.0
            for k in range(A.shape[1]):
                acc += A[i, k] * B[k, j]
            out[i, j] = acc
    return out


@njit(cache=True)
def mtm(A, B):
    """Aᵀ B (:func:`mm` on the transposed view: the same sums)."""
    return mm(A.T, B)
