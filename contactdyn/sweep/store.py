"""A sweep's files: per-run rows, the summary table, the manifest; every write atomic."""

from __future__ import annotations

import json
import math
import os
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import ContactdynError, SceneError
from ..result import atomic_path, atomic_write
from .plan import Sweep

__all__ = ["STATUSES", "SUMMARY_FIXED", "result_row", "record_failure", "done_row", "cached_rows", "write_manifest",
           "write_summary", "lock_out"]

STATUSES = ("ok", "failed", "crashed")
SUMMARY_FIXED = ("run_id", "status", "error", "wall_s")  #: columns before the metrics (after the parameters)


def result_row(rid: str, result) -> dict[str, Any]:
    """Summary row of a finished run: status ``failed`` if its channels hold non-finite values."""
    from ..metrics import metrics

    bad = sorted(k for k, v in result.channels.items()
                 if not k.endswith((".F_d", "tip_ref")) and not np.all(np.isfinite(v)))
    error = f"non-finite values in {', '.join(bad)}" if bad else ""
    return {"run_id": rid, "status": "failed" if bad else "ok", "error": error,
            "wall_s": float(result.stats.get("wall_s", math.nan)), **metrics(result)}


def record_failure(runs_dir: Path, rid: str, overrides: dict[str, Any], status: str, error: str, wall_s: float
                   ) -> dict[str, Any]:
    """Write ``<id>.failed.json`` (the error and the overrides) and return the run's summary row."""
    row = {"run_id": rid, "status": status, "error": error, "wall_s": wall_s}
    atomic_write(runs_dir / f"{rid}.failed.json", json.dumps({**row, "overrides": overrides}, indent=1,
                                                              default=str).encode())
    return row


def lock_out(out: Path):
    """Hold ``OUT/.sweep.lock`` for this sweep (released when the process ends, however it ends).

    A second sweep into the same folder is refused: it would rewrite the summary and could
    run the same cases twice. Returns the open lock file; keep it until the sweep is done.
    """
    import fcntl

    lock = open(out / ".sweep.lock", "a+")  # noqa: SIM115 (held for the whole sweep)
    try:
        fcntl.flock(lock.fileno(), fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        lock.seek(0)
        holder = lock.read().strip() or "?"
        lock.close()
        raise SceneError("--out", "a folder no other sweep is writing to (wait for it, or choose another --out)",
                         f"{out} (sweep process {holder} is running into it)") from None
    lock.seek(0)
    lock.truncate()
    lock.write(str(os.getpid()))
    lock.flush()
    return lock


def done_row(runs_dir: Path, rid: str, cache: dict[str, dict[str, Any]]) -> dict[str, Any] | None:
    """The row of a finished run (from the last summary, else from its files); None if it must run."""
    from ..result import load_result

    failed = runs_dir / f"{rid}.failed.json"
    finished = failed.is_file() or ((runs_dir / f"{rid}.npz").is_file() and (runs_dir / f"{rid}.json").is_file())
    if not finished:
        return None
    if rid in cache:
        return cache[rid]
    try:
        if failed.is_file():
            doc = json.loads(failed.read_text())
            return {k: doc[k] for k in SUMMARY_FIXED}
        return result_row(rid, load_result(runs_dir / rid))
    except (OSError, ValueError, KeyError, TypeError, RecursionError, ContactdynError):  # damaged by hand: run again
        return None


def cached_rows(out: Path) -> dict[str, dict[str, Any]]:
    """Rows of the last summary by run id, to resume without reloading every result."""
    import pandas as pd

    from ..metrics import is_metric

    try:
        frame = pd.read_parquet(out / "summary.parquet")
    except (OSError, ValueError, ImportError):
        return {}
    cols = [c for c in frame.columns if c in SUMMARY_FIXED or is_metric(c)]
    if not set(SUMMARY_FIXED) <= set(cols):
        return {}
    return {r["run_id"]: r for r in frame[cols].to_dict("records")}


def write_manifest(out: Path, sweep: Sweep, cases: list) -> None:
    path = out / "sweep.json"
    digest = sweep.digest()
    if path.is_file():
        try:
            old = json.loads(path.read_text()).get("scene_digest")
        except (OSError, ValueError, AttributeError, RecursionError):
            old = None
        if old not in (None, digest):
            raise SceneError("<file>", f"a sweep of the same base scene (this one is {sweep.file}); "
                             "choose another --out or remove this folder", "a sweep of another scene", str(path))
    doc = {"scene_file": sweep.file, "scene_digest": digest, "fixed": sweep.fixed, "axes": sweep.axes,
           "runs": sweep.runs, "cases": [{"run_id": rid, "params": p} for rid, p, _ in cases],
           "document": sweep.document}
    atomic_write(path, json.dumps(doc, indent=1, sort_keys=True, default=str).encode())


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
    """A parameter column with one type: numbers, strings or booleans; anything else as JSON text."""
    present = [v for v in values if v is not None]
    if present and all(isinstance(v, bool) for v in present):
        return [v for v in values]
    if present and all(isinstance(v, int | float) and not isinstance(v, bool) for v in present):
        return np.array([math.nan if v is None else float(v) for v in values])
    if all(isinstance(v, str) for v in present):
        return values
    return [None if v is None else json.dumps(v, sort_keys=True) for v in values]


