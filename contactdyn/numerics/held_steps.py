"""Sample instants as step boundaries of the compiled DOP853: a held command's jumps inside one integration.

A sampled controller (:mod:`contactdyn.laws.controllers.sampled`) holds its command in the state and changes it
only at the sample instants t_k [s]. Ending a segment at every t_k costs a new segment each time (the hybrid
loop's set-up, a first-step estimate, no FSAL). Here one run of :func:`contactdyn.numerics.dop853.solve`'s steps
(scipy's core or a compiled mode's steps) carries the hold (``hold``: ``next_time() -> t_k`` [s], inf: none
left in the run; ``take(t, y) -> y_new``, the state with the new held command; ``event_value(event)``: the
function whose fall through zero across a jump fires that event, None where the jump cannot fire it):

- a step is clipped to land exactly on t_k (each sample interval is one *piece* of steps);
- there the hold jumps the state, f is evaluated again at (t_k, y_new) (the FSAL value is stale) and the step
  size goes on with the proposal of the step that landed on t_k (the segment version's first step too);
- an event whose function falls through zero across the jump (``g(t_k, y) > 0 ≥ g(t_k, y_new)``, what
  :func:`~contactdyn.hybrid.events.fired_across` tests between segments) is a terminal event located at t_k:
  the run stops there with the state after the jump;
- the dense output is the pieces' own interpolants, never one across a jump; at exactly t_k it gives the state
  after the jump (the segment version's next segment starts there: the output sampler reads it).
"""

from __future__ import annotations

from bisect import bisect_right
from collections.abc import Callable, Sequence

import numpy as np

from .dop853 import (
    _Y_NEW,
    DenseSolution,
    Solution,
    _Core,
    _EventWatch,
    _first_step,
    _proposal,
    _stepped,
    _Steps,
    core_steps,
    dense_states,
    solution_status,
)

__all__ = ["solve", "PiecewiseDense"]


class PiecewiseDense:
    """y(t) over the pieces between jumps (like :class:`~contactdyn.numerics.dop853.DenseSolution`): each piece's
    own interpolants; a piece's start belongs to it (at a jump: the state after it)."""

    def __init__(self, pieces: list[_Steps], t_end: float):
        self.parts = [DenseSolution(p, p.t[-1]) for p in pieces[:-1]] + [DenseSolution(pieces[-1], t_end)]
        self.start_list = [p.t[0] for p in pieces]  #: [s] where each piece starts (bisect's, for one time)
        self.starts = np.array(self.start_list)  #: the same, as an array (searchsorted's, for many)
        self.t_min, self.t_max = pieces[0].t[0], t_end

    @property
    def late_calls(self) -> int:
        """Right-hand-side calls made for interpolants after the run returned (output sampling)."""
        return sum(part.late_calls for part in self.parts)

    def __call__(self, t, derivatives: Callable | None = None) -> np.ndarray:
        """The state at t [s] (shape (n,)) or at each time of an array (shape (n, len(t)))."""
        if np.ndim(t) == 0:
            piece = min(max(bisect_right(self.start_list, float(t)) - 1, 0), len(self.parts) - 1)  # (part_of's)
            return self.parts[piece].state(float(t), derivatives)
        tt = np.atleast_1d(np.asarray(t, float))
        out = np.empty((len(tt), len(self.parts[0].steps.y0)))
        split = self.split(tt)
        for (_, at), y in zip(split, dense_states([(part, tt[at]) for part, at in split], derivatives), strict=True):
            out[at] = y
        return out.T

    def part_of(self, tt: np.ndarray) -> np.ndarray:
        """The piece of each time tt [s] (a piece's start belongs to it)."""
        return np.clip(np.searchsorted(self.starts, tt, side="right") - 1, 0, len(self.parts) - 1)

    def split(self, tt: np.ndarray) -> list[tuple[DenseSolution, np.ndarray]]:
        """(piece, the positions in tt of its times) per piece that has times tt [s], in piece order."""
        idx = self.part_of(tt)
        if not len(idx):
            return []
        order = np.argsort(idx, kind="stable")  # (per piece, its times' positions in increasing order)
        firsts = np.flatnonzero(np.diff(idx[order])) + 1
        return [(self.parts[int(idx[at[0]])], at) for at in np.split(order, firsts)]


