"""DOP853 stepped by scipy's compiled core, with dense output and located events.

``solve_ivp``'s DOP853 is written in Python: every step pays for its stage
combinations, error norm, step control, dense output and event bookkeeping in NumPy
calls (65 µs per step with an empty right-hand side, against 8 µs here; ~75 µs on B1
against ~100 µs of right-hand side; docs/performance.md). Here the steps are
taken by scipy's compiled DOP853 (``scipy.integrate._dop.dopri853``, the C translation of
Hairer's code behind ``scipy.integrate.ode("dop853")``), and Python sees each accepted
step once, in the ``solout`` callback, to test the events.

Dense output. scipy's C wrapper does not pass Hairer's ``CONT`` array to ``solout``, and
asking for it (``iout = 2``) crashes scipy 1.17 (the core advances its ``nfcn`` pointer
instead of the count). The stages are still in the workspace the caller owns, laid out as
Hairer documents (``WORK(21…)``: k1…k10, y1): at each accepted step ``solout`` copies
them, and the 7th-order interpolant of a step (the tableau's, :mod:`.dop853_tableau`, three more
right-hand-side calls) is built only when something needs it: an event's sign change in
that step, or output samples falling in it, then for all those steps in one batch.

Events follow ``solve_ivp``'s contract: ``g(t, y)`` at t0 and at every step end in
increasing t; a sign change in the event's direction is located by Brent's method (:func:`brent_root`, scipy's
``brentq``'s iterations) on the step's interpolant (xtol = rtol = 4 ε), and the earliest terminal root ends the run
there. Step control is ``solve_ivp``'s, so both take the same steps. The first step is solve_ivp's estimate
(:func:`_initial_step`, ``select_initial_step``'s arithmetic; the core's own uses other norms). After an accepted step
the core's rule is solve_ivp's (h·min(MAX_FACTOR, SAFETY err^(−1/8)), no Lund stabilisation).
After a rejection it is not: scipy's C core shrinks by a fixed factor (a slip in its translation
of Hairer's code) where solve_ivp shrinks by max(MIN_FACTOR, SAFETY err^(−1/8)), and on B1 that
cost 26 % more steps (306 against 243). So a rejection ends the core's run (``_Core``), the
rejected step's error norm is read from the stages left in the workspace, and the run restarts
with solve_ivp's smaller step; the step after it may not grow (solve_ivp's rule, enforced by
reading the next step off its first stage time). Stiffness detection is off, as in
``solve_ivp``. Verified against ``solve_ivp``'s DOP853 in ``tests/test_dop853.py``.

Compiled steps. A right-hand side whose whole step can be one compiled call brings it (``step``, from
:mod:`contactdyn.hybrid.steps`: the stages, y_new, the FSAL call and the error norm): then :func:`_stepped`
takes the steps, with ``solve_ivp``'s RK step control written out (its loop, not the core's), the stages
kept in the core's layout for the same dense output and events; a step the compiled call declines is taken
by ``fun`` (:func:`_attempt`, ``solve_ivp``'s arithmetic). Verified in ``tests/test_compiled_steps.py``. Such a run
never imports scipy.integrate or scipy.optimize (the core is imported at its first use: :func:`scipy_core`):
``tests/test_scipy_free_start.py`` holds the tableau, the first step and the roots to scipy's bit for bit.
"""

from __future__ import annotations

import math
from bisect import bisect_left
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np

from ..errors import SceneError
from . import dop853_tableau as _coef
from .dense_output import horner_at, horner_rows
from .twins import current

__all__ = ["solve", "DenseSolution", "Solution", "build_interpolants", "dense_states"]

#: the core's rejection factor (its fac1). scipy 1.17's C translation shrinks a rejected step by this fixed
#: factor (it reads facc1/safe where Hairer's Fortran has fac11/safe); solve_ivp by max(MIN_FACTOR,
#: SAFETY err^(−1/8)). So small that the core's next step is below its minimum: the run returns at
#: once, and solve() restarts it with solve_ivp's step. It bounds accepted steps' ratios too, never binding.
_END_AT_REJECTION = 1e-300
_LIMIT_SLACK = 1e-9  #: relative slack when reading a step size back from a stage time (rounding) [-]
MAX_STEPS = 10**9  #: step budget of one call (no practical limit; stiffness detection is off)
_ERROR_ORDER = 7  #: DOP853's error estimator order (solve_ivp's error_estimator_order)
_EXPONENT = -1.0 / (_ERROR_ORDER + 1)  #: step ratio = SAFETY err^_EXPONENT
_EPS = np.finfo(float).eps
_WORK0 = 20  #: k1 starts at work[20] (Hairer's WORK(21))
# slots of the workspace block k1…k10 after an accepted step (each n long)
_F_NEW, _S11, _S12, _Y_NEW = 0, 1, 2, 4  # k1 = f(t_new), k2 = stage 11, k3 = stage 12, k5 = y_new
_STAGES_6_10 = slice(5, 10)  # k6…k10 = stages 6…10
#: the stage held in each row of the workspace block after a rejected attempt (k1 is still f(t_old);
#: k4 = Σ b k and k5 = y_new hold no stage): the error norms' weights E5, E3 on those rows (the other
#: stages have weight 0, tests/test_dop853.py)
_ROW_STAGE = (0, 10, 11, None, None, 5, 6, 7, 8, 9)
_ERR_ROWS = np.array([[0.0 if s is None else E[s] for s in _ROW_STAGE] for E in (_coef.E5, _coef.E3)])
_A, _C, _D = _coef.A, _coef.C, _coef.D
_N = _coef.N_STAGES  # 12
#: right-hand-side calls of one step's interpolant (DOP853's extra stages 14–16)
INTERPOLANT_STAGES = _coef.N_STAGES_EXTENDED - _N - 1
#: solve_ivp's step control (scipy.integrate._ivp.rk's): a step grows by at most MAX_FACTOR, a rejected one shrinks
#: by at least MIN_FACTOR, the error's proposal is damped by SAFETY
SAFETY, MIN_FACTOR, MAX_FACTOR = 0.9, 0.2, 10.0
_MESSAGES = {-1: "input is not consistent", -2: "larger nsteps is needed", -3: "step size becomes too small",
             -4: "problem is probably stiff"}


