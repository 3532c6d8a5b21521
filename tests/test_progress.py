"""No run works without bound, and a long one says how far it is (contactdyn.hybrid.progress)."""

from __future__ import annotations

import io

import numpy as np
import pytest

import contactdyn.hybrid.events
import contactdyn.hybrid.loop
import contactdyn.hybrid.progress as progress
import contactdyn.scene.budget as budget
from contactdyn import SimulationError, simulate


def test_a_run_over_its_step_budget_stops_with_the_cause(monkeypatch):
    """B1 takes ~240 steps over 2 s; with a budget of 50 steps per simulated second (and no base) it stops at
    the 100th step, saying where, the budget and the fastest mode."""
    monkeypatch.setattr(contactdyn.hybrid.loop, "step_budget", lambda solver, duration, rate=0.0: 100)
    with pytest.raises(SimulationError) as info:
        simulate("b1", {"solver.steps_per_second": 50.0})
    text = str(info.value)
    assert "after 100 integration steps, its budget" in text and "fastest mode |λ|" in text
    assert "solver.steps_per_second" in text and "per sample" not in text
    with pytest.raises(SimulationError, match="per simulated second \\+ 2 per sample of its 1000 Hz law"):
        simulate("b1", {"solver.steps_per_second": 50.0, "controller.sample_rate": 1000.0})


def test_steps_that_keep_failing_are_bounded_by_the_calls(monkeypatch):
    """The same budget counted in right-hand-side calls (rejected attempts too): B1 needs ~4200 calls; with a
    budget of 50 steps (1200 calls) it stops inside the integration, naming the calls."""
    monkeypatch.setattr(contactdyn.hybrid.loop, "step_budget", lambda solver, duration, rate=0.0: 50)
    monkeypatch.setattr(contactdyn.hybrid.loop, "WorkWatch", lambda left, progress: progress_watch(10**9))
    with pytest.raises(SimulationError, match="right-hand-side calls \\(24 per budgeted step\\)"):
        simulate("b1")


def progress_watch(left: int):
    return contactdyn.hybrid.events.WorkWatch(left)


def test_the_budget_is_the_base_plus_the_rate_times_the_duration():
    from contactdyn.scene.scene_file import load_scene

    scene = load_scene("b1", {"solver.steps_per_second": 1000.0})
    assert budget.step_budget(scene.solver, scene.duration) == budget.STEPS_BASE + 2000
    assert budget.sample_rate(scene) == 0.0


def test_a_sampled_laws_samples_add_their_steps_to_the_budget(monkeypatch):
    """Each sample instant is a step boundary: a 5 kHz law over 0.1 s takes 500 steps at least, beyond a continuous
    budget of 100 steps per simulated second (no base: 10 steps); the budget adds STEPS_PER_SAMPLE per sample."""
    from contactdyn.scene.scene_file import load_scene

    scene = load_scene("b1", {"solver.steps_per_second": 1000.0, "controller.sample_rate": 5000.0})
    assert budget.sample_rate(scene) == 5000.0
    assert budget.step_budget(scene.solver, scene.duration, 5000.0) == budget.STEPS_BASE + 2000 + 2 * 5000 * 2
    monkeypatch.setattr(budget, "STEPS_BASE", 0)
    run = simulate("b1", {"solver.steps_per_second": 100.0, "controller.sample_rate": 5000.0, "duration": 0.1})
    assert run.stats["samples"] == 500 and 500 <= run.stats["steps"] <= 10 + 2 * 500


def test_a_sample_rate_beyond_the_runs_step_bound_is_named():
    from contactdyn.errors import SceneError
    from contactdyn.scene.scene_file import load_scene

    with pytest.raises(SceneError, match=": controller.sample_rate: expected at most 1e\\+07 samples"):
        load_scene("b1", {"controller.sample_rate": 1e6, "duration": 100.0})


def test_progress_shows_after_a_while_as_lines_off_a_terminal(monkeypatch):
    clock = iter([0.0, 1.0, 2.5, 3.0, 13.0])
    monkeypatch.setattr(progress.time, "monotonic", lambda: next(clock))
    out = io.StringIO()
    p = progress.Progress("b1", 2.0, out)  # created at 0 s
    for t in (0.1, 0.5, 0.6, 1.9):  # at 1 s (quiet), 2.5 s (a line), 3 s (too soon), 13 s (a line)
        p(t)
    assert out.getvalue().splitlines() == ["b1: t = 0.5 / 2 s (25 %, 2 s)", "b1: t = 1.9 / 2 s (95 %, 13 s)"]


def test_a_scene_name_with_escape_codes_is_shown_escaped():
    stream = io.StringIO()
    shown = progress.Progress("b1\x1b[31mRED", 2.0, stream)
    shown.next = 0.0  # due now (no waiting for SHOW_AFTER)
    shown(1.0)
    assert "\x1b" not in stream.getvalue() and stream.getvalue().startswith("b1\\x1b[31mRED: t = 1 / 2 s (50 %")


def test_a_right_hand_sides_batches_are_counted_as_their_calls():
    """Work.wrap counts a right-hand side's ``derivatives`` (the dense output's batch) as one call per state and its
    ``interpolant`` as its three stages, where it gives one (declined: the calls that build it instead count)."""
    def fun(t, y):
        return -y

    fun.derivatives = lambda ts, Y: -Y
    fun.interpolant = lambda t, h, y, f, block: None if h < 0.0 else np.zeros((7, len(y)))
    work = progress.Work(limit=100)
    counted = work.wrap(fun)
    assert np.array_equal(counted.derivatives(np.zeros(4), np.ones((4, 2))), -np.ones((4, 2)))
    counted(0.0, np.ones(2))
    assert work.calls == 5
    assert counted.interpolant(0.0, 0.1, np.ones(2), np.ones(2), None).shape == (7, 2) and work.calls == 8
    assert counted.interpolant(0.0, -0.1, np.ones(2), np.ones(2), None) is None and work.calls == 8
