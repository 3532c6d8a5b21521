"""The output's batches (contactdyn.output.channels.sample_states): a compiled mode's samples over several runs of
segments in one call are the runs' own, bit for bit, also where a call has no answer (then each run on its own, the
rows from that one on within its run NaN); Samples.scattered puts rows back in place."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

BENCH = Path(__file__).resolve().parent.parent / "benchmarks"
sys.path.insert(0, str(BENCH))
from pipeline_proto import case, states  # noqa: E402

from contactdyn.hybrid import pipeline_mode  # noqa: E402
from contactdyn.hybrid.pipeline_mode import PipelineMode  # noqa: E402
from contactdyn.model.pipeline.pipeline import Pipeline  # noqa: E402
from contactdyn.output.samples import Samples  # noqa: E402


def _bits(S: Samples) -> dict[str, bytes]:
    out = {}
    for name, value in vars(S).items():
        for key, arr in (value.items() if isinstance(value, dict) else [("", value)]):
            out[f"{name}.{key}"] = np.asarray(arr).tobytes()
    return out


def _mode(name: str = "b1_sampled_joints"):
    system, modes, phase, t, x0 = case(name)
    X = np.array(states(x0, 7))
    return system, PipelineMode(Pipeline(system, modes, phase)), t + np.linspace(0.0, 0.05, len(X)), X


def _run_by_run(system, pm, ts, X, runs):
    """The samples of each run of ``runs`` rows on its own, concatenated."""
    ends = np.cumsum(runs)
    return Samples.concatenate([pm.samples(ts[e - n:e], X[e - n:e]) for n, e in zip(runs, ends, strict=True)], system)


def test_runs_in_one_call_are_each_runs_own():
    system, pm, ts, X = _mode()
    runs = [2, 3, 2]
    alone = _run_by_run(system, pm, ts, X, runs)
    assert _bits(pm.samples(ts, X, runs=runs)) == _bits(alone)


def test_a_call_without_an_answer_samples_each_run_on_its_own(monkeypatch):
    """A call with no answer at one state (here: made to, at ts[3]): the batch of runs gives what each run gave alone,
    the rows of that run from it on NaN (one call without an answer counted), the other runs' on the compiled
    call."""
    system, pm, ts, X = _mode()
    compiled = pipeline_mode.samples_at

    def declining(t, X_, *args):
        Xd, E, W, done = compiled(t, X_, *args)
        bad = np.flatnonzero(t == ts[3])
        return Xd, E, W, min(done, int(bad[0])) if len(bad) else done

    monkeypatch.setattr(pipeline_mode, "samples_at", declining)
    runs = [2, 3, 2]
    alone = _run_by_run(system, pm, ts, X, runs)
    failed = pm.singular
    assert failed == 1  # the run [2, 5) at row 3
    assert np.isnan(alone.tau[3:5]).all() and np.isfinite(alone.tau[:3]).all() and np.isfinite(alone.tau[5:]).all()
    assert _bits(pm.samples(ts, X, runs=runs)) == _bits(alone)
    assert pm.singular == 2 * failed


def test_scattered_puts_each_part_at_its_rows():
    system, pm, ts, X = _mode()
    whole = pm.samples(ts, X)
    rows = [np.array([0, 3, 6]), np.array([1, 2]), np.array([4, 5])]
    parts = [pm.samples(ts[r], X[r]) for r in rows]
    assert _bits(Samples.scattered(parts, rows, system)) == _bits(whole)


def test_last_evaluation_solves_an_instant_once():
    """LastEvaluation: the same (t, x bit for bit, modes, phase object) again is the kept Evaluation; any other
    argument (a -0.0 for a 0.0, another phase object) solves again, equal to the mode's call's evaluation."""
    from contactdyn.hybrid.pipeline_mode import mode_runner
    from contactdyn.hybrid.transitions import LastEvaluation

    system, modes, phase, t, x0 = case("b1_sampled_joints")
    calls = []
    runner = mode_runner(system)

    class Counting:
        def __init__(self, mode):
            self.mode = mode

        def evaluation(self, *args):
            calls.append(args)
            return self.mode.evaluation(*args)

    last = LastEvaluation(system, lambda modes_, phase_: Counting(runner(modes_, phase_)))
    first = last(t, x0, modes, phase)
    assert last(t, x0.copy(), list(modes), phase) is first and len(calls) == 1
    zeroed = x0.copy()
    zeroed[zeroed == 0.0] = -0.0
    last(t, zeroed, modes, phase)
    other = last(t, x0, modes, type(phase)(**vars(phase)))
    assert len(calls) == 3 - (not np.any(x0 == 0.0))
    assert np.array_equal(other.xdot, runner(modes, phase).evaluation(t, x0).xdot)