@dataclass
class _Steps:
    """Accepted steps of one run: ends, states, stages; interpolants built on demand."""

    fun: Callable
    n: int
    t: list[float] = field(default_factory=list)  #: step ends [s], t[0] = t0
    y0: np.ndarray | None = None
    f0: np.ndarray | None = None  #: f(t0, y0)
    blocks: list[np.ndarray] = field(default_factory=list)  #: workspace k1…k10 (10 n) per step
    coef: dict[int, np.ndarray] = field(default_factory=dict)  #: step -> interpolant coefficients (7, n)
    calls: int = 0  #: right-hand-side calls made for interpolants
    end_x: np.ndarray | None = None  #: the last step end's state as the FSAL call got it (None: not kept)
    #: [s] per accepted step, the step its error proposes next (h min(MAX_FACTOR, SAFETY err^(−1/8)), before the
    #: no-growth rule after a rejection), where the compiled steps took them (:func:`_stepped`): :func:`_proposal`'s
    proposals: list[float] = field(default_factory=list)

    def y_old(self, i: int) -> np.ndarray:
        return self.y0 if i == 0 else self.blocks[i - 1][_Y_NEW]

    def f_old(self, i: int) -> np.ndarray:
        return self.f0 if i == 0 else self.blocks[i - 1][_F_NEW]

    def at(self, i: int, t: float, derivatives: Callable | None = None) -> np.ndarray:
        """The state at t [s] on step i's own interpolant, as solve_ivp's step dense output. Built if needed: by
        ``derivatives`` (see :func:`build_interpolants`); else by the run's ``fun.interpolant`` (one compiled call),
        else by its ``fun.derivatives``, else by ``fun``, one call per state (all the same numbers)."""
        if i not in self.coef and (derivatives is not None or not self._built_by_fun(i)):
            build_interpolants([(self, i)], derivatives or getattr(self.fun, "derivatives", None))
        t_old = self.t[i]
        return current(horner_at)(self.coef[i], (t - t_old) / (self.t[i + 1] - t_old), self.y_old(i))

    def _built_by_fun(self, i: int) -> bool:
        """Step i's interpolant by the run's ``fun.interpolant`` (:func:`build_interpolants`' numbers in one compiled
        call: :func:`~contactdyn.hybrid.steps.interpolant`, a compiled mode's): False where it has none or declines."""
        one = getattr(self.fun, "interpolant", None)
        F = one(self.t[i], self.t[i + 1] - self.t[i], self.y_old(i), self.f_old(i), self.blocks[i]) if one else None
        if F is None:
            return False
        self.coef[i] = F
        self.calls += INTERPOLANT_STAGES
        return True


def build_interpolants(wanted: list[tuple[_Steps, int]], derivatives: Callable | None = None) -> None:
    """Interpolant coefficients of steps (steps, i) of one or several runs (DOP853's stages 14–16), in one batch:
    each step's row is its own arithmetic (the batch's other rows do not change its numbers).

    ``derivatives(ts, Y) -> F``: the runs' right-hand side at all the steps' stage states at once, in place of one
    call per state (:func:`~contactdyn.hybrid.steps.derivatives` gives the calls' values bitwise); None: each run's
    ``fun``, one call per state."""
    if not wanted:
        return
    m, n = len(wanted), wanted[0][0].n
    t_old = np.array([st.t[i] for st, i in wanted])
    h = np.array([st.t[i + 1] for st, i in wanted]) - t_old
    Y0 = np.array([st.y_old(i) for st, i in wanted])
    B = np.array([st.blocks[i] for st, i in wanted])
    K = np.zeros((m, _coef.N_STAGES_EXTENDED, n))
    K[:, 0] = [st.f_old(i) for st, i in wanted]
    K[:, 5:10] = B[:, _STAGES_6_10]
    K[:, 10], K[:, 11], K[:, _N] = B[:, _S11], B[:, _S12], B[:, _F_NEW]
    for s in range(_N + 1, _coef.N_STAGES_EXTENDED):
        Ys = Y0 + h[:, None] * np.einsum("msn,s->mn", K[:, :s], _A[s, :s])
        ts = t_old + _C[s] * h
        if derivatives is not None:
            K[:, s] = derivatives(ts, Ys)
        else:
            for k, (st, _) in enumerate(wanted):
                K[k, s] = st.fun(float(ts[k]), Ys[k])
        for st, _ in wanted:
            st.calls += 1
    dy = B[:, _Y_NEW] - Y0
    F = np.empty((m, _coef.INTERPOLATOR_POWER, n))
    F[:, 0] = dy
    F[:, 1] = h[:, None] * K[:, 0] - dy
    F[:, 2] = 2.0 * dy - h[:, None] * (K[:, _N] + K[:, 0])
    F[:, 3:] = h[:, None, None] * np.einsum("ds,msn->mdn", _D, K)
    for k, (st, i) in enumerate(wanted):
        st.coef[i] = F[k]


