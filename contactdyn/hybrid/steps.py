"""A mode's DOP853 step attempt in one compiled call: the 12 stages through the one pipeline's call
(:func:`contactdyn.model.pipeline.pipeline.call`), as ``solve_ivp``'s DOP853 takes a step (``rk_step``: the stages,
y_new, the FSAL call at t + h, and ``_estimate_error_norm``), returning the stages the dense output needs in the
scipy core's layout; :func:`contactdyn.numerics.dop853.solve` keeps ``solve_ivp``'s step control around it.

With the scipy core each stage crosses from the core into Python and from Python into the compiled call (~2 µs of a
~6 µs call); here a whole step is one crossing. A stage whose call declines (a KKT system with a non-finite entry, a
law that gave no force or raised) ends the attempt: the driver takes that step by the mode's Python right-hand side
instead (a law's error is raised there, at its own call's time); a singular KKT matrix does not (the call solves it
by least squares and counts it, ``Pipeline.least_squares``).
"""

from __future__ import annotations

import numpy as np
from numba import types

from ..laws.abi import drop_python_stage_error
from ..model.pipeline.pack import A_CALL, NX
from ..model.pipeline.pipeline import rates_at
from ..numerics import dop853_tableau as _coef
from ..numerics.compile_cache import njit
from ..numerics.dense_output import coefficients, stage_states
from ..numerics.linalg import put
from ..numerics.native_call import call_at

__all__ = ["attempt", "stepper", "derivatives", "interpolant", "interpolant_builder"]
OK, DECLINED = 0, 1  #: :func:`attempt`'s and :func:`interpolant`'s status
_A, _B, _C = np.ascontiguousarray(_coef.A[:12, :12]), _coef.B.copy(), _coef.C[:12].copy()
_E = np.ascontiguousarray(np.vstack((_coef.E5, _coef.E3)))  #: the error estimators' weights on K's 13 rows
_STAGE_C = np.append(_C[1:], 1.0)  #: [-] where in the step stages 1–11 and the end's call are
#: the dense output's tableau: all 16 stages (A, C) and the interpolant's weights D
_A16, _C16, _D16 = np.ascontiguousarray(_coef.A), _coef.C.copy(), np.ascontiguousarray(_coef.D)


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
    for r, k in ((0, 12), (1, 10), (2, 11)):  # (put: no array assignment, see numerics.linalg.put)
        put(block[r], 0, K[k])
    put(block[4], 0, y_new)
    for r in range(5, 10):
        put(block[r], 0, K[r])
    if e5 == 0.0 and e3 == 0.0:
        return 0.0
    return abs(h) * e5 / np.sqrt((e5 + 0.01 * e3) * n)


@njit(cache=True)
def attempt(ints, reals, work, events, t, y, f, h, rtol, atol, A, B, C, E, y_new, block, Ys, Es):
    """(status, error norm) of one DOP853 step of h [s] from (t, y) with f = f(t, y) over the packed mode's call;
    y_new and, in the scipy core's layout (:mod:`contactdyn.numerics.dop853`: f_new, stages 11, 12, –, y_new,
    stages 6–10), ``block`` written; ``events`` hold the FSAL call's event values, Ys[s] and Es[s] stage s's
    state and event values (s = 1 … 12, the FSAL call's last). DECLINED where a call's status is not 1 (a
    non-finite KKT system, a law that gave no force: the step by the Python right-hand side)."""
    n = y.size
    K = np.empty((13, n))
    put(K[0], 0, f)  # (put: no array assignment, see numerics.linalg.put)
    ys = np.empty(n)
    for s in range(1, 13):
        if s < 12:
            _stage_state(K, y, h, A, s, ys)
        else:
            _step_end(K, y, h, B, y_new)
            ys = y_new
        at = t + C[s] * h if s < 12 else t + h
        put(K[s], 0, call_at(ints[A_CALL], "pipeline.call", (at, ys, ints, reals, work, events)))  # (not linked in)
        if events[events.size - 1] != 1.0:
            return DECLINED, 0.0
        put(Ys[s], 0, ys)
        put(Es[s], 0, events)
    return OK, _error_norm(K, y, y_new, h, rtol, atol, E, block)


