"""Interleaved timing for the benchmarks: every variant once per repeat, then medians.

Interleaving (A B A B ... rather than A A ... B B ...) lets a slow drift of the shared
machine's load hit every variant alike, so their ratio stays fair. Each call is timed in
wall time and in this process's CPU time [s]; a benchmark reports whichever suits it
(CPU when the machine is busy, wall when other processes do the work, e.g. a pool).

    from timing import interleaved
    times = interleaved({"DOP853": lambda: simulate(s, ...), "DOP853C": ...}, repeats=3)
    times["DOP853"].cpu, times["DOP853"].last.stats
"""

from __future__ import annotations

import json
import os
import platform
import statistics
import time
from collections.abc import Callable, Hashable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, TypeVar

__all__ = ["Timing", "interleaved", "write_report"]

K = TypeVar("K", bound=Hashable)


@dataclass
class Timing:
    """One variant's times over the repeats and the value its last call returned."""

    wall_s: list[float] = field(default_factory=list)  #: [s] wall time of each call
    cpu_s: list[float] = field(default_factory=list)  #: [s] this process's CPU time of each call
    last: Any = None  #: what the last call returned

    @property
    def wall(self) -> float:
        """Median wall time [s]."""
        return statistics.median(self.wall_s)

    @property
    def cpu(self) -> float:
        """Median CPU time of this process [s]."""
        return statistics.median(self.cpu_s)


def interleaved(variants: dict[K, Callable[[], Any]], repeats: int) -> dict[K, Timing]:
    """Call every variant once per repeat, in the given order, ``repeats`` times; their timings by key."""
    timings = {key: Timing() for key in variants}
    for _ in range(repeats):
        for key, call in variants.items():
            t0, c0 = time.perf_counter(), time.process_time()
            value = call()
            timing = timings[key]
            timing.wall_s.append(time.perf_counter() - t0)
            timing.cpu_s.append(time.process_time() - c0)
            timing.last = value
    return timings


def write_report(path: Path, head: dict, rows: list) -> dict:
    """Write ``head``, the machine's load average, Python and machine, then ``rows`` as JSON at path; return it."""
    out = {**head, "load_average": os.getloadavg(), "python": platform.python_version(),
           "machine": platform.machine(), "rows": rows}
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(out, indent=1))
    print(f"wrote {path}")
    return out