class DenseSolution:
    """y(t) on [t0, t_end] from the steps' 7th-order interpolants (like ``OdeSolution``)."""

    def __init__(self, steps: _Steps, t_end: float):
        self.steps = steps
        self.t_min, self.t_max = steps.t[0], t_end
        self._t = np.array(steps.t)  #: the step ends [s], t0 first (fixed: the run has returned)
        self.ends = self._t[1:]
        self.calls_counted = steps.calls  #: interpolant calls already in the Solution's nfev

    @property
    def late_calls(self) -> int:
        """Right-hand-side calls made for interpolants after the run returned (output sampling)."""
        return self.steps.calls - self.calls_counted

    def __call__(self, t, derivatives: Callable | None = None) -> np.ndarray:
        """The state at t [s] (shape (n,)) or at each time of an array (shape (n, len(t))).

        ``derivatives``: see :func:`build_interpolants` (the interpolants this call builds, for output samples; at
        one time without it: :meth:`_Steps.at`'s)."""
        if np.ndim(t) == 0:
            return self.state(float(t), derivatives)
        (y,) = dense_states([(self, np.atleast_1d(np.asarray(t, float)))], derivatives)
        return y.T

    def state(self, t: float, derivatives: Callable | None = None) -> np.ndarray:
        """The state at one time t [s]: :meth:`locate`'s step and fraction, without its arrays (the same numbers)."""
        st = self.steps
        if not len(self.ends) or t == st.t[0]:
            return st.y0.copy()
        i = min(bisect_left(st.t, t, 1) - 1, len(self.ends) - 1)  # (np.searchsorted(self.ends, t, "left"))
        return st.at(i, t, derivatives)

    def locate(self, tt: np.ndarray) -> tuple[list[int], np.ndarray, np.ndarray] | None:
        """Where the times tt [s] fall: (their steps, sorted; each time's position in that list; its step fraction
        [-]), or None where the state is y0 at all of them (no step, or all at the start)."""
        st = self.steps
        if not len(self.ends) or (tt == st.t[0]).all():  # (at the start: y0, what the interpolant gives there)
            return None
        idx = np.minimum(np.searchsorted(self.ends, tt, side="left"), len(self.ends) - 1)
        steps = sorted(set(idx.tolist()))  # per step, then per sample (np.unique's, without its cost on ~3 items)
        ends = self._t
        return steps, np.searchsorted(steps, idx), (tt - ends[idx]) / (ends[idx + 1] - ends[idx])

    def states(self, tt: np.ndarray, where) -> np.ndarray:
        """The states (len(tt), n) at the times tt [s] located at ``where`` (:meth:`locate`; interpolants built)."""
        st = self.steps
        if where is None:
            return np.repeat(st.y0[None, :], len(tt), axis=0)
        steps, at, s = where
        C, Y0 = np.array([st.coef[i] for i in steps]), np.array([st.y_old(i) for i in steps])
        return current(horner_rows)(C, at, s, Y0)  # (a leaf: a first run's record holds it)


def dense_states(parts: list[tuple[DenseSolution, np.ndarray]], derivatives: Callable | None = None
                 ) -> list[np.ndarray]:
    """The states (len(tt), n) of dense outputs at their times tt [s], (dense, tt) per part (each dense once), the
    interpolants they need built in one batch (:func:`build_interpolants`, with ``derivatives``)."""
    where = [dense.locate(tt) for dense, tt in parts]
    build_interpolants([(dense.steps, i) for (dense, _), w in zip(parts, where, strict=True) if w is not None
                        for i in w[0] if i not in dense.steps.coef], derivatives)
    located = [(dense.steps, w) for (dense, _), w in zip(parts, where, strict=True) if w is not None]
    if len(located) < 2:
        return [dense.states(tt, w) for (dense, tt), w in zip(parts, where, strict=True)]
    states = iter(_states_at_once(located))  # (a piecewise run's many pieces: one compiled call, not one each)
    return [next(states) if w is not None else dense.states(tt, w) for (dense, tt), w in zip(parts, where, strict=True)]


