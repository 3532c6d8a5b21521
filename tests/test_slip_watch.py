"""The ``slip`` event's stage watch (events.SlipWatch): a crossing hidden inside a step is reported,
and located at its first stage; stages of other steps do not count."""

from __future__ import annotations

import numpy as np

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
