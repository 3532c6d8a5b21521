"""The ``slip`` event's stage watch (events.SlipWatch): a crossing hidden inside a step is reported,
and located at its first stage; stages of other steps do not count."""

from __future__ import annotations

import numpy as np
import pytest

from contactdyn.hybrid.events import SlipWatch

X = np.zeros(2)


def watch(g_of_t):
    return SlipWatch(lambda t, x: g_of_t(t), "tip", 0.5)


def test_step_ends_alone_give_the_function():
    w = watch(lambda t: 1.0 - t)
    assert w(0.0, X) == 1.0
    for t in (0.1, 0.2, 0.3):
        w.sample(t, 1.0 - t)
    assert w(0.5, X) == 0.5


def test_a_crossing_hidden_inside_a_step_is_reported_from_its_first_stage():
    w = watch(lambda t: 1.0)  # positive at every step end
    w(0.0, X)
    for t, g in ((0.1, 1.0), (0.3, -2.0), (0.2, -1.0), (0.4, 0.5)):  # stages in any order
        w.sample(t, g)
    assert w(0.5, X) == -1.0  # the step end [0, 0.5] reports a crossing
    assert w.latch == 0.2  # held negative from the first negative stage on, while it is located
    assert w(0.1, X) == 1.0 and w(0.2, X) < 0.0 and w(0.45, X) < 0.0


def test_stages_outside_the_step_do_not_count():
    w = watch(lambda t: 1.0)
    w(0.0, X)
    w(0.5, X)
    w.sample(0.2, -1.0)  # a stage before the last step end (a rejected attempt's, or stale)
    w.sample(0.9, -1.0)  # a stage beyond the next step end: kept for the step that holds it
    assert w(0.7, X) == 1.0
    assert w(1.0, X) == -1.0 and w.latch == 0.9


def test_a_negative_step_end_is_returned_as_it_is():
    w = watch(lambda t: -3.0 if t >= 0.5 else 1.0)
    w(0.0, X)
    w.sample(0.2, -1.0)
    assert w(0.5, X) == -3.0  # the end itself crossed: the root finder locates it on the interpolant


def test_a_stick_decided_inside_the_cones_slack_slips_as_its_load_grows():
    """A stick decided at the cone's edge with g = μ_s F − |F_f| = −2e-12 N (inside in_cone's round-off slack) and a
    load growing at 1 N/s: g never crosses zero from above, so without its floor the watch would never fire and the
    contact would stay stuck outside the cone (tests/test_pinch.py saw 0.44 N on an AMD EPYC). With the floor g(t0)
    the event is g − g(t0) through zero: it fires at the first step end and is located at the segment's start."""
    from contactdyn.model.friction import in_cone
    from contactdyn.numerics.dop853 import solve

    g0, mu, F = -2e-12, 0.5, 1.0
    assert in_cone(np.array([mu * F - g0]), F, mu)  # the stick the transitions decided
    w = SlipWatch(lambda t, x: g0 - t, "tip", mu, floor=min(g0, 0.0))
    sol = solve(lambda t, x: np.zeros(1), (0.0, 1.0), np.zeros(1), rtol=1e-9, atol=1e-12, events=[w])
    assert sol.status == 1 and sol.t_events[0][0] == pytest.approx(0.0, abs=1e-12)
    unfloored = SlipWatch(lambda t, x: g0 - t, "tip", mu)
    sol = solve(lambda t, x: np.zeros(1), (0.0, 1.0), np.zeros(1), rtol=1e-9, atol=1e-12, events=[unfloored])
    assert sol.status == 0 and len(sol.t_events[0]) == 0  # the gap the floor closes


def test_a_slide_from_rest_sticks_again_only_strictly_inside_the_cone():
    """in_cone's hysteresis: at the edge (|F_f| = μ_s F within the slack) a stick holds (the lenient test) but a slide
    from rest is not stuck again (the strict one), so the two decisions cannot chatter at one instant."""
    from contactdyn.model.friction import CONE_TOL, in_cone

    mu, F = 0.7, 0.315
    edge = np.array([mu * F * (1.0 + 0.5 * CONE_TOL)])
    assert in_cone(edge, F, mu) and not in_cone(edge, F, mu, strictly=True)
    inside = np.array([mu * F * (1.0 - 3.0 * CONE_TOL)])
    assert in_cone(inside, F, mu, strictly=True)