@njit(cache=True)
def interpolant(ints, reals, work, events, t, h, y, f, block, A, C, D):
    """(status, F): the 7th-order interpolant's coefficients F (7, n) of the accepted step of h [s] from (t [s], y),
    f = f(t, y), its stages in ``block`` (the scipy core's layout): DOP853's extra stages 14–16 through the packed
    mode's call, then :func:`~contactdyn.numerics.dense_output.coefficients`, the numbers
    :func:`~contactdyn.numerics.dop853.build_interpolants` forms by three calls. DECLINED where a call's status is not
    1 (then ``build_interpolants`` builds it, by the mode's derivatives)."""
    n = y.size
    K = np.zeros((1, 16, n))
    put(K[0, 0], 0, f)  # (put: no array assignment, see numerics.linalg.put)
    for r in range(5):
        put(K[0, 5 + r], 0, block[5 + r])  # stages 6–10
    put(K[0, 10], 0, block[1])
    put(K[0, 11], 0, block[2])
    put(K[0, 12], 0, block[0])  # f(t + h)
    Y0, y_new, hs = np.empty((1, n)), np.empty((1, n)), np.full(1, h)
    put(Y0[0], 0, y)
    put(y_new[0], 0, block[4])
    for s in range(13, 16):
        ys = stage_states(K, s, A, Y0, hs)
        put(K[0, s], 0, call_at(ints[A_CALL], "pipeline.call", (t + C[s] * h, ys[0], ints, reals, work, events)))
        if events[events.size - 1] != 1.0:
            return DECLINED, np.empty((0, n))
    return OK, coefficients(K, Y0, y_new, hs, D, 12)[0]


#: :func:`interpolant`'s argument types, compiled with a compiled mode (not at a run's first located event)
_F1, _F2, _I1 = types.float64[::1], types.float64[:, ::1], types.int64[::1]
INTERPOLANT_ARGS = (_I1, _F1, _F1, _F1, types.float64, types.float64, _F1, _F1, _F2, _F2, _F1, _F2)


def interpolant_builder(packed):
    """one(t, h, y, f, block) -> F (7, n), or None where a call of it declines: a step's interpolant in one compiled
    call (:func:`interpolant`) over a mode packed for the one pipeline (an event located in that step). Compiled
    here, where the compiled call is (a background build compiles it with the scene's kind, not a later run at its
    first event); an interpreted mode has none (its events' steps: ``build_interpolants`` by its derivatives)."""
    if hasattr(interpolant, "compile"):  # (not under NUMBA_DISABLE_JIT)
        interpolant.compile(INTERPOLANT_ARGS)
    ints, reals, work, events = packed.ints, packed.reals, packed.work, packed.events

    def one(t, h, y, f, block):
        status, F = interpolant(ints, reals, work, events, t, h, y, f, block, _A16, _C16, _D16)
        if status:  # (a Python stage's error: raised by the Python calls' repeat, at its call's time)
            drop_python_stage_error()
            return None
        return F

    return one


def stepper(packed, ring, on_stage=None, on_stages=None):
    """step(t, y, f, h, rtol, atol) -> (error norm, y_new, block), or None where a call of the step declines (then
    the caller takes the step by the pipeline's Python right-hand side), over a mode packed for the one pipeline
    (:class:`~contactdyn.model.pipeline.pack.Packed`); each step's FSAL call's event values enter ``ring`` as
    (t, y_new, events) (the event functions read them). ``on_stage(t, y)``: called after an attempt per stage
    (t [s], its state) with that stage's event values the ring's latest (a stuck contact's slip watch sees every
    stage, as it sees every call of the Python right-hand side); ``on_stages(times, Ys, Es)``: once per attempt with
    its stages' states and event values (stages 1–11, then the end's), ``times()`` their times [s]."""
    ints, reals, work, events = packed.ints, packed.reals, packed.work, packed.events
    Ys, Es = np.empty((13, packed.ints[NX])), np.empty((13, events.size))

    def step(t, y, f, h, rtol, atol):
        y_new, block = np.empty(y.size), np.empty((10, y.size))  # (block's row 3 is not read)
        status, err = attempt(ints, reals, work, events, t, y, f, h, rtol, atol, _A, _B, _C, _E, y_new, block,
                              Ys, Es)
        if status:  # (a Python stage's error: raised by the Python calls' repeat, at its call's time)
            drop_python_stage_error()
            return None
        if on_stages is not None:
            on_stages(lambda: t + _STAGE_C * h, Ys[1:], Es[1:])
        if on_stage is not None:
            for s in range(1, 12):
                ys = Ys[s]
                ring.append((t + _C[s] * h, ys, Es[s].copy()))
                on_stage(t + _C[s] * h, ys)
        ring.append((t + h, y_new, events.copy()))
        if on_stage is not None:
            on_stage(t + h, y_new)
        return err, y_new, block

    return step


def derivatives(packed, fun):
    """f(ts, Y) -> Ẋ (N, n): the pipeline's right-hand side at many states in one compiled call (the dense output's
    extra stages), bitwise its call; from a state whose call declines on, ``fun`` (its Python right-hand side)."""
    def batch(ts: np.ndarray, Y: np.ndarray) -> np.ndarray:
        ts, Y = np.ascontiguousarray(ts, dtype=float), np.ascontiguousarray(Y, dtype=float)
        Yd, done = rates_at(ts, Y, packed.ints, packed.reals, packed.work, packed.events)
        for k in range(done, len(ts)):
            Yd[k] = fun(float(ts[k]), Y[k])
        return Yd

    return batch
