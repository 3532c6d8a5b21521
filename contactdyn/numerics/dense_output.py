"""DOP853's dense output evaluated by compiled loops: a step's 7th-order interpolant at step fractions.

:mod:`contactdyn.numerics.dop853` keeps a step's interpolant as the coefficients F (7, n) of scipy's
``Dop853DenseOutput`` and evaluates it by Horner's rule, y(s) = y_old + F₀ s (1 − s) … (s: the step fraction).
In NumPy that is 14 array operations on an n-vector, ~8 µs for the 4–30 states of a run's right-hand side; event
location evaluates it ~7 times per located event and the output once per sample. Here the same operations, in
the same order, on one element at a time (each a separate rounding, no fused multiply-add: numba does not
contract them), so the numbers are NumPy's bit for bit (``tests/test_dense_output.py``), at ~0.8 µs a call.

A compiled mode builds a located event's step interpolant in one call (:func:`contactdyn.hybrid.steps.interpolant`)
by :func:`stage_states` and :func:`coefficients`: the numbers :func:`contactdyn.numerics.dop853.build_interpolants`
forms in NumPy (``einsum`` sums over the stages in their order for two or more states; the same elementwise
operations), bit for bit (``tests/test_dense_output.py``). ``build_interpolants`` stays NumPy: a first run, on the
interpreted call, compiles neither.
"""

from __future__ import annotations

import numpy as np

from .compile_cache import njit

__all__ = ["horner_at", "horner_rows", "stage_states", "coefficients"]


@njit(cache=True, inline="always")
def _horner(F, i, n_rows, s, r):
    """y − y_old of element i of interpolant F (rows, n) at step fraction s (r = 1 − s), NumPy's order."""
    y = 0.0
    for k in range(n_rows):
        y += F[n_rows - 1 - k, i]
        y *= s if k % 2 == 0 else r
    return y


@njit(cache=True)
def horner_at(F, s, y_old):
    """y_old + the interpolant F (rows, n) at step fraction s [-]: the state (n,)."""
    n_rows, n = F.shape
    r = 1.0 - s
    out = np.empty(n)
    for i in range(n):
        out[i] = _horner(F, i, n_rows, s, r) + y_old[i]
    return out


@njit(cache=True)
def horner_rows(C, which, s, Y0):
    """The states (len(s), n): row k is Y0[which[k]] + interpolant C[which[k]] (steps, rows, n) at fraction s[k]."""
    n_rows, n = C.shape[1], C.shape[2]
    out = np.empty((s.size, n))
    for k in range(s.size):
        j, sk = which[k], s[k]
        r = 1.0 - sk
        for i in range(n):
            out[k, i] = _horner(C[j], i, n_rows, sk, r) + Y0[j, i]
    return out


@njit(cache=True)
def stage_states(K, s, A, Y0, h):
    """The states (m, n) of stage s of m steps: Y0[k] + h[k] Σ_{j<s} A[s, j] K[k, j] (the sum in stage order; h [s]
    the steps, K (m, 16, n) their stages, A the tableau)."""
    m, n = Y0.shape
    out = np.empty((m, n))
    for k in range(m):
        for i in range(n):
            acc = 0.0
            for j in range(s):
                acc += K[k, j, i] * A[s, j]
            out[k, i] = Y0[k, i] + h[k] * acc
    return out


@njit(cache=True)
def coefficients(K, Y0, y_new, h, D, last):
    """The interpolants' coefficients (m, 3 + len(D), n) of m steps from their stages K (m, 16, n), states at the
    start Y0 and end y_new (m, n), steps h [s] (m,); ``last``: K's row of f(t_new) (scipy's Dop853DenseOutput)."""
    m, S, n = K.shape
    d_rows = D.shape[0]
    F = np.empty((m, 3 + d_rows, n))
    for k in range(m):
        hk = h[k]
        for i in range(n):
            dy = y_new[k, i] - Y0[k, i]
            F[k, 0, i] = dy
            F[k, 1, i] = hk * K[k, 0, i] - dy
            F[k, 2, i] = 2.0 * dy - hk * (K[k, last, i] + K[k, 0, i])
        for d in range(d_rows):
            for i in range(n):
                acc = 0.0
                for j in range(S):
                    acc += D[d, j] * K[k, j, i]
                F[k, 3 + d, i] = hk * acc
    return F