def _states_at_once(located: list[tuple[_Steps, tuple]]) -> list[np.ndarray]:
    """:meth:`DenseSolution.states` of several runs' located times ((steps, where) per run) in one compiled call:
    each row is its own arithmetic, so the numbers are the same as one call per run."""
    C = np.array([st.coef[i] for st, (steps, _, _) in located for i in steps])
    Y0 = np.array([st.y_old(i) for st, (steps, _, _) in located for i in steps])
    firsts = np.cumsum([0] + [len(steps) for _, (steps, _, _) in located[:-1]])  # each run's first row in C
    at = np.concatenate([w[1] + first for (_, w), first in zip(located, firsts, strict=True)])
    rows = current(horner_rows)(C, at, np.concatenate([w[2] for _, w in located]), Y0)
    return np.split(rows, np.cumsum([len(w[1]) for _, w in located[:-1]]))


@dataclass
class Solution:
    """What ``solve_ivp`` returns, as far as the hybrid loop reads it."""

    t: np.ndarray
    y: np.ndarray
    sol: DenseSolution
    t_events: list[np.ndarray]
    status: int  #: 0 end reached, 1 a terminal event, −1 failure
    message: str
    nfev: int
    naccept: int
    nreject: int
    #: [s] the step solve_ivp's control proposes after the last accepted one (None: the run did not reach its end)
    h_next: float | None = None

    @property
    def success(self) -> bool:
        return self.status >= 0


def _active(g_old: float, g_new: float, direction: float) -> bool:
    """Did g cross zero between two step ends in the event's direction (``solve_ivp``'s test)?"""
    up = g_old <= 0.0 <= g_new
    down = g_old >= 0.0 >= g_new
    return (up and direction > 0) or (down and direction < 0) or ((up or down) and direction == 0)


class _EventWatch:
    """The events' values at the step ends, and their roots (``solve_ivp``'s rules)."""

    def __init__(self, events: Sequence[Callable], t0: float, y0: np.ndarray):
        self.events = list(events)
        self.g = [float(e(t0, y0)) for e in self.events]
        self.direction = [float(getattr(e, "direction", 0.0)) for e in self.events]
        self.terminal = [bool(getattr(e, "terminal", False)) for e in self.events]
        self.falling = all(d < 0 for d in self.direction)  #: _active reduces to g_old ≥ 0 ≥ g_new
        #: the events that also look inside a step, on its dense output (``dips(t_old, state_at)``: whether their
        #: function falls below zero and back within it; they then hold it negative from there while it is located)
        self.inside = [i for i, e in enumerate(self.events) if getattr(e, "dips", None) is not None]
        self.hits: list[tuple[float, int]] = []  #: (root [s], event), in time order

    def stop(self, steps: _Steps, t: float, x: np.ndarray) -> bool:
        """At the step end (t, x): record the roots in the step; True at a terminal one (hits ends with it)."""
        g_old, g_new = self.g, [float(e(t, x)) for e in self.events]
        step, t_old = len(steps.t) - 2, steps.t[-2]
        for i in self.inside:
            if g_new[i] > 0.0 and self.events[i].dips(t_old, lambda s: steps.at(step, s)):
                g_new[i] = -1.0
            elif g_new[i] <= 0.0 < g_old[i] and hasattr(self.events[i], "first_fall"):  # (the first of several)
                self.events[i].first_fall(t_old, lambda s: steps.at(step, s))
        self.g = g_new
        if self.falling:  # all events fall through zero (the hybrid loop's): one test per event
            fired = [i for i, (a, b) in enumerate(zip(g_old, g_new, strict=True)) if a >= 0.0 >= b]
        else:
            fired = [i for i, (a, b, d) in enumerate(zip(g_old, g_new, self.direction, strict=True))
                     if _active(a, b, d)]
        if not fired:
            return False
        for i in fired:  # as solve_ivp: brentq on the step's own interpolant (a step shorter than t's
            # resolution, LSODA's where its steps collapse: at its end)
            root = t if t == t_old else brent_root(lambda s, e=self.events[i]: e(s, steps.at(step, s)), t_old, t,
                                               xtol=4 * _EPS, rtol=4 * _EPS)
            self.hits.append((root, i))
        self.hits.sort()
        first = next((k for k, (_, i) in enumerate(self.hits) if self.terminal[i]), None)
        if first is None:
            return False
        del self.hits[first + 1:]
        return True

    def t_events(self) -> list[np.ndarray]:
        return [np.array([r for r, k in self.hits if k == i]) for i in range(len(self.events))]


