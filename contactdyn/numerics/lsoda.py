"""LSODA stepped by scipy's compiled core directly, with dense output and located events.

``solve_ivp``'s LSODA takes each step through ``OdeSolver``'s Python machinery: ~60–100 µs per step
beside the right-hand side (a step object, a dense output built and kept per step, the events'
bookkeeping), where the core's own step costs a few µs. Here the core is called as ``solve_ivp``
calls it (scipy's ``ode`` integrator ``lsoda``, one step per call: ``itask = 5``, never past t_end;
the same tolerances, first and largest step, finite-difference Jacobian), so the accepted steps and
states are ``solve_ivp``'s; per step only the Nordsieck history is kept, and a step's interpolant is
built when something asks for it (an event's sign change in that step, output samples).

Events follow ``solve_ivp``'s contract (values at t0 and at every step end; a sign change in the
event's direction located by ``brentq``, xtol = rtol = 4 ε; the earliest terminal root ends the run
there), with one difference: the bracket's ends take the values at the steps' own states. LSODA's
interpolant does not pass exactly through the step's start, so a crossing within that interpolation
error would have no sign change on it (a 2-D slide's stop at v_t·r = 1e-9 m/s at rtol 1e-11: "f(a)
and f(b) must have different signs" in ``solve_ivp``). Verified against ``solve_ivp``'s LSODA in
``tests/test_lsoda.py``.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np
from scipy.integrate import _ode
from scipy.integrate._ivp.lsoda import LsodaDenseOutput

from .dop853 import Solution, _EventWatch

__all__ = ["solve", "available"]

_ONE_STEP = 5  #: the core's itask: one step, not past rwork[0] = t_end (solve_ivp's)
#: a run is ended after this many steps in a row that do not advance t: where the derivatives overflow, scipy 1.17's
#: core accepts steps of length 0 for ever (y' = y² past its blow-up hangs solve_ivp's LSODA); a step shorter than
#: t's resolution is otherwise rare (a handful in a row where its steps collapse)
_STALLED_STEPS = 1000


def available() -> bool:
    """Is scipy's compiled LSODA reachable the way this module calls it (scipy 1.17's ``_ode.lsoda``)?"""
    integ = getattr(_ode, "lsoda", None)
    return integ is not None and hasattr(integ, "runner") and "state_doubles" in vars(integ())


class _Steps:
    """Accepted steps of one run: ends and the Nordsieck histories; interpolants built on demand."""

    def __init__(self, t0: float, y0: np.ndarray):
        self.t = [t0]  #: step ends [s], t[0] = t0
        self.ys = [y0]  #: the states there
        #: per step: (h [s], order, the core's Nordsieck history flat, the order falls next, the step taken [s])
        self.history: list[tuple[float, int, np.ndarray, bool, float]] = []
        self.dense: dict[int, LsodaDenseOutput] = {}

    def add(self, t: float, y: np.ndarray, rwork: np.ndarray, iwork: np.ndarray) -> None:
        """Keep the step ending at (t, y) with the core's history as it stands (its columns laid out when an
        interpolant asks for them, :meth:`history_of`: most steps' never are)."""
        order = int(iwork[13])  # the order of the step just taken
        self.t.append(t)
        self.ys.append(y)
        self.history.append((float(rwork[11]), order, rwork[20:20 + (order + 1) * len(y)].copy(),
                             int(iwork[14]) < order, float(rwork[10])))

    def history_of(self, i: int) -> tuple[float, int, np.ndarray]:
        """Step i's (h [s], order, yh), read off the core's work arrays as ``solve_ivp``'s dense output does: h the
        next step's size (the history's scale); where the order falls next, the last column (not updated) rescaled
        to h."""
        h, order, flat, falls, h_used = self.history[i]
        yh = np.reshape(flat, (len(self.ys[0]), order + 1), order="F").copy()
        if falls:
            yh[:, -1] *= (h / h_used) ** order
        return h, order, yh

    def interpolant(self, i: int) -> LsodaDenseOutput:
        got = self.dense.get(i)
        if got is None:
            got = self.dense[i] = LsodaDenseOutput(self.t[i], self.t[i + 1], *self.history_of(i))
        return got

    def at(self, i: int, t: float) -> np.ndarray:
        """The state at t [s] on step i's interpolant (its ends: the step's own states; a step shorter than t's
        resolution: its end's)."""
        if t == self.t[i + 1]:
            return self.ys[i + 1]
        if t == self.t[i]:
            return self.ys[i]
        return self.interpolant(i)(t)


