"""A plan's DOP853 step attempt in one compiled call: the 12 stages through the plan's own compiled call.

With the scipy core (:mod:`contactdyn.numerics.dop853`) each stage crosses from the core into Python and from Python
into the plan's compiled call (~2 µs of a ~8 µs call). Where a plan's right-hand side is one compiled call
(:func:`.plan_operational.call_at`, :func:`.plan_kernel.call_at`), :func:`attempt` takes
a whole step there, as ``solve_ivp``'s DOP853 takes it (``rk_step``: the stages, y_new, the FSAL call at
t + h, and ``_estimate_error_norm``), and returns the stages the dense output needs in the scipy core's
layout; :func:`contactdyn.numerics.dop853.solve` keeps ``solve_ivp``'s step control around it. A stage the call
declines (a clip, a singular solve, a slide inside the stick band) ends the attempt: the driver takes that
step by the plan's Python right-hand side instead (:func:`stepper`).
"""

from __future__ import annotations

import numpy as np
from scipy.integrate._ivp import dop853_coefficients as _coef

from ..numerics.compile_cache import njit
from . import plan_kernel, plan_operational
from .plan_kernel import DECLINED, KERNEL, OK
from .plan_operational import OPERATIONAL

__all__ = ["attempt", "stepper", "derivatives"]
_A, _B, _C = np.ascontiguousarray(_coef.A[:12, :12]), _coef.B.copy(), _coef.C[:12].copy()
_E = np.ascontiguousarray(np.vstack((_coef.E5, _coef.E3)))  #: the error estimators' weights on K's 13 rows


def _u_of(kind: int, u: np.ndarray) -> np.ndarray | None:
    """The compiled functions' u for a plan's call of this kind: the tip law's inputs' buffer of a plan_kernel call,
    None for the operational call. Each compiled function below branches on ``u is None`` itself (no helper
    between: numba compiles each function with all it calls, so a level less is one compile of both kernels less)
    and numba drops the branch the None-ness rules out: a step of one kind compiles that kind's call only."""
    if kind == OPERATIONAL:
        return None
    assert kind == KERNEL
    return u


@njit(cache=True)
def attempt(work, phi, u, fb, ib, t, y, f, h, rtol, atol, A, B, C, E, out, y_new, block):
    """(status, error norm) of one DOP853 step of h [s] from (t, y) with f = f(t, y); y_new and, in the scipy
    core's layout (:mod:`contactdyn.numerics.dop853`: f_new, stages 11, 12, –, y_new, stages 6–10), ``block`` written;
    ``out`` holds the FSAL call's [ẋ, z, o, τ]. Status DECLINED where a stage's call declines."""
    n = y.size
    K = np.empty((13, n))
    K[0] = f
    ys = np.empty(n)
    for s in range(1, 12):
        for i in range(n):
            acc = 0.0
            for j in range(s):
                acc += K[j, i] * A[s, j]
            ys[i] = y[i] + acc * h
        if u is None:
            status = plan_operational.call_at(t + C[s] * h, ys, work, phi, fb, ib, out)
        else:
            status = plan_kernel.call_at(t + C[s] * h, ys, work, phi, u, fb, ib, out)
        if status:
            return DECLINED, 0.0
        K[s] = out[:n]
    for i in range(n):
        acc = 0.0
        for j in range(12):
            acc += K[j, i] * B[j]
        y_new[i] = y[i] + h * acc
    if u is None:
        status = plan_operational.call_at(t + h, y_new, work, phi, fb, ib, out)
    else:
        status = plan_kernel.call_at(t + h, y_new, work, phi, u, fb, ib, out)
    if status:
        return DECLINED, 0.0
    K[12] = out[:n]
    e5 = e3 = 0.0
    for i in range(n):
        scale = atol + max(abs(y[i]), abs(y_new[i])) * rtol
        a5 = a3 = 0.0
        for j in range(13):
            a5 += K[j, i] * E[0, j]
            a3 += K[j, i] * E[1, j]
        e5 += (a5 / scale) ** 2
        e3 += (a3 / scale) ** 2
    block[0], block[1], block[2], block[4] = K[12], K[10], K[11], y_new
    block[5:10] = K[5:10]
    if e5 == 0.0 and e3 == 0.0:
        return OK, 0.0
    return OK, abs(h) * e5 / np.sqrt((e5 + 0.01 * e3) * n)


@njit(cache=True)
def _derivatives(work, phi, u, fb, ib, ts, Y, out, Yd):
    """Yd[k] = ẋ at (ts[k], Y[k]) by the plan's compiled call (u as :func:`_u_of`'s), in order; the number of
    states done (fewer than len(ts) where the call declines the next)."""
    n = Y.shape[1]
    for k in range(ts.size):
        if u is None:
            status = plan_operational.call_at(ts[k], Y[k], work, phi, fb, ib, out)
        else:
            status = plan_kernel.call_at(ts[k], Y[k], work, phi, u, fb, ib, out)
        if status:
            return k
        Yd[k] = out[:n]
    return ts.size


def derivatives(kind: int, inputs, layout: tuple[int, int, int, int], fun):
    """f(ts, Y) -> Ẋ (N, n): the right-hand side at many states in one compiled call (the dense output's extra
    stages, DenseSolution.__call__), bitwise the plan's call; states the compiled call
    cannot take go to ``fun``, the plan's right-hand side."""
    size, n, _, _ = layout

    def batch(ts: np.ndarray, Y: np.ndarray) -> np.ndarray:
        ts, Y = np.ascontiguousarray(ts, dtype=float), np.ascontiguousarray(Y, dtype=float)
        Yd = np.empty((len(ts), n))
        args = inputs()
        if args is None:
            done = 0
        else:
            work, phi, u, fb, ib = args
            done = _derivatives(work, phi, _u_of(kind, u), fb, ib, ts, Y, np.empty(size), Yd)
        for k in range(done, len(ts)):
            Yd[k] = fun(float(ts[k]), Y[k])
        return Yd

    return batch


def stepper(plan, kind: int, inputs, layout: tuple[int, int, int, int]):
    """step(t, y, f, h, rtol, atol) -> (error norm, y_new, block), or None where the plan's compiled call cannot
    take it (``inputs()`` -> (work, φ, u, fb, ib) or None: a tip law not read yet, a time part in Python; or a
    stage declined): then the caller takes the step by the plan's right-hand side; ``step.usable()``: whether
    inputs are there (a segment whose steps cannot be compiled stays on scipy's core). Each step's FSAL call
    enters the plan's ring (the events read its values)."""
    size, n, m, no = layout
    ring = plan.ring

    def usable() -> bool:  # can the compiled call take a step now (dop853.solve asks once per segment)
        return inputs() is not None

    def step(t, y, f, h, rtol, atol):
        args = inputs()
        if args is None:
            return None
        out, y_new, block = np.empty(size), np.empty(n), np.empty((10, n))  # (block's row 3 is not read)
        work, phi, u, fb, ib = args
        status, err = attempt(work, phi, _u_of(kind, u), fb, ib, t, y, f, h, rtol, atol, _A, _B, _C, _E, out, y_new,
                              block)
        if status:
            return None
        ring.append((t + h, y_new, out[n:n + m], out[n + m:n + m + no]))
        return err, y_new, block

    step.usable = usable
    return step