def _jump(watch: _EventWatch, t: float, before: np.ndarray, after: np.ndarray, value_of: Callable) -> bool:
    """The events fired by the jump from ``before`` to ``after`` at t [s] (their functions fall through zero,
    :func:`~contactdyn.hybrid.events.fired_across`'s test) recorded at t; True if one is terminal. The watch goes on
    from the values after the jump."""
    fired = False
    for i, event in enumerate(watch.events):
        g = value_of(event)
        if g is None:
            continue
        g_after = float(g(t, after))
        if g(t, before) > 0.0 >= g_after:
            watch.hits.append((t, i))
            fired = fired or watch.terminal[i]
        watch.g[i] = g_after
    if fired:
        watch.hits.sort()
        first = next(k for k, (_, i) in enumerate(watch.hits) if watch.terminal[i])
        del watch.hits[first + 1:]
    return fired


def solve(fun: Callable[[float, np.ndarray], np.ndarray], t_span: tuple[float, float], y0: np.ndarray, *,
          rtol: float, atol: float, hold, max_step: float = np.inf, first_step: float | None = None,
          events: Sequence[Callable] | None = None, step: Callable | None = None) -> Solution:
    """:func:`contactdyn.numerics.dop853.solve` with the hold's sample instants as step boundaries (the module
    docstring): the same arguments and result; ``sol.sol`` is a :class:`PiecewiseDense`."""
    t0, t_end = float(t_span[0]), float(t_span[1])
    y = np.array(y0, float)
    f = np.asarray(fun(t0, y), float)
    watch = _EventWatch(events or [], t0, y)
    calls = [1]

    def counted(t, x):
        calls[0] += 1
        return fun(t, x)

    h = _first_step(counted, t0, y, f, min(t_end, hold.next_time()), max_step, rtol, atol, first_step)
    compiled = step is not None
    core = None if compiled else _Core(fun, t0, y, f, watch, rtol, atol, max_step)
    pieces: list[_Steps] = []
    t, nreject, after = t0, 0, None
    while True:
        t_k = hold.next_time()
        stop = t_k if t_k < t_end else t_end
        piece = _Steps(fun, len(y), [t], y, f)
        pieces.append(piece)
        if compiled:
            ierr, rejected, calls[0] = _stepped(step, fun, piece, watch, stop, h, rtol, atol, max_step, calls[0])
        else:
            core.steps = piece
            ierr, rejected = core_steps(core, stop, h)
        nreject += rejected
        if ierr != 1 or stop >= t_end or len(piece.t) < 2:
            break
        piece.t[-1] = t = stop  # (the core's last step ends within rounding of it)
        before = piece.end_x if piece.end_x is not None else piece.blocks[-1][_Y_NEW]
        h = _carried(piece, h, rtol, atol)
        y = np.asarray(hold.take(t, before), float)
        f = np.asarray(fun(t, y), float)  # the FSAL value was before the jump
        calls[0] += 1
        if watch.events and _jump(watch, t, before, y, hold.event_value):
            ierr, after = 2, y
            break
    return _solution(pieces, watch, ierr, t_end, after, calls[0] + (core.calls if core else 0), nreject, rtol, atol)


def _carried(piece: _Steps, h_start: float, rtol: float, atol: float) -> float:
    """[s] The step to go on with after a piece that ended at a sample instant: its last step was clipped to land
    there, so where that step's own error lets the step grow, the proposal it was clipped from (made after the step
    before, or the piece's first step ``h_start`` [s]), if larger; else the clipped step's own proposal."""
    h_last, last = piece.t[-1] - piece.t[-2], len(piece.t) - 2

    def proposal(i: int) -> float:  # (the compiled steps' own, else from the stages)
        return piece.proposals[i] if len(piece.proposals) > last else _proposal(piece, rtol, atol, i)

    own = proposal(last)
    if own < h_last:  # the clipped step's error already asks for a shorter one
        return own
    return max(own, h_start if last == 0 else proposal(last - 1))


def _solution(pieces: list[_Steps], watch: _EventWatch, ierr: int, t_end: float, after: np.ndarray | None,
              calls: int, nreject: int, rtol: float, atol: float) -> Solution:
    """The Solution of the pieces (``after``: the state after the jump that fired an event, where the run stopped)."""
    last = pieces[-1]
    if ierr == 1:
        last.t[-1] = t_end
    status, message, t_stop = solution_status(ierr, watch, last.t[-1])
    dense = PiecewiseDense(pieces, t_stop)
    ts = np.array([pieces[0].t[0]] + [t for p in pieces for t in p.t[1:]])
    ys = np.column_stack([pieces[0].y0] + [b[_Y_NEW] for p in pieces for b in p.blocks])
    if status == 1:
        ts[-1] = t_stop
        ys[:, -1] = after if after is not None else dense(t_stop)
    h_next = _proposal(last, rtol, atol) if status == 0 and len(last.t) > 1 else None
    return Solution(ts, ys, dense, watch.t_events(), status, message, calls + sum(p.calls for p in pieces),
                    len(ts) - 1, nreject, h_next)