class _Core:
    """Runs of scipy's compiled DOP853 from the last accepted step: its workspace and its two callbacks.

    A run ends at t_end, at a terminal event, or at the first rejected step: with the core's
    rejection factor at ``_END_AT_REJECTION`` its next step is below its own minimum and it returns
    (ierr −3) with the rejected attempt's stages still in the workspace, from which
    :meth:`error_norm` reads solve_ivp's error norm; the driver (:func:`solve`) then restarts it
    with solve_ivp's smaller step. (At t = 0 the core's minimum is 0 and it tries once more: the
    new attempt's first call tells, and the run is ended from ``f``.)
    """

    def __init__(self, fun: Callable, t0: float, y0: np.ndarray, f0: np.ndarray, events: _EventWatch,
                 rtol: float, atol: float, max_step: float):
        self.core = scipy_core()
        n = len(y0)
        self.fun, self.n, self.watch = fun, n, events
        self.rtol, self.atol = rtol, atol
        self.work = np.zeros(11 * n + 21)  # Hairer's layout: 20 parameters, then k1…k10, y1
        self.block = self.work[_WORK0:_WORK0 + 10 * n].reshape(10, n)  #: view of k1…k10
        self.iwork = np.zeros(21, dtype=np.int32)
        self.work[1], self.work[2], self.work[3] = SAFETY, _END_AT_REJECTION, MAX_FACTOR
        self.work[4] = -1.0  # no Lund stabilisation (beta = 0), as solve_ivp
        self.work[5] = max_step if np.isfinite(max_step) else 0.0
        self.steps = _Steps(fun, n, [t0], y0.copy(), f0)
        self.last_t, self.last_x, self.calls = None, None, 0  # the latest call: at a step end, the FSAL one
        self.failure: list[BaseException] = []
        self.nan = np.full(n, np.nan)
        self.rejected: tuple[float, float] | None = None  #: (step [s], error norm) that ended the run
        self.grew = False  #: the run was ended because the step after a retried one grew (solve_ivp forbids it)
        self.ending = False  #: failure, rejected or grew: the run is being ended

    def run(self, t_end: float, h: float, limit: float | None) -> int:
        """One run of the core from the last accepted step with first step h [s] (the core's ierr).

        ``limit`` [s]: after a rejection, the step following the first accepted one may not exceed it.
        """
        steps = self.steps
        self.limit, self.check_next, self.rejected, self.grew, self.ending = limit, False, None, False, False
        self.fresh, self.started, self.since = True, False, 0
        self.work[6] = h
        self.iwork[:] = 0
        self.iwork[3] = -1  # no stiffness detection
        t = steps.t[-1]
        # the extra-arguments tuple () given explicitly: scipy 1.17's wrapper leaves its optional
        # fcn_extra_args uninitialized when omitted and may append a stale tuple's items to every call
        _, _, ierr = self.core(self.f, t, steps.y_old(len(steps.t) - 1), t_end, self.rtol, self.atol, self.solout,
                           1, self.work, self.iwork, MAX_STEPS, -1, ())
        if self.failure:
            raise self.failure[0]
        if ierr == -3 and self.since == _N - 1 and self.rejected is None and not self.grew:
            h_step = self.last_t - steps.t[-1]  # the attempt's last stage is at its end
            self.rejected = (h_step, self.error_norm(h_step))
        return int(ierr)

    def error_norm(self, h_step: float) -> float:
        """solve_ivp's error norm of the attempt whose stages are in the workspace (the rejected one)."""
        n, block = self.n, self.block
        y_old = self.steps.y_old(len(self.steps.t) - 1)
        scale = self.atol + self.rtol * np.maximum(np.abs(y_old), np.abs(block[_Y_NEW]))
        e5, e3 = (_ERR_ROWS @ block) / scale
        s5, s3 = float(e5 @ e5), float(e3 @ e3)
        if s5 == 0.0 and s3 == 0.0:
            return 0.0
        return abs(h_step) * s5 / np.sqrt((s5 + 0.01 * s3) * n)

    def f(self, t: float, x: np.ndarray) -> np.ndarray:
        """The right-hand side as the core calls it."""
        if self.ending:
            return self.nan  # the run is being ended (the core stops after this attempt)
        if self.fresh:  # the core's first call: f at the start, known (f0 or the last FSAL value)
            self.fresh = False
            return self.steps.f_old(len(self.steps.t) - 1)
        since = self.since = self.since + 1
        if since == 1 and self.check_next:  # the first stage of the step after a retried one
            self.check_next, limit, self.limit = False, self.limit, None
            if (t - self.steps.t[-1]) / _C[1] > limit * (1.0 + _LIMIT_SLACK):
                self.grew = self.ending = True
                return self.nan
        elif since == _N and t != self.last_t:  # not the FSAL call: a new attempt (a rejection at t = 0)
            h_step = self.last_t - self.steps.t[-1]
            self.rejected, self.ending = (h_step, self.error_norm(h_step)), True
            return self.nan
        if since == _N:  # the step end's (FSAL) call, whose state the events read after the core moved on: a
            x = x.copy()  # copy (the core passes views of its workspace, which its next stages overwrite)
        self.last_t, self.last_x = t, x
        self.calls += 1
        try:
            return self.fun(t, x)
        except BaseException as exc:  # raised again after the core returns (it cannot carry it)
            self.failure.append(exc)
            self.ending = True
            return self.nan

    def solout(self, t: float, y: np.ndarray) -> int:
        """After each accepted step: keep its stages, test the events; −1 stops the core."""
        try:
            return self._step_end(t)
        except BaseException as exc:  # as in f
            self.failure.append(exc)
            self.ending = True
            return -1

    def _step_end(self, t: float) -> int:
        steps = self.steps
        if self.failure:
            return -1
        if not self.started:  # the call at the run's start
            self.started = True
            return 0
        self.check_next = self.limit is not None  # the run's first accepted step (f clears the limit)
        self.since = 0
        steps.t.append(t)
        steps.blocks.append(self.block.copy())
        steps.end_x = self.last_x if self.last_t == t else None
        if not self.watch.events:
            return 0
        # the FSAL call's own array (the same values): a compiled mode has its results cached
        x = self.last_x if self.last_t == t else steps.blocks[-1][_Y_NEW]
        return -1 if self.watch.stop(steps, t, x) else 0  # (the located step's interpolant is built)


