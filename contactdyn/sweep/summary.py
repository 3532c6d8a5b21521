"""A sweep's summary table, kept current at a cost linear in the number of runs.

``OUT/summary.parquet`` (and ``summary.csv``) holds one row per finished run. Rewriting it
costs time proportional to its rows, so rewriting it after every chunk made a sweep's
summary cost grow with the square of its size. Instead each chunk's rows go to a small
file of their own, ``OUT/summary.parts/<n>.json`` (written atomically, never rewritten),
and the table is rewritten, the parts merged into it and removed:

- when the sweep starts (the parts a killed sweep left) and when it ends (even by an
  exception or Ctrl-C; a SIGKILL leaves the parts for the next sweep to merge);
- in between, when at least :data:`REFRESH_S` have passed since the last rewrite and at
  least :data:`COST_FACTOR` times that rewrite's own duration: the rewrites then take at
  most 1/(1 + COST_FACTOR) of the sweep's time, however many rows and chunks it has.

Resuming reads the table and the parts (:func:`cached_rows`), so no finished run's row is
lost or recomputed.
"""

from __future__ import annotations

import json
import math
import shutil
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from ..output.result import atomic_path, atomic_write, jsonable

__all__ = ["SUMMARY_FIXED", "PARTS", "REFRESH_S", "COST_FACTOR", "Summary", "cached_rows", "write_summary"]

SUMMARY_FIXED = ("run_id", "status", "error", "wall_s")  #: columns before the metrics (after the parameters)
PARTS = "summary.parts"  #: folder of the rows written since the last rewrite of the table
REFRESH_S = 30.0  #: [s] between two rewrites of the table during a sweep, at least
COST_FACTOR = 20.0  #: ... and at least this many times the last rewrite's duration


class Summary:
    """The summary of one sweep: rows by run id, the part files, and when to rewrite the table.

    ``clock`` [s] (monotonic) is there for tests; ``rewrites`` counts the full rewrites.
    """

    def __init__(self, out: Path, rows: dict[str, dict[str, Any]], params: dict[str, dict[str, Any]],
                 keys: list[str], csv: bool, clock: Callable[[], float] = time.monotonic) -> None:
        self.out, self.rows, self.params, self.keys, self.csv = out, rows, params, keys, csv
        self.path = out / "summary.parquet"
        self.rewrites = 0
        self._clock = clock
        self.pending = False  #: rows added since the last rewrite of the table
        self._parts = 0  #: part files written since the last rewrite
        self._last = clock()  #: [s] when the last rewrite ended
        self._cost = 0.0  #: [s] the last rewrite's duration

    def add(self, chunk_rows: list[dict[str, Any]]) -> None:
        """Record a chunk's rows: in their own part file, and in the table when it is due."""
        self.rows.update((r["run_id"], r) for r in chunk_rows)
        self.pending = True  # in the table at the next rewrite, even if the part below is interrupted
        parts = self.out / PARTS
        parts.mkdir(exist_ok=True)
        atomic_write(parts / f"{self._parts:06d}.json", json.dumps(chunk_rows, default=jsonable))
        self._parts += 1
        if self._clock() - self._last >= max(REFRESH_S, COST_FACTOR * self._cost):
            self.rewrite()

    def rewrite(self) -> Path:
        """Write the whole table (atomically), then remove the part files it now holds."""
        start = self._clock()
        write_summary(self.out, self.rows, self.params, self.keys, self.csv)
        shutil.rmtree(self.out / PARTS, ignore_errors=True)  # only this sweep writes them (it holds the lock)
        self.rewrites += 1
        self.pending, self._parts = False, 0
        self._last = self._clock()
        self._cost = self._last - start
        return self.path


def cached_rows(out: Path) -> dict[str, dict[str, Any]]:
    """Rows of the last table and of the part files after it, by run id, to resume without reloading results."""
    rows = _table_rows(out / "summary.parquet")
    for part in sorted((out / PARTS).glob("[0-9]*.json")):  # in the order they were written
        rows.update((r["run_id"], r) for r in _part_rows(part))
    return rows


def _table_rows(path: Path) -> dict[str, dict[str, Any]]:
    import pandas as pd

    from ..output.metrics import is_metric

    try:
        frame = pd.read_parquet(path)
    except (OSError, ValueError, ImportError):
        return {}
    cols = [c for c in frame.columns if c in SUMMARY_FIXED or is_metric(c)]
    if not set(SUMMARY_FIXED) <= set(cols):
        return {}
    return {r["run_id"]: r for r in frame[cols].to_dict("records")}


def _part_rows(path: Path) -> list[dict[str, Any]]:
    """The rows of one part file; none if it is damaged (those runs are then reloaded from their files)."""
    from ..output.metrics import is_metric

    try:
        rows = json.loads(path.read_text())
    except (OSError, ValueError, RecursionError):
        return []
    good = isinstance(rows, list) and all(isinstance(r, dict) and set(SUMMARY_FIXED) <= set(r) for r in rows)
    return [{k: v for k, v in r.items() if k in SUMMARY_FIXED or is_metric(k)} for r in rows] if good else []


def write_summary(out: Path, rows: dict[str, dict[str, Any]], params: dict[str, dict[str, Any]],
                  keys: list[str], csv: bool) -> Path:
    """summary.parquet (and .csv) of the finished runs, sorted by the swept parameters, written atomically."""
    import pandas as pd

    ids = sorted(rows, key=lambda i: (_parameter_order(params[i], keys), i))
    metric_cols = sorted({k for r in rows.values() for k in r} - set(SUMMARY_FIXED))
    data: dict[str, Any] = {"run_id": ids}
    for key in keys:
        data[key] = _column([params[i].get(key) for i in ids])
    for col in SUMMARY_FIXED[1:]:
        data[col] = [rows[i][col] for i in ids]
    data["wall_s"] = np.array(data["wall_s"], dtype=float)
    for col in metric_cols:
        data[col] = np.array([rows[i].get(col, math.nan) for i in ids], dtype=float)
    frame = pd.DataFrame(data)
    path = out / "summary.parquet"
    atomic_path(path, lambda tmp: frame.to_parquet(tmp, index=False, engine="pyarrow"))
    if csv:
        atomic_path(out / "summary.csv", lambda tmp: frame.to_csv(tmp, index=False))
    return path


def _parameter_order(params: dict[str, Any], keys: list[str]) -> tuple:
    """Sort key of a run: its parameter values in the order of ``keys`` (numbers, then strings, then the rest)."""
    order = []
    for key in keys:
        v = params.get(key)
        if isinstance(v, int | float) and not isinstance(v, bool):
            order.append((0, float(v), ""))
        elif isinstance(v, str | bool):
            order.append((1, 0.0, str(v)))
        else:
            order.append((2 if v is not None else 3, 0.0, json.dumps(v, sort_keys=True)))
    return tuple(order)


def _column(values: list[Any]) -> Any:
    """A parameter column with one type: integers, numbers, strings or booleans; anything else as JSON text."""
    present = [v for v in values if v is not None]
    if present and all(isinstance(v, bool) for v in present):
        return [v for v in values]
    if present and all(isinstance(v, int) and not isinstance(v, bool) for v in present):
        import pandas as pd

        return pd.array(values, dtype="Int64")  # integers stay integers (a sample count, a delay); None: <NA>
    if present and all(isinstance(v, int | float) and not isinstance(v, bool) for v in present):
        return np.array([math.nan if v is None else float(v) for v in values])
    if all(isinstance(v, str) for v in present):
        return values
    return [None if v is None else json.dumps(v, sort_keys=True) for v in values]
