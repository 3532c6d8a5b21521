"""A sweep's files: per-run rows, the manifest, the lock; every write atomic (the summary: :mod:`.summary`)."""

from __future__ import annotations

import json
import math
import os
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import ContactdynError, SceneError
from ..output.result import atomic_write
from .plan import Sweep
from .summary import SUMMARY_FIXED

__all__ = ["STATUSES", "result_row", "record_failure", "done_row", "write_manifest", "lock_out"]

STATUSES = ("ok", "failed", "crashed")


def result_row(rid: str, result) -> dict[str, Any]:
    """Summary row of a finished run: status ``failed`` if its channels hold non-finite values."""
    from ..output.metrics import metrics

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
    from ..output.result import load_result

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