def _first_step(fun: Callable, t0: float, y0: np.ndarray, f0: np.ndarray, t_end: float, max_step: float,
                rtol: float, atol: float, first_step: float | None) -> float:
    """solve_ivp's first step [s]: the given one (within max_step), else scipy's own estimate (one call)."""
    if first_step:
        return min(float(first_step), max_step)
    return _initial_step(fun, t0, y0, f0, t_end, max_step, rtol, atol)


def _rms(v: np.ndarray) -> float:
    """The root mean square of v (solve_ivp's norm)."""
    return np.linalg.norm(v) / v.size ** 0.5


def _initial_step(fun: Callable, t0: float, y0: np.ndarray, f0: np.ndarray, t_end: float, max_step: float,
                  rtol: float, atol: float) -> float:
    """[s] solve_ivp's estimate of the first step forwards from (t0, y0), f0 = f(t0, y0) (Hairer, Nørsett and
    Wanner I, II.4): one call. scipy's ``select_initial_step``, the same arithmetic
    (``tests/test_scipy_free_start.py``)."""
    if y0.size == 0:
        return math.inf
    span = abs(t_end - t0)
    if span == 0.0:
        return 0.0
    scale = atol + np.abs(y0) * rtol
    d0, d1 = _rms(y0 / scale), _rms(f0 / scale)
    h0 = 1e-6 if d0 < 1e-5 or d1 < 1e-5 else 0.01 * d0 / d1
    h0 = min(h0, span)
    f1 = fun(t0 + h0, y0 + h0 * f0)
    d2 = _rms((f1 - f0) / scale) / h0
    h1 = max(1e-6, h0 * 1e-3) if d1 <= 1e-15 and d2 <= 1e-15 else (0.01 / max(d1, d2)) ** (1 / (_ERROR_ORDER + 1))
    return float(min(100 * h0, h1, span, max_step))


def scipy_core():
    """scipy's compiled DOP853 core (``scipy.integrate._dop.dopri853``, scipy 1.17), imported at its first use: a run
    on the compiled steps (hybrid.steps) never imports scipy.integrate."""
    from scipy.integrate import _dop  # (~0.5 s with scipy.optimize, which it imports)

    core = getattr(_dop, "dopri853", None)  # (older scipy has an f2py one)
    if core is None:
        import scipy

        raise SceneError("solver.method", "DOP853C: scipy's compiled DOP853 (scipy.integrate._dop.dopri853, "
                         "as in scipy 1.17); or DOP853", f"scipy {scipy.__version__} without it")
    return core


def brent_root(f: Callable[[float], float], a: float, b: float, xtol: float, rtol: float, maxiter: int = 100) -> float:
    """A root of f in [a, b] (f(a), f(b) of opposite signs) by Brent's method (Brent 1973, ch. 4): inverse quadratic
    or secant steps where they stay well inside the bracket, else bisection, to |error| ≤ (xtol + rtol |x|) / 2.
    The same iterations as scipy's ``brentq`` (its C loop), so the same root bit for bit
    (``tests/test_scipy_free_start.py``), here without importing scipy.optimize. A NaN value or no convergence in
    ``maxiter`` raises, as brentq does."""
    def value(x: float) -> float:
        fx = float(f(x))
        if math.isnan(fx):
            raise ValueError(f"The function value at x={x:f} is NaN; solver cannot converge.")
        return fx

    xpre, xcur = float(a), float(b)
    fpre, fcur = value(xpre), value(xcur)
    if fpre == 0.0:
        return xpre
    if fcur == 0.0:
        return xcur
    if math.copysign(1.0, fpre) == math.copysign(1.0, fcur):
        raise ValueError("f(a) and f(b) must have different signs")
    xblk = fblk = spre = scur = 0.0
    for _ in range(maxiter):
        if fpre != 0.0 and fcur != 0.0 and math.copysign(1.0, fpre) != math.copysign(1.0, fcur):
            xblk, fblk = xpre, fpre
            spre = scur = xcur - xpre
        if abs(fblk) < abs(fcur):
            xpre, xcur, xblk = xcur, xblk, xcur
            fpre, fcur, fblk = fcur, fblk, fcur
        delta = (xtol + rtol * abs(xcur)) / 2
        sbis = (xblk - xcur) / 2
        if fcur == 0.0 or abs(sbis) < delta:
            return xcur
        if abs(spre) > delta and abs(fcur) < abs(fpre):
            if xpre == xblk:  # secant
                stry = -fcur * (xcur - xpre) / (fcur - fpre)
            else:  # inverse quadratic
                dpre = (fpre - fcur) / (xpre - xcur)
                dblk = (fblk - fcur) / (xblk - xcur)
                stry = -fcur * (fblk * dblk - fpre * dpre) / (dblk * dpre * (fblk - fpre))
            bound = min(abs(spre), 3 * abs(sbis) - delta)
            spre, scur = (scur, stry) if 2 * abs(stry) < bound else (sbis, sbis)
        else:
            spre = scur = sbis
        xpre, fpre = xcur, fcur
        xcur += scur if abs(scur) > delta else (delta if sbis > 0 else -delta)
        fcur = value(xcur)
    raise RuntimeError(f"Failed to converge after {maxiter} iterations.")


