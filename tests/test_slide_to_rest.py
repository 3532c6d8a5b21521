"""A 2-D slide coming to rest: DOP853's steps collapse, the rest of the mode runs on LSODA (contactdyn.hybrid.loop)."""

import math

import numpy as np
import pytest

from contactdyn import simulate
from contactdyn.hybrid import loop as hybrid
from contactdyn.hybrid.events import StepCollapse
from contactdyn.numerics.integrators import integrate


def test_step_collapse_fires_at_the_end_of_the_counted_short_step():
    """+1 until the end of the 3rd step shorter than ¼ of the longest so far, −1 from there on; values asked
    inside a step (root location) neither count nor move it."""
    watch = StepCollapse(0.25, 3)
    ends = [0.0, 1.0, 2.0, 2.2, 2.3, 2.8, 2.9, 3.0]  # steps 1, 1, 0.2, 0.1, 0.5, 0.1, 0.1
    values = []
    for t in ends:
        values.append(watch(t, np.zeros(1)))
        assert watch(t - 0.01, np.zeros(1)) == (1.0 if t - 0.01 < 2.9 else -1.0)  # inside the step: no count
    assert values == [1.0] * 6 + [-1.0, -1.0]
    assert watch.t_fire == 2.9 and math.isinf(StepCollapse(0.25, 3).t_fire)


def test_the_writers_slide_to_rest_finishes_on_lsoda_with_dop853s_result(monkeypatch):
    """The 5-DOF writer's circle ends at 4.5 s and the pencil's slide comes to rest (|v_t| falls to the stick band
    at 4.49996 s): its direction relaxes at a rate ∝ 1/|v_t| and DOP853's steps collapse. After COLLAPSE_STEPS
    short steps the stiffness check sends the rest of that mode to LSODA at RESTING_TOL × the tolerances: fewer
    calls (6–19 % fewer measured: the size moves with the runs' last bits), the same events, and the run equals
    DOP853's alone within its own error against the rtol 1e-11 reference (6e-6 N, 3.4e-10 m; benchmarks/scenes.py):
    up to 1e-7 N, 2e-10 m, 6.3e-10 rad measured."""
    switched = simulate("case2_writer5dof")
    monkeypatch.setattr(hybrid, "COLLAPSE_STEPS", 10**9)  # no collapse is ever seen: DOP853 to the end
    explicit = simulate("case2_writer5dof")
    assert switched.stats["resting_switches"] == 1 and "resting_switches" not in explicit.stats
    assert switched.stats["segments_by_method"]["LSODA"] == explicit.stats["segments_by_method"]["LSODA"] + 1
    # measured 21311 against 23873; the ratio moves with the last bit of the start: 0.81-0.89 over 1-ulp changes of
    # robot.tip0 on the code before the transitions read the compiled call, 0.81-0.89 after (a fifth to a tenth
    # saved). On another machine (another CPU: the last bits differ) the same code measured 21320 against 22706: 0.94.
    # What holds on both is that the switch saves calls; how many is a benchmark's figure, not this test's.
    assert switched.stats["rhs_evals"] < explicit.stats["rhs_evals"]
    kinds = [(e["kind"], e["name"]) for e in explicit.events]
    assert _slide_ends_as_one(switched.events) == _slide_ends_as_one(explicit.events)
    assert ("stick", "pencil") == kinds[-2] and kinds[-3] in (("stop", "pencil"), ("turn", "pencil"))
    # The bounds: ~3x the largest difference measured over 1-ulp changes of robot.tip0 (the runs' last bits decide
    # where the slow stop crossing lands: |v_t| = 1e-9 m/s, ~1e-10 m/s per 3e-8 s): the stop 2.3e-8 to 1.6e-7 s
    # apart, F_n 6.5e-9 to 1e-7 N, the tip 1.2e-11 to 2e-10 m, q 3.8e-11 to 6.3e-10 rad
    for a, b in zip(switched.events, explicit.events, strict=True):
        assert a["t"] == pytest.approx(b["t"], abs=5e-7)
    for key, tol in (("contact.pencil.F_n", 3e-7), ("tip", 5e-10), ("q", 2e-9)):
        assert float(np.abs(switched[key] - explicit[key]).max()) < tol


def _slide_ends_as_one(events: list[dict]) -> list[tuple[str, str]]:
    """The events' (kind, name) with the slide's end written one way: as |v_t| falls to ~2 v_ε its stop
    (v·r = v_ε) and turn (v·r = ½|v| − v_ε) functions cross zero within rounding of each other, and either ends
    the slide into a stick at that same instant (seen: which one fires moves with the last bits of the state); a
    turn not followed by a stick at its own time stays a turn."""
    out = [(e["kind"], e["name"]) for e in events]
    for k in range(len(out) - 1):
        if out[k][0] == "turn" and out[k + 1][0] == "stick" and events[k + 1]["t"] == events[k]["t"]:
            out[k] = ("stop", out[k][1])
    return out


def test_where_lsoda_fails_to_finish_the_slide_the_scene_method_does_it_once_for_the_mode(monkeypatch):
    """LSODA made to fail whenever it finishes a slide: the segment is redone by the scene's method and the rest of
    the mode stays on it (no second switch, no second try), the run ends with the same events as DOP853's alone;
    the launches' LSODA segments never run at the finishing tolerance."""
    rtol = 1e-7  # the scene's
    tries = []

    def failing_to_finish(fun, span, y0, method, **kw):
        if method == "LSODA":
            tries.append(kw["rtol"])
        if method == "LSODA" and kw["rtol"] < rtol:  # finishing a slide (RESTING_TOL × the scene's)
            sol = integrate(fun, (span[0], span[0] + 1e-4), y0, method, **{**kw, "events": None})
            sol.status, sol.message = -1, "made to fail"
            return sol
        return integrate(fun, span, y0, method, **kw)

    monkeypatch.setattr(hybrid, "integrate", failing_to_finish)
    got = simulate("case2_writer5dof")
    assert got.stats["resting_switches"] == 1
    assert tries.count(hybrid.RESTING_TOL * rtol) == 1 and tries.count(rtol) == 2  # one finish tried; the launches
    monkeypatch.setattr(hybrid, "COLLAPSE_STEPS", 10**9)
    explicit = simulate("case2_writer5dof")
    assert _slide_ends_as_one(got.events) == _slide_ends_as_one(explicit.events)
