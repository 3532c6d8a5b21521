"""benchmarks/timing.py: every variant once per repeat, in turn; medians of what was recorded."""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

_PATH = Path(__file__).resolve().parent.parent / "benchmarks" / "timing.py"
_spec = importlib.util.spec_from_file_location("timing", _PATH)
timing = importlib.util.module_from_spec(_spec)
sys.modules[_spec.name] = timing  # dataclasses look their module up while the class is built
_spec.loader.exec_module(timing)


def test_variants_are_interleaved_repeat_by_repeat_and_keep_their_last_value():
    calls = []

    def variant(name):
        def call():
            calls.append(name)
            return f"{name}{calls.count(name)}"
        return call

    times = timing.interleaved({"a": variant("a"), "b": variant("b"), "c": variant("c")}, repeats=3)
    assert calls == ["a", "b", "c"] * 3  # A B C A B C ..., never A A A B B B
    assert [times[k].last for k in "abc"] == ["a3", "b3", "c3"]
    assert all(len(times[k].wall_s) == len(times[k].cpu_s) == 3 for k in "abc")


def test_wall_and_cpu_are_the_medians_of_the_repeats():
    t = timing.Timing(wall_s=[3.0, 1.0, 2.0, 10.0, 0.5], cpu_s=[4.0, 1.0, 2.0])
    assert (t.wall, t.cpu) == (2.0, 2.0)