def solve(fun: Callable[[float, np.ndarray], np.ndarray], t_span: tuple[float, float], y0: np.ndarray, *,
          rtol: float, atol: float, max_step: float = np.inf, first_step: float | None = None,
          events: Sequence[Callable] | None = None, step: Callable | None = None) -> Solution:
    """Integrate y' = fun(t, y) over t_span by compiled DOP853, locating the events (``solve_ivp``'s contract).

    ``atol`` and ``rtol`` are scalars; ``max_step`` [s] (inf: none) and ``first_step`` [s] (None:
    solve_ivp's estimate) as in ``solve_ivp``. Events are terminal if their ``terminal`` attribute is.
    The steps are solve_ivp's: after a rejection the step shrinks by max(MIN_FACTOR, SAFETY err^(−1/8))
    and the next step may not grow. ``step``: a compiled step attempt of ``fun``'s (hybrid.steps)
    that takes the steps in place of scipy's core, with the same step control.
    """
    t0, t_end = float(t_span[0]), float(t_span[1])
    y0 = np.array(y0, float)
    f0 = np.asarray(fun(t0, y0), float)  # (first: the events' values at the start then read this call's)
    watch = _EventWatch(events or [], t0, y0)
    calls = [1]

    def counted(t, y):
        calls[0] += 1
        return fun(t, y)

    h = _first_step(counted, t0, y0, f0, t_end, max_step, rtol, atol, first_step)
    if step is not None:
        steps = _Steps(fun, len(y0), [t0], y0.copy(), f0)
        ierr, nreject, calls[0] = _stepped(step, fun, steps, watch, t_end, h, rtol, atol, max_step, calls[0])
        return _solution(steps, watch, ierr, t_end, calls[0], nreject, rtol, atol)
    core = _Core(fun, t0, y0, f0, watch, rtol, atol, max_step)
    ierr, nreject = core_steps(core, t_end, h)
    return _solution(core.steps, watch, ierr, t_end, calls[0] + core.calls, nreject, rtol, atol)


def core_steps(core: _Core, t_end: float, h: float) -> tuple[int, int]:
    """Runs of the core from its last accepted step to t_end [s] with first step h [s], restarted after each
    rejection with solve_ivp's smaller step: (the core's ierr, rejections)."""
    limit, nreject, ierr = None, 0, 1
    while t_end > core.steps.t[-1]:
        t = core.steps.t[-1]
        if h < 10.0 * abs(np.nextafter(t, np.inf) - t):  # solve_ivp's smallest step
            ierr = -3
            break
        ierr = core.run(t_end, h, limit)
        if core.rejected:  # solve_ivp's rule: shrink by the error, and the step after may not grow
            h_step, err = core.rejected
            h = limit = abs(h_step) * max(MIN_FACTOR, SAFETY * err ** _EXPONENT)
            nreject += 1
        elif core.grew:
            h, limit = limit, None
        else:
            break
    return ierr, nreject


def _stepped(step: Callable, fun: Callable, steps: _Steps, watch: _EventWatch, t_end: float, h_abs: float,
             rtol: float, atol: float, max_step: float, calls: int) -> tuple[int, int, int]:
    """solve_ivp's DOP853 steps (its RK step control; h_abs, max_step [s]) by ``step`` (a compiled attempt,
    :mod:`contactdyn.hybrid.steps`; None where it cannot: then :func:`_attempt` by ``fun``): (the core's ierr,
    rejections, calls)."""
    nreject = 0
    while steps.t[-1] < t_end:
        t, y, f = steps.t[-1], steps.y_old(len(steps.t) - 1), steps.f_old(len(steps.t) - 1)
        min_step = 10.0 * abs(math.nextafter(t, math.inf) - t)
        h_abs = min(max(h_abs, min_step), max_step)
        rejected = False
        while True:
            if h_abs < min_step:
                return -3, nreject, calls
            t_new = min(t + h_abs, t_end)
            h = t_new - t
            got = step(t, y, f, h, rtol, atol) or _attempt(fun, t, y, f, h, rtol, atol)
            calls += _N
            err, y_new, block = got
            if err < 1.0:
                factor = MAX_FACTOR if err == 0.0 else min(MAX_FACTOR, SAFETY * err ** _EXPONENT)
                h_abs = abs(h) * (min(1.0, factor) if rejected else factor)
                steps.proposals.append(h * factor)
                break
            h_abs = abs(h) * max(MIN_FACTOR, SAFETY * err ** _EXPONENT)
            rejected, nreject = True, nreject + 1
        steps.t.append(t_new)
        steps.blocks.append(block)
        steps.end_x = y_new
        if watch.events and watch.stop(steps, t_new, y_new):
            return 2, nreject, calls
    return 1, nreject, calls


