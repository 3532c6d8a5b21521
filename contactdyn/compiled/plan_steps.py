"""A plan's DOP853 step attempt in one compiled call: the 12 stages through the plan's own compiled call, or through
the one pipeline's call (:func:`pipeline_attempt`: the same tableau, stage states and error norm, the call the one
thing that differs).

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

from ..model.pipeline.pack import A_CALL, NX
from ..model.pipeline.pipeline import rates_at
from ..numerics.compile_cache import njit
from ..numerics.native_call import call_at
from . import plan_kernel, plan_operational
from .plan_kernel import DECLINED, KERNEL, OK
from .plan_operational import OPERATIONAL

__all__ = ["attempt", "pipeline_attempt", "stepper", "derivatives", "pipeline_stepper", "pipeline_derivatives"]
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


@njit(cache=True, inline="always")
def _stage_state(K, y, h, A, s, ys):
    """ys = y + h Σ_{j<s} A[s, j] K[j]: stage s's state (DOP853's tableau, in rk_step's order)."""
    for i in range(y.size):
        acc = 0.0
        for j in range(s):
            acc += K[j, i] * A[s, j]
        ys[i] = y[i] + acc * h


@njit(cache=True, inline="always")
def _step_end(K, y, h, B, y_new):
    """y_new = y + h Σ_j B[j] K[j]."""
    for i in range(y.size):
        acc = 0.0
        for j in range(12):
            acc += K[j, i] * B[j]
        y_new[i] = y[i] + h * acc


@njit(cache=True, inline="always")
def _error_norm(K, y, y_new, h, rtol, atol, E, block):
    """The step's error norm (solve_ivp's DOP853 ``_estimate_error_norm``); the dense output's stages into
    ``block`` (the scipy core's layout)."""
    n = y.size
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
    for r in range(5, 10):  # (row by row: a 2-D slice assignment compiles numba's shape check and its message)
        block[r] = K[r]
    if e5 == 0.0 and e3 == 0.0:
        return 0.0
    return abs(h) * e5 / np.sqrt((e5 + 0.01 * e3) * n)


@njit(cache=True)
def attempt(work, phi, u, fb, ib, t, y, f, h, rtol, atol, A, B, C, E, out, y_new, block):
    """(status, error norm) of one DOP853 step of h [s] from (t, y) with f = f(t, y); y_new and, in the scipy
    core's layout (:mod:`contactdyn.numerics.dop853`: f_new, stages 11, 12, –, y_new, stages 6–10), ``block`` written;
    ``out`` holds the FSAL call's [ẋ, z, o, τ]. Status DECLINED where a stage's call declines."""
    n = y.size
    K = np.empty((13, n))
    K[0] = f
    ys = np.empty(n)
    for s in range(1, 13):
        if s < 12:
            _stage_state(K, y, h, A, s, ys)
        else:
            _step_end(K, y, h, B, y_new)
            ys = y_new
        if u is None:
            status = plan_operational.call_at(t + C[s] * h if s < 12 else t + h, ys, work, phi, fb, ib, out)
        else:
            status = plan_kernel.call_at(t + C[s] * h if s < 12 else t + h, ys, work, phi, u, fb, ib, out)
        if status:
            return DECLINED, 0.0
        K[s] = out[:n]
    return OK, _error_norm(K, y, y_new, h, rtol, atol, E, block)


@njit(cache=True)
def pipeline_attempt(ints, reals, work, events, t, y, f, h, rtol, atol, A, B, C, E, y_new, block, Ys, Es):
    """:func:`attempt` over the one pipeline's call (:func:`contactdyn.model.pipeline.pipeline.call`, the one thing
    that differs): (status, error norm); ``events`` hold the FSAL call's event values, Ys[s] and Es[s] stage s's
    state and event values (s = 1 … 12, the FSAL call's last). DECLINED where a call's status is not 1 (a singular
    KKT matrix, a law that gave no force: the step by the Python right-hand side)."""
    n = y.size
    K = np.empty((13, n))
    K[0] = f
    ys = np.empty(n)
    for s in range(1, 13):
        if s < 12:
            _stage_state(K, y, h, A, s, ys)
        else:
            _step_end(K, y, h, B, y_new)
            ys = y_new
        at = t + C[s] * h if s < 12 else t + h
        K[s] = call_at(ints[A_CALL], "pipeline.call", (at, ys, ints, reals, work, events))  # (not linked in)
        if events[events.size - 1] != 1.0:
            return DECLINED, 0.0
        Ys[s] = ys
        Es[s] = events
    return OK, _error_norm(K, y, y_new, h, rtol, atol, E, block)


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


def pipeline_stepper(packed, ring, on_stage=None):
    """step(t, y, f, h, rtol, atol) -> (error norm, y_new, block), or None where a call of the step declines (then
    the caller takes the step by the pipeline's Python right-hand side), over a mode packed for the one pipeline
    (:class:`~contactdyn.model.pipeline.pack.Packed`); as :func:`stepper`, each step's FSAL call's event values
    enter ``ring`` as (t, y_new, events). ``on_stage(t, y)``: called after an attempt per stage (t [s], its state)
    with that stage's event values the ring's latest (a stuck contact's slip watch sees every stage, as it sees
    every call of the Python right-hand side)."""
    ints, reals, work, events = packed.ints, packed.reals, packed.work, packed.events
    Ys, Es = np.empty((13, packed.ints[NX])), np.empty((13, events.size))

    def step(t, y, f, h, rtol, atol):
        y_new, block = np.empty(y.size), np.empty((10, y.size))  # (block's row 3 is not read)
        status, err = pipeline_attempt(ints, reals, work, events, t, y, f, h, rtol, atol, _A, _B, _C, _E, y_new,
                                       block, Ys, Es)
        if status:
            return None
        if on_stage is not None:
            for s in range(1, 12):
                ys = Ys[s]
                ring.append((t + _C[s] * h, ys, Es[s].copy()))
                on_stage(t + _C[s] * h, ys)
        ring.append((t + h, y_new, events.copy()))
        if on_stage is not None:
            on_stage(t + h, y_new)
        return err, y_new, block

    step.usable = lambda: True
    return step


def pipeline_derivatives(packed, fun):
    """f(ts, Y) -> Ẋ (N, n): the pipeline's right-hand side at many states in one compiled call (the dense output's
    extra stages), bitwise its call; from a state whose call declines on, ``fun`` (its Python right-hand side)."""
    def batch(ts: np.ndarray, Y: np.ndarray) -> np.ndarray:
        ts, Y = np.ascontiguousarray(ts, dtype=float), np.ascontiguousarray(Y, dtype=float)
        Yd, done = rates_at(ts, Y, packed.ints, packed.reals, packed.work, packed.events)
        for k in range(done, len(ts)):
            Yd[k] = fun(float(ts[k]), Y[k])
        return Yd

    return batch
