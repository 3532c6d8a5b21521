"""Test helpers that hold the compiled call to its own source: two whole runs of one scene (the compiled call's
against the same call interpreted), and the model at an instant or at output samples on the interpreted call."""

from __future__ import annotations

import numpy as np

from contactdyn.hybrid.pipeline_mode import mode_runner
from contactdyn.model.paths import INTERPRETED, PIPELINE
from contactdyn.output.samples import Samples

RUN_RTOL = 1e-9  #: each channel to RUN_RTOL of its largest magnitude (plus 1e-12 in SI units)
EVENT_ATOL = 1e-9  #: [s] the events' times


def assert_runs_agree(fast, interpreted) -> None:
    """Every mode of ``fast`` on the compiled call, of ``interpreted`` on the same call interpreted (a run with
    ``LivePipelines.use`` off); the same channels and events (RUN_RTOL; the events' times to EVENT_ATOL)."""
    assert {row["path"] for row in fast.stats["paths"].values()} == {PIPELINE}, fast.stats["paths"]
    assert {row["path"] for row in interpreted.stats["paths"].values()} == {INTERPRETED}
    assert set(fast.channels) == set(interpreted.channels)
    for key, ref in interpreted.channels.items():
        ref, got = np.asarray(ref, float), np.asarray(fast.channels[key], float)
        if ref.size and not np.all(np.isnan(ref)):
            assert float(np.nanmax(np.abs(got - ref))) <= RUN_RTOL * float(np.nanmax(np.abs(ref))) + 1e-12, key
    assert [(e["kind"], e["name"]) for e in fast.events] == [(e["kind"], e["name"]) for e in interpreted.events]
    np.testing.assert_allclose([e["t"] for e in fast.events], [e["t"] for e in interpreted.events], rtol=0,
                               atol=EVENT_ATOL)


def interpreted_evaluate(system, t: float, x: np.ndarray, modes, phase):
    """The model at (t [s], x) on the same call interpreted (its Python source): the reference a compiled call is
    held to state by state (one interpreted runner per system, kept on it)."""
    runner = getattr(system, "_interpreted_runner", None)
    if runner is None:
        runner = system._interpreted_runner = mode_runner(system, compiled=False)
    return runner(modes, phase).evaluation(t, np.array(x, float))


def interpreted_samples(system, ts: np.ndarray, X: np.ndarray, modes, phase) -> Samples:
    """The output samples at the states X[k] (times ts[k]) on the same call interpreted."""
    interpreted_evaluate(system, float(ts[0]), X[0], modes, phase)
    return system._interpreted_runner(modes, phase).samples(np.asarray(ts, float), np.asarray(X, float), modes)
