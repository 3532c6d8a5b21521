"""A long run says how far it is, and no run works without bound.

:class:`~contactdyn.hybrid.events.WorkWatch` is a terminal event of every integration segment (a
step-counting event of :mod:`contactdyn.hybrid.events`): it fires when the run's integration steps
exceed its budget (:func:`~contactdyn.scene.budget.step_budget`; a stiff or mis-set scene, such
as ``solver.stabilization = 1e9``, stops there with a message naming the cause instead of
running for hours); :class:`Work` bounds the right-hand-side calls the same way
(CALLS_PER_STEP per budgeted step: rejected attempts count too), and, when a
:class:`Progress` is attached (``contactdyn run``), it reports the simulated time: after
SHOW_AFTER seconds of wall time, a bar on a terminal redrawn every REDRAW seconds, else a line
every LINE_EVERY seconds.
"""

from __future__ import annotations

import math
import sys
import time

from ..numerics.dop853 import INTERPOLANT_STAGES

__all__ = ["CALLS_PER_STEP", "Progress", "Work", "OverBudget"]

STEP_STAGES = 12  #: right-hand-side calls of one compiled DOP853 step (its stages)
SHOW_AFTER = 2.0  #: [s] of wall time before progress is shown
REDRAW = 0.5  #: [s] between redraws of the bar on a terminal
LINE_EVERY = 10.0  #: [s] between progress lines when stderr is not a terminal
#: right-hand-side calls a step may take on average (DOP853: 12 per attempt): rejected attempts count too, so a
#: run whose steps keep failing is bounded as well
CALLS_PER_STEP = 24


class Progress:
    """Simulated time t of T [s], shown on stderr once a run has taken SHOW_AFTER seconds."""

    def __init__(self, name: str, duration: float, stream=None):
        #: control characters (terminal escape codes in a scene's file name) shown as escapes, not obeyed
        self.name = "".join(c if c.isprintable() else repr(c)[1:-1] for c in name)
        self.duration = duration  #: [s]
        self.stream = stream or sys.stderr
        self.start = time.monotonic()
        self.next = self.start + SHOW_AFTER
        self.tty = bool(getattr(self.stream, "isatty", lambda: False)())
        self.shown = False

    def __call__(self, t: float) -> None:
        now = time.monotonic()
        if now < self.next:
            return
        self.next = now + (REDRAW if self.tty else LINE_EVERY)
        share = min(max(t / self.duration, 0.0), 1.0) if self.duration > 0 else 1.0
        text = f"{self.name}: t = {t:.6g} / {self.duration:g} s ({100 * share:.0f} %, {now - self.start:.0f} s)"
        if self.tty:
            bar = "#" * int(30 * share)
            self.stream.write(f"\r{text} [{bar:<30}]")
        else:
            self.stream.write(text + "\n")
        self.stream.flush()
        self.shown = True

    def done(self) -> None:
        if self.shown and self.tty:
            self.stream.write("\n")
            self.stream.flush()


class OverBudget(Exception):
    """The run's right-hand-side calls reached their budget (raised from inside the integration)."""


class Work:
    """Counts a run's right-hand-side calls (a compiled step as 12) and raises OverBudget past ``limit``."""

    def __init__(self, limit: float):
        self.limit, self.calls = limit, 0
        self.last: tuple[float, object] | None = None  #: (t [s], state) of the call that spent the budget

    def count(self, n: int, t: float = math.nan, y=None) -> None:
        self.calls += n
        if self.calls > self.limit:
            self._spent(t, y)

    def _spent(self, t: float, y) -> None:
        self.limit = math.inf  # spent: what reports it (and samples the run) is not counted again
        self.last = (t, y) if y is not None else None
        raise OverBudget

    def wrap(self, fun):
        """``fun`` counted; its compiled ``step`` (contactdyn.hybrid.steps), if any, counted as its STEP_STAGES
        calls, its ``derivatives`` (a batch of calls) as one call per state, its ``interpolant`` as
        INTERPOLANT_STAGES."""
        def counted(t, y):
            self.calls += 1  # (count() inline: this wraps every right-hand-side call)
            if self.calls > self.limit:
                self._spent(t, y)
            return fun(t, y)

        step = getattr(fun, "step", None)
        if step is not None:
            def counted_step(t, y, *args):  # (the step's start: where a spent budget says it stopped)
                self.count(STEP_STAGES, t, y)
                return step(t, y, *args)

            counted.step = counted_step
        derivatives = getattr(fun, "derivatives", None)
        if derivatives is not None:  # (a batch of calls: the dense output's extra stages)
            def counted_derivatives(ts, Y):
                self.count(len(ts))
                return derivatives(ts, Y)

            counted.derivatives = counted_derivatives
        one = getattr(fun, "interpolant", None)
        if one is not None:  # (a step's interpolant: its three extra stages)
            def counted_interpolant(*args):
                F = one(*args)
                if F is not None:  # (declined: the calls that build it instead are counted)
                    self.count(INTERPOLANT_STAGES)
                return F

            counted.interpolant = counted_interpolant
        return counted
