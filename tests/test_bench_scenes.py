"""The scene benchmark's error measure (benchmarks/scenes.py): event samples excluded, maxima over contacts."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import numpy as np
import pytest

_spec = importlib.util.spec_from_file_location("bench_scenes",
                                              Path(__file__).parent.parent / "benchmarks" / "scenes.py")
bench = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(bench)


class Run:
    def __init__(self, t, channels, events):
        self.t, self.channels, self.events = t, channels, events

    def __getitem__(self, name):
        return self.channels[name]


def test_errors_exclude_two_samples_around_each_event_of_either_run():
    t = np.linspace(0.0, 1.0, 101)  # 0.01 s samples
    zeros = np.zeros(101)
    F_a, F_b = zeros.copy(), zeros.copy()
    F_a[50:] = 10.0  # a touch at 0.5 s in one run ...
    F_b[52:] = 10.0  # ... at 0.515 s in the other: a jump, not integration error
    F_b[80] += 1e-6  # a genuine difference [N]
    tip = np.zeros((101, 3))
    tip_b = tip.copy()
    tip_b[10] = [3e-9, 4e-9, 0.0]
    run = Run(t, {"contact.a.F_n": F_a, "contact.b.F_n": zeros, "tip": tip, "stage.a.n.env1.x": zeros},
              [{"t": 0.5, "kind": "touch"}, {"t": 0.3, "kind": "turn"}])
    ref = Run(t, {"contact.a.F_n": F_b, "contact.b.F_n": zeros + 2e-7, "tip": tip_b, "stage.a.n.env1.x": zeros},
              [{"t": 0.515, "kind": "touch"}])
    e = bench.errors(run, ref)
    assert e["force_all"] == 10.0
    assert e["force_away"] == pytest.approx(1e-6)  # samples 0.48-0.53 excluded (±2 around each touch)
    assert e["tip_all"] == e["tip_away"] == pytest.approx(5e-9)  # 'turn' is no mode switch: 0.3 s is kept
    assert e["samples_away"] == 101 - len(range(48, 54))  # 48..52 and 50..53 (0.515 ± 0.02)
    with pytest.raises(ValueError, match="output grids"):
        bench.errors(run, Run(t[:-1], {}, []))
