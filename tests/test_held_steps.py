"""Sample instants as step boundaries of the compiled DOP853 (contactdyn.numerics.held_steps).

The system y' = u, u' = 0 with a hold u := −c y at t_k = k T: between samples y is linear in t (DOP853 exact to
rounding), so y(t_k) = y0 (1 − c T)^k in closed form.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from contactdyn.numerics import dop853, held_steps

T = 0.1  #: [s] the sample period


class _Hold:
    """u := −c y at k T (k ≥ 1) before ``last`` [s]; the event functions it names can be fired by the jump."""

    def __init__(self, c: float = 1.0, last: float = math.inf, jumping=()):
        self.c, self.k, self.last, self.jumping, self.taken = c, 1, last, jumping, []

    def next_time(self) -> float:
        t = self.k * T
        return t if t < self.last else math.inf

    def take(self, t: float, y: np.ndarray) -> np.ndarray:
        self.taken.append(t)
        self.k += 1
        return np.array([y[0], -self.c * y[0]])

    def event_value(self, event):
        return event if event in self.jumping else None


def _f(t, y):
    return np.array([y[1], 0.0])


def _solve(hold, t_end=1.0, events=None):
    return held_steps.solve(_f, (0.0, t_end), np.array([1.0, -1.0]), rtol=1e-10, atol=1e-12, hold=hold,
                            events=events)


def test_the_steps_land_on_the_samples_and_the_state_is_the_closed_form_there():
    hold = _Hold(c=1.0, last=1.0)
    sol = _solve(hold)
    assert sol.status == 0 and sol.t[-1] == 1.0
    np.testing.assert_allclose(hold.taken, T * np.arange(1, 10), rtol=0, atol=0)
    for k in range(1, 10):
        assert np.any(sol.t == k * T)  # a step ends exactly there
        before, after = sol.sol(k * T - 1e-12), sol.sol(k * T)
        y_k = (1.0 - T) ** k
        np.testing.assert_allclose(after, [y_k, -y_k], rtol=1e-12)  # at t_k: the state after the jump
        np.testing.assert_allclose(before[1], -((1.0 - T) ** (k - 1)), rtol=1e-12)  # just before: the old hold
    np.testing.assert_allclose(sol.y[0, -1], (1.0 - T) ** 10, rtol=1e-12)


def test_equals_segments_ending_at_each_sample():
    held = _solve(_Hold(c=3.0, last=1.0))
    y, t, h = np.array([1.0, -1.0]), 0.0, None
    for k in range(1, 11):
        seg = dop853.solve(_f, (t, k * T), y, rtol=1e-10, atol=1e-12, first_step=h)
        t, y, h = k * T, seg.y[:, -1].copy(), seg.h_next
        if k < 10:
            y[1] = -3.0 * y[0]
    np.testing.assert_allclose(held.y[:, -1], y, rtol=1e-12)
    grid = np.linspace(0.0, 1.0, 41)
    assert np.all(np.isfinite(held.sol(grid)))


def test_the_dense_output_at_many_times_in_any_order_is_each_times_own():
    """Many times at once (the output's way: each piece's interpolants in one batch), shuffled, jumps included:
    bit for bit the state at each time alone (the piece a jump starts owns its instant: the state after it)."""
    sol = _solve(_Hold(c=3.0, last=1.0))
    tt = np.concatenate([np.linspace(0.0, 1.0, 57), T * np.arange(1, 10)])
    np.random.default_rng(7).shuffle(tt)
    together = sol.sol(tt)
    alone = np.column_stack([sol.sol(float(t)) for t in tt])
    np.testing.assert_array_equal(together, alone)
    assert sol.sol(np.empty(0)).shape == (2, 0)


def test_the_jump_consults_only_the_events_the_hold_names():
    def watch(t, y):  # a step watch: called at the start and at each step end, never at a jump
        watch.calls += 1
        return 1.0

    watch.calls, watch.terminal, watch.direction = 0, True, -1
    sol = _solve(_Hold(c=1.0, last=1.0), events=[watch])
    assert sol.status == 0 and watch.calls == len(sol.t)


@pytest.mark.parametrize("c, fires_at", [(1.5, 1), (1.0, None)])
def test_a_jump_through_zero_stops_the_run_at_the_sample(c, fires_at):
    def g(t, y):  # u + 1.2 > 0 from the start (u0 = −1): falls through zero where the hold makes u ≤ −1.2
        return y[1] + 1.2

    g.terminal, g.direction = True, -1
    hold = _Hold(c=c, jumping=(g,))
    sol = _solve(hold, events=[g])
    if fires_at is None:  # u = −(1 − T)^(k−1) > −1.2 at every sample: no event
        assert sol.status == 0 and len(sol.t_events[0]) == 0
        return
    t_k = fires_at * T  # y_1 = 1 − T = 0.9, u := −1.35: g = −0.15
    assert sol.status == 1 and sol.t[-1] == t_k
    np.testing.assert_array_equal(sol.t_events[0], [t_k])
    np.testing.assert_allclose(sol.y[:, -1], [0.9, -1.35], rtol=1e-12)  # the state after the jump
    assert hold.taken == [t_k]


def test_a_piece_carries_on_with_the_compiled_steps_own_proposals(monkeypatch):
    """B1 sampled at 1 kHz: at every sample the held steps go on with the proposals the compiled steps recorded
    (``_Steps.proposals``), one per accepted step; each is the step solve_ivp's control proposes from that step's
    stages (``dop853._proposal``), to its error norm's rounding: a norm cancelling to ~1e-7 gives 1e-3 relative, one
    cancelling to ~1e-8 more (``_proposal``'s NumPy products round by the arrays' place in memory: after
    test_compiled_steps.py in one process, 0.00826 s against the cap of 0.01 s, norms of 2e-8 and below 4e-9; the run
    itself is the same bit for bit), so the norms the proposals stand for agree to 1e-6 (of the tolerance's 1)."""
    from contactdyn import simulate

    checked, carried = [], held_steps._carried

    def norm(proposal: float, h: float) -> float:  # the error norm a step h's proposal stands for (at most, at the cap)
        return (dop853.SAFETY * h / proposal) ** (-1.0 / dop853._EXPONENT)

    def check(piece, h_start, rtol, atol):
        assert len(piece.proposals) == len(piece.t) - 1
        for i, got in enumerate(piece.proposals):
            want, h = dop853._proposal(piece, rtol, atol, i), piece.t[i + 1] - piece.t[i]
            assert got == pytest.approx(want, rel=1e-3) or abs(norm(got, h) - norm(want, h)) <= 1e-6
        checked.append(len(piece.proposals))
        return carried(piece, h_start, rtol, atol)

    monkeypatch.setattr(held_steps, "_carried", check)
    simulate("b1", {"controller.sample_rate": 1000.0, "duration": 0.05})
    assert len(checked) >= 49  # (a sample per ms from the first on)