def _attempt(fun: Callable, t: float, y: np.ndarray, f: np.ndarray, h: float, rtol: float, atol: float
             ) -> tuple[float, np.ndarray, np.ndarray]:
    """One DOP853 step attempt by ``fun`` as solve_ivp's (rk_step, _estimate_error_norm): (error norm, y_new,
    the stages in the core's layout)."""
    K = np.empty((_N + 1, len(y)))
    K[0] = f
    for s in range(1, _N):
        K[s] = fun(t + _C[s] * h, y + (K[:s].T @ _A[s, :s]) * h)
    y_new = y + h * (K[:_N].T @ _coef.B)
    K[_N] = fun(t + h, y_new)
    scale = atol + np.maximum(np.abs(y), np.abs(y_new)) * rtol
    e5, e3 = ((K.T @ _coef.E5) / scale) ** 2, ((K.T @ _coef.E3) / scale) ** 2
    s5, s3 = float(e5.sum()), float(e3.sum())
    err = 0.0 if s5 == 0.0 and s3 == 0.0 else abs(h) * s5 / np.sqrt((s5 + 0.01 * s3) * len(y))
    block = np.zeros((10, len(y)))
    block[_F_NEW], block[_S11], block[_S12], block[_Y_NEW] = K[_N], K[10], K[11], y_new
    block[_STAGES_6_10] = K[5:10]
    return err, y_new, block


def _solution(steps: _Steps, watch: _EventWatch, ierr: int, t_end: float, calls: int, nreject: int, rtol: float,
              atol: float) -> Solution:
    """The Solution of a finished integration (core's ierr: 1 end, 2 stopped by an event, < 0 failure)."""
    if ierr == 1:
        steps.t[-1] = t_end  # the core's last step ends at t + (t_end − t), within rounding of t_end
    status, message, t_stop = solution_status(ierr, watch, steps.t[-1])
    dense = DenseSolution(steps, t_stop)
    ts = np.array(steps.t)
    ys = np.column_stack([steps.y0] + [b[_Y_NEW] for b in steps.blocks])
    if status == 1:
        ts[-1] = t_stop
        ys[:, -1] = dense(t_stop)
    h_next = _proposal(steps, rtol, atol) if status == 0 and len(steps.t) > 1 else None
    return Solution(ts, ys, dense, watch.t_events(), status, message, calls + steps.calls, len(steps.t) - 1, nreject,
                    h_next)


def solution_status(ierr: int, watch: _EventWatch, t_last: float) -> tuple[int, str, float]:
    """(status, message, where the solution stops [s]) of a run that ended with the core's ierr at t_last [s]."""
    if ierr == 2 and watch.hits and watch.terminal[watch.hits[-1][1]]:
        return 1, "A termination event occurred.", watch.hits[-1][0]
    if ierr < 0:
        return -1, f"DOP853C: {_MESSAGES.get(ierr, f'error {ierr}')} at t = {t_last:.9g} s", t_last
    return 0, "The solver successfully reached the end of the integration interval.", t_last


def _proposal(steps: _Steps, rtol: float, atol: float, i: int = -1) -> float:
    """[s] The step after accepted step i (−1: the last) by solve_ivp's control: h min(MAX_FACTOR, SAFETY
    err^(−1/8)) with that step's error norm, from its stages (k1 of its block is f(t_new): f(t_old) from the step
    before)."""
    i = len(steps.t) - 2 if i < 0 else i
    h = steps.t[i + 1] - steps.t[i]
    block = steps.blocks[i].copy()
    block[_F_NEW] = steps.f_old(i)  # the row of stage 0 in _ROW_STAGE's layout
    y_old = steps.y_old(i)
    scale = atol + rtol * np.maximum(np.abs(y_old), np.abs(steps.blocks[i][_Y_NEW]))
    e5, e3 = (_ERR_ROWS @ block) / scale
    s5, s3 = float(e5 @ e5), float(e3 @ e3)
    if s5 == 0.0 and s3 == 0.0:
        return h * MAX_FACTOR
    err = abs(h) * s5 / np.sqrt((s5 + 0.01 * s3) * len(y_old))
    return h * (MAX_FACTOR if err == 0.0 else min(MAX_FACTOR, SAFETY * err ** _EXPONENT))
