"""benchmarks/compare_outputs.py, the refactoring guard: it must see a difference where there is one."""

from __future__ import annotations

import importlib.util
import json
from pathlib import Path

import numpy as np

_PATH = Path(__file__).resolve().parent.parent / "benchmarks" / "compare_outputs.py"
_spec = importlib.util.spec_from_file_location("compare_outputs", _PATH)
compare_outputs = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(compare_outputs)


def test_rel_diff_is_relative_to_the_channel_and_nan_equals_nan():
    old = np.array([1.0, -4.0, np.nan])
    assert compare_outputs.rel_diff(old.copy(), old) == 0.0
    assert np.isclose(compare_outputs.rel_diff(old + [0.0, 4e-12, 0.0], old), 1e-12, rtol=1e-3)  # 4e-12 / max|old|
    assert compare_outputs.rel_diff(np.array([1.0, -4.0, 0.0]), old) == np.inf  # a NaN that appeared or vanished
    assert compare_outputs.rel_diff(old[:2], old) == np.inf  # another length


def test_compare_case_reports_channels_events_and_impacts(tmp_path):
    channels = {"t": np.linspace(0.0, 1.0, 5), "q": np.arange(5.0)}
    doc = {"events": [{"t": 0.25, "kind": "touch", "name": "tip"}], "impacts": []}
    saved = tmp_path / "case"
    np.savez(saved.with_suffix(".npz"), **channels)
    saved.with_suffix(".json").write_text(json.dumps(doc))
    assert compare_outputs.compare_case(channels, doc, saved) == (0.0, "-", "same")
    worst, name, verdict = compare_outputs.compare_case({**channels, "q": channels["q"] * (1 + 1e-9)}, doc, saved)
    assert name == "q" and np.isclose(worst, 1e-9) and verdict == "same"
    later = {"events": [{"t": 0.25 * (1 + 1e-10), "kind": "touch", "name": "tip"}], "impacts": []}
    worst, name, _ = compare_outputs.compare_case(channels, later, saved)
    assert name == "events" and np.isclose(worst, 1e-10)
    assert compare_outputs.compare_case(channels, {**doc, "events": []}, saved)[2] == "events: 0 vs 1"
    renamed = {"events": [{"t": 0.25, "kind": "separate", "name": "tip"}], "impacts": []}
    assert compare_outputs.compare_case(channels, renamed, saved)[2] == "events: kinds/names differ"
