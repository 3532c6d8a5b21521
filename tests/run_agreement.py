"""Two whole runs of one scene held to each other: the compiled call's run against the readable model's (used by
tests/test_moved_declines.py and tests/test_python_controller.py)."""

from __future__ import annotations

import numpy as np

from contactdyn.model.paths import PIPELINE, READABLE

RUN_RTOL = 1e-9  #: each channel to RUN_RTOL of its largest magnitude (plus 1e-12 in SI units)
EVENT_ATOL = 1e-9  #: [s] the events' times


def assert_runs_agree(fast, readable) -> None:
    """Every mode of ``fast`` on the compiled call, of ``readable`` on the readable model; the same channels and
    events (RUN_RTOL; the events' times to EVENT_ATOL)."""
    assert {row["path"] for row in fast.stats["paths"].values()} == {PIPELINE}, fast.stats["paths"]
    assert {row["path"] for row in readable.stats["paths"].values()} == {READABLE}
    assert set(fast.channels) == set(readable.channels)
    for key, ref in readable.channels.items():
        ref, got = np.asarray(ref, float), np.asarray(fast.channels[key], float)
        if ref.size and not np.all(np.isnan(ref)):
            assert float(np.nanmax(np.abs(got - ref))) <= RUN_RTOL * float(np.nanmax(np.abs(ref))) + 1e-12, key
    assert [(e["kind"], e["name"]) for e in fast.events] == [(e["kind"], e["name"]) for e in readable.events]
    np.testing.assert_allclose([e["t"] for e in fast.events], [e["t"] for e in readable.events], rtol=0,
                               atol=EVENT_ATOL)