class LsodaSolution:
    """y(t) on [t0, t_end] from the steps' interpolants (as ``OdeSolution`` for LSODA: at a step end, the next
    step's)."""

    def __init__(self, steps: _Steps, t_end: float):
        self.steps, self.t_min, self.t_max = steps, steps.t[0], t_end
        self.ends = np.array(steps.t[1:-1])

    def __call__(self, t) -> np.ndarray:
        tt = np.atleast_1d(np.asarray(t, float))
        st = self.steps
        if not st.history:
            out = np.repeat(st.ys[0][:, None], len(tt), axis=1)
            return out[:, 0] if np.ndim(t) == 0 else out
        idx = np.searchsorted(self.ends, tt, side="right")
        out = np.empty((len(st.ys[0]), len(tt)))
        for i in np.unique(idx):
            sel = idx == i
            out[:, sel] = st.interpolant(int(i))(tt[sel]).reshape(len(st.ys[0]), -1)
        return out[:, 0] if np.ndim(t) == 0 else out


def solve(fun: Callable[[float, np.ndarray], np.ndarray], t_span: tuple[float, float], y0: np.ndarray, *,
          rtol: float, atol: float, max_step: float = np.inf, first_step: float | None = None,
          events: Sequence[Callable] | None = None) -> Solution:
    """Integrate y' = fun(t, y) over t_span by compiled LSODA, locating the events (``solve_ivp``'s contract).

    ``atol`` and ``rtol`` are scalars; ``max_step`` [s] (inf: none) and ``first_step`` [s] (None: the core's
    own estimate) as in ``solve_ivp``. Events are terminal if their ``terminal`` attribute is."""
    t0, t_end = float(t_span[0]), float(t_span[1])
    y = np.array(y0, float)
    calls = [0]

    def counted(t, x):
        calls[0] += 1
        return fun(t, x)

    integ = _ode.lsoda(rtol=rtol, atol=atol, max_step=0.0 if max_step == np.inf else max_step,
                       first_step=first_step or 0.0)
    integ.reset(len(y), False)
    integ.rwork[0] = t_end
    integ.call_args[2] = _ONE_STEP
    steps, watch = _Steps(t0, y.copy()), _EventWatch(events or [], t0, y)
    t, status, message = t0, 0, "The solver successfully reached the end of the integration interval."
    work = y.copy()  # the core's state array, which it updates in place
    stalled = 0  # steps in a row that did not advance t
    while t < t_end:
        t_old = t
        work, t = integ.run(counted, None, work, t, t_end, (), ())
        stalled = stalled + 1 if t == t_old else 0
        if stalled >= _STALLED_STEPS:
            status, message = -1, (f"LSODA (compiled): {_STALLED_STEPS} steps in a row did not advance t = {t:.9g} s "
                                   "(derivatives that overflow there?)")
            break
        if not integ.success:
            why = integ.messages.get(integ.istate, f"istate {integ.istate}")
            status, message = -1, f"LSODA (compiled): {why} at t = {t:.9g} s"
            break
        if not np.isfinite(work).all():  # the core accepts a step from a nan derivative and carries it on
            status, message = -1, f"LSODA (compiled): the state is not finite at t = {t:.9g} s"
            break
        y = work.copy()
        steps.add(t, y, integ.rwork, integ.iwork)
        if watch.events and watch.stop(steps, t, y):
            status, message = 1, "A termination event occurred."
            break
    return _solution(steps, watch, status, message, calls[0])


def _solution(steps: _Steps, watch: _EventWatch, status: int, message: str, calls: int) -> Solution:
    t_stop = watch.hits[-1][0] if status == 1 else steps.t[-1]
    dense = LsodaSolution(steps, t_stop)
    ts, ys = np.array(steps.t), np.column_stack(steps.ys)
    if status == 1:
        ts[-1] = t_stop
        ys[:, -1] = steps.at(len(steps.history) - 1, t_stop)
    return Solution(ts, ys, dense, watch.t_events(), status, message, calls, len(steps.history), 0)
