"""Batch simulation: a scene run over a grid of overrides, on a process pool or a Dask cluster.

A sweep is a base scene, fixed overrides (``--set``) and the cases: the Cartesian product
of the axes (``--grid key=v1,v2``, ``--range key=lo:hi:n[:log]``), optionally times a list
of explicit runs from a sweep file. Each case is one run whose id is a stable hash of its
overrides (fixed and varied), so the same case always lands in the same files:

- ``OUT/runs/<id>.npz`` + ``.json``: the run's :class:`~contactdyn.result.Result`
  (``<id>.failed.json`` instead, with the error, when the run failed);
- ``OUT/summary.parquet`` (and ``summary.csv`` on request): one row per run, sorted by id:
  the varied parameters, status, error message, wall time [s] and the key metrics
  (:mod:`contactdyn.metrics`);
- ``OUT/sweep.json``: the base scene document, fixed overrides and the cases.

Every file is written atomically; the summary is rewritten after each chunk of runs, so an
interrupted sweep loses at most the runs in progress, and re-running the same command
skips the runs whose files exist. A run that fails (a bad parameter combination, a solver
failure, a blow-up) is a row with status ``failed`` (a :class:`ContactdynError` or a
numerical failure such as ``LinAlgError``) or ``crashed`` (any other exception, i.e. a
bug) and its message; the other runs go on.
Apart from the wall time (``wall_s`` in the summary, ``stats.wall_s`` and
``stats.real_time_factor`` in each ``<id>.json``) the outputs are bit-identical for the
same inputs.

Sweep file (TOML)::

    scene = "b1"                                   # a path (relative to this file) or a name in sims/
    [set]                                          # fixed overrides
    duration = 0.5
    [grid]                                         # one axis per key: a list of values
    "contact.tip.normal.k" = [1e4, 1e5, 1e6]
    [range]                                        # lo, hi, n (and log = true for log spacing)
    "controller.kp" = { lo = 100.0, hi = 1e4, n = 5, log = true }
    [[run]]                                        # explicit runs, each crossed with the axes
    "solver.method" = "RK45"
"""

from __future__ import annotations

import hashlib
import itertools
import json
import math
import os
import sys
import tempfile
import time
import tomllib
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from .config import Reader
from .errors import ContactdynError, SceneError
from .scene import find_scene, parse_override, parse_scene

__all__ = ["Sweep", "SweepReport", "parse_grid", "parse_range", "load_sweep_file", "run_id", "run_sweep",
           "run_chunk", "STATUSES"]

STATUSES = ("ok", "failed", "crashed")
SUMMARY_FIXED = ("run_id", "status", "error", "wall_s")  #: columns before the metrics (after the parameters)
CHUNKS_PER_WORKER = 4  #: aim for this many chunks per worker (load balance vs per-chunk cost)
#: numerical failures a blow-up raises from numpy inside a run (a failed run, not a bug)
NUMERICAL: tuple[type[Exception], ...] = (np.linalg.LinAlgError, FloatingPointError, OverflowError)
MAX_CHUNK = 32  #: runs per chunk at most, so the summary is refreshed often
SCHEDULER_TIMEOUT = 10.0  #: [s] to connect to a Dask scheduler


# ---- describing a sweep ------------------------------------------------------------------
@dataclass
class Sweep:
    """A base scene document, fixed overrides and the varied axes (key -> values)."""

    document: dict[str, Any]
    file: str | None
    fixed: dict[str, Any] = field(default_factory=dict)
    axes: dict[str, list[Any]] = field(default_factory=dict)
    runs: list[dict[str, Any]] = field(default_factory=list)  #: explicit runs, crossed with the axes

    @property
    def name(self) -> str:
        name = self.document.get("name")
        return name if isinstance(name, str) else Path(self.file or "scene").stem

    def cases(self) -> list[tuple[str, dict[str, Any], dict[str, Any]]]:
        """(run id, varied parameters, all overrides) per run, sorted by id; duplicates merged."""
        out: dict[str, tuple[str, dict[str, Any], dict[str, Any]]] = {}
        keys = list(self.axes)
        for explicit in self.runs or [{}]:
            for values in itertools.product(*(self.axes[k] for k in keys)):
                params = {**explicit, **dict(zip(keys, values, strict=True))}
                overrides = {**self.fixed, **params}
                rid = run_id(overrides)
                out[rid] = (rid, params, overrides)
        return [out[k] for k in sorted(out)]

    def parameter_keys(self) -> list[str]:
        keys = list(self.axes)
        for explicit in self.runs:
            keys += [k for k in explicit if k not in keys]
        return keys

    def digest(self) -> str:
        """A hash of the base document: a resumed sweep must start from the same scene."""
        return hashlib.sha256(_canonical(self.document).encode()).hexdigest()[:16]


def run_id(overrides: dict[str, Any]) -> str:
    """Stable id of a run: the first 12 hex digits of the SHA-256 of its sorted overrides."""
    return hashlib.sha256(_canonical(overrides).encode()).hexdigest()[:12]


def _canonical(obj: Any) -> str:
    return json.dumps(obj, sort_keys=True, separators=(",", ":"), allow_nan=True, default=str)


def parse_grid(text: str) -> tuple[str, list[Any]]:
    """``key=v1,v2,...`` (each value read as TOML, else as a string; commas inside [] are kept)."""
    key, sep, rest = text.partition("=")
    key = key.strip()
    items = _split_top_level(rest)
    if not sep or not key or not items or any(not s for s in items):
        raise SceneError("--grid", "key.path=v1,v2,... with at least one value", text)
    return key, [parse_override(f"{key}={item}")[1] for item in items]


def parse_range(text: str) -> tuple[str, list[float]]:
    """``key=lo:hi:n`` (n values, linear) or ``key=lo:hi:n:log`` (log spacing, lo and hi > 0)."""
    key, sep, rest = text.partition("=")
    parts = rest.split(":")
    expected = "key.path=lo:hi:n or key.path=lo:hi:n:log (numbers, n >= 1)"
    if not sep or not key.strip() or len(parts) not in (3, 4) or (len(parts) == 4 and parts[3].strip() != "log"):
        raise SceneError("--range", expected, text)
    try:
        lo, hi, n = float(parts[0]), float(parts[1]), int(parts[2])
    except ValueError:
        raise SceneError("--range", expected, text) from None
    return key.strip(), _spaced(f"--range {key.strip()}", lo, hi, n, len(parts) == 4)


def _spaced(where: str, lo: float, hi: float, n: int, log: bool, file: str | None = None) -> list[float]:
    if not (math.isfinite(lo) and math.isfinite(hi)):
        raise SceneError(where, "finite lo and hi", [lo, hi], file)
    if n < 1:
        raise SceneError(where, "n >= 1 values", n, file)
    if log and (lo <= 0 or hi <= 0):
        raise SceneError(where, "lo > 0 and hi > 0 for log spacing", [lo, hi], file)
    values = np.geomspace(lo, hi, n) if log else np.linspace(lo, hi, n)
    return [float(v) for v in values]


def _split_top_level(text: str) -> list[str]:
    items, depth, quote, cur = [], 0, "", ""
    for ch in text:
        if quote:
            quote = "" if ch == quote else quote
        elif ch in "\"'":
            quote = ch
        elif ch in "[{":
            depth += 1
        elif ch in "]}":
            depth -= 1
        elif ch == "," and depth == 0:
            items.append(cur.strip())
            cur = ""
            continue
        cur += ch
    items.append(cur.strip())
    return items if any(items) else []


def load_sweep_file(path: str | Path) -> tuple[str | None, dict[str, Any], dict[str, list[Any]], list[dict[str, Any]]]:
    """Read a sweep file: (scene, fixed overrides, axes, explicit runs); errors name file and key."""
    path = Path(path)
    file = str(path)
    try:
        doc = tomllib.loads(path.read_text())
    except tomllib.TOMLDecodeError as exc:
        raise SceneError("<file>", "valid TOML", str(exc), file) from None
    except (OSError, UnicodeDecodeError) as exc:
        raise SceneError("<file>", "a readable sweep file", getattr(exc, "strerror", None) or str(exc), file) from None
    top = Reader(doc, "", file)
    scene = top.str("scene", None) if top.has("scene") else None
    if scene is not None and not Path(scene).is_absolute() and (path.parent / scene).is_file():
        scene = str(path.parent / scene)
    fixed = _flatten(top.raw("set", {}), "set", file, leaf=lambda v: not isinstance(v, dict))
    axes: dict[str, list[Any]] = {}
    for key, values in _flatten(top.raw("grid", {}), "grid", file, leaf=lambda v: not isinstance(v, dict)).items():
        if not isinstance(values, list) or not values:
            raise SceneError(f"grid.{key}", "a non-empty list of values", values, file)
        axes[key] = values
    spec_leaf = lambda v: not isinstance(v, dict) or "lo" in v  # noqa: E731
    for key, spec in _flatten(top.raw("range", {}), "range", file, leaf=spec_leaf).items():
        r = Reader(spec, f"range.{key}", file)
        lo, hi = r.float("lo"), r.float("hi")
        n, log = r.int("n", lo=1), r.bool("log", False)
        r.finish()
        axes[key] = _spaced(f"range.{key}", lo, hi, n, log, file)
    runs = [_flatten(t.data, t.path, file, leaf=lambda v: not isinstance(v, dict)) for t in top.tables("run")]
    top.finish()
    return scene, fixed, axes, runs


def _flatten(table: Any, where: str, file: str, leaf: Callable[[Any], bool]) -> dict[str, Any]:
    if not isinstance(table, dict):
        raise SceneError(where, "a table of key.path = value", table, file)
    out: dict[str, Any] = {}
    for key, value in table.items():
        if leaf(value):
            out[key] = value
        else:
            out.update({f"{key}.{k}": v for k, v in _flatten(value, f"{where}.{key}", file, leaf).items()})
    return out


def make_sweep(scene: str | Path | None, sets: Iterable[str] = (), grids: Iterable[str] = (),
               ranges: Iterable[str] = (), sweep_file: str | Path | None = None) -> Sweep:
    """Assemble a sweep from command-line pieces (they override the sweep file's)."""
    fixed: dict[str, Any] = {}
    axes: dict[str, list[Any]] = {}
    runs: list[dict[str, Any]] = []
    if sweep_file is not None:
        file_scene, fixed, axes, runs = load_sweep_file(sweep_file)
        scene = scene if scene is not None else file_scene
    if scene is None:
        raise SceneError("scene", "a scene (argument or `scene = ...` in the sweep file)", None,
                         str(sweep_file) if sweep_file else None)
    fixed.update(dict(parse_override(s) for s in sets))
    axes.update(dict(parse_grid(s) for s in grids))
    axes.update(dict(parse_range(s) for s in ranges))
    path = find_scene(scene)
    try:
        document = tomllib.loads(path.read_text())
    except tomllib.TOMLDecodeError as exc:
        raise SceneError("<file>", "valid TOML", str(exc), str(path)) from None
    except (OSError, UnicodeDecodeError) as exc:
        raise SceneError("<file>", "a readable scene file", getattr(exc, "strerror", None) or str(exc),
                         str(path)) from None
    return Sweep(document, str(path), fixed, axes, runs)


def check_sweep(sweep: Sweep) -> None:
    """Reject a sweep that cannot be right as a whole (exit 2), before any run starts.

    An unknown key in any case, every case invalid, or a robot that cannot be found is bad
    input. A case whose values alone are invalid is a bad parameter combination: it runs
    (and fails, recorded) with the others.
    """
    from .robot import resolve_robot_path

    first_ok, first_error = None, None
    for _, _, overrides in sweep.cases():
        try:
            scene = parse_scene(sweep.document, overrides, sweep.file)
        except SceneError as exc:
            if exc.found == "an unknown key":
                raise
            first_error = first_error or exc
            continue
        first_ok = first_ok or scene
    if first_ok is None:
        raise first_error  # type: ignore[misc]
    resolve_robot_path(first_ok.robot.source)


# ---- running -------------------------------------------------------------------------------
def run_chunk(document: dict[str, Any], file: str | None, runs_dir: str, tasks: list[tuple[str, dict[str, Any]]]
              ) -> list[dict[str, Any]]:
    """Run ``tasks`` [(id, overrides)] one after the other; write each result; return their rows.

    Runs in a worker process (pool or Dask); results go straight to ``runs_dir`` (which
    Dask workers must see: a shared file system).
    """
    return [_run_one(document, file, Path(runs_dir), rid, overrides) for rid, overrides in tasks]


def _run_one(document: dict[str, Any], file: str | None, runs_dir: Path, rid: str, overrides: dict[str, Any]
             ) -> dict[str, Any]:
    from .simulate import simulate

    wall0 = time.perf_counter()
    try:
        result = simulate(parse_scene(document, overrides, file))
    except (ContactdynError, *NUMERICAL) as exc:
        status, error = "failed", f"{type(exc).__name__}: {exc}"
    except Exception as exc:  # noqa: BLE001 (a bug or an uncaught blow-up: recorded, the sweep goes on)
        status, error = "crashed", f"{type(exc).__name__}: {exc}"
    else:
        result.save(runs_dir / rid)
        return result_row(rid, result)
    row = {"run_id": rid, "status": status, "error": error, "wall_s": time.perf_counter() - wall0}
    _atomic_write(runs_dir / f"{rid}.failed.json", json.dumps({**row, "overrides": overrides}, indent=1,
                                                              default=str).encode())
    return row


def result_row(rid: str, result) -> dict[str, Any]:
    """Summary row of a finished run: status ``failed`` if its channels hold non-finite values."""
    from .metrics import metrics

    bad = sorted(k for k, v in result.channels.items()
                 if not k.endswith((".F_d", "tip_ref")) and not np.all(np.isfinite(v)))
    error = f"non-finite values in {', '.join(bad)}" if bad else ""
    return {"run_id": rid, "status": "failed" if bad else "ok", "error": error,
            "wall_s": float(result.stats.get("wall_s", math.nan)), **metrics(result)}


def _done_row(runs_dir: Path, rid: str, cache: dict[str, dict[str, Any]]) -> dict[str, Any] | None:
    """The row of a finished run (from the last summary, else from its files); None if it must run."""
    from .result import load_result

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
    except (OSError, ValueError, KeyError, ContactdynError):  # damaged by hand (never by us): run it again
        return None


def _cached_rows(out: Path) -> dict[str, dict[str, Any]]:
    """Rows of the last summary by run id, to resume without reloading every result."""
    import pandas as pd

    from .metrics import is_metric

    try:
        frame = pd.read_parquet(out / "summary.parquet")
    except (OSError, ValueError, ImportError):
        return {}
    cols = [c for c in frame.columns if c in SUMMARY_FIXED or is_metric(c)]
    if not set(SUMMARY_FIXED) <= set(cols):
        return {}
    return {r["run_id"]: r for r in frame[cols].to_dict("records")}


@dataclass
class SweepReport:
    out: Path
    total: int  #: runs in the sweep
    skipped: int  #: already finished before this call (resumed)
    counts: dict[str, int]  #: runs per status
    wall_s: float  #: [s] wall time of this call
    summary: Path

    def as_dict(self) -> dict[str, Any]:
        return {"out": str(self.out), "total": self.total, "skipped": self.skipped, "counts": self.counts,
                "wall_s": self.wall_s, "summary": str(self.summary)}


def run_sweep(sweep: Sweep, out: str | Path, *, workers: int | None = None, scheduler: str | None = None,
              chunk: int | None = None, csv: bool = False, retry_failed: bool = False, progress: bool = False,
              check: bool = True) -> SweepReport:
    """Run every case not finished yet; write results and the summary under ``out``.

    ``workers``: local processes (None: all cores, 0: this process); ``scheduler``: a Dask
    scheduler address instead (chunks of ``chunk`` runs are the tasks either way).
    """
    wall0 = time.perf_counter()
    out = Path(out)
    runs_dir = out / "runs"
    runs_dir.mkdir(parents=True, exist_ok=True)
    for stale in runs_dir.glob(".*.tmp"):  # left by a killed writer; the real files are whole or absent
        stale.unlink(missing_ok=True)
    if check:
        check_sweep(sweep)
    cases = sweep.cases()
    _write_manifest(out, sweep, cases)
    rows: dict[str, dict[str, Any]] = {}
    cache = _cached_rows(out)
    for rid, _, _ in cases:
        if retry_failed and (runs_dir / f"{rid}.failed.json").is_file():
            (runs_dir / f"{rid}.failed.json").unlink()
        row = _done_row(runs_dir, rid, cache)
        if row is not None:
            rows[rid] = row
    todo = [(rid, overrides) for rid, _, overrides in cases if rid not in rows]
    skipped = len(rows)
    params = {rid: p for rid, p, _ in cases}
    summary = _write_summary(out, rows, params, sweep.parameter_keys(), csv)
    n_workers = (os.cpu_count() or 1) if workers is None else max(0, workers)
    size = chunk or max(1, min(MAX_CHUNK, math.ceil(len(todo) / (CHUNKS_PER_WORKER * max(1, n_workers)))))
    chunks = [todo[i:i + size] for i in range(0, len(todo), size)]
    bar = _progress(len(cases), skipped, progress)
    try:
        for chunk_rows in _execute(sweep, runs_dir, chunks, n_workers, scheduler):
            rows.update((r["run_id"], r) for r in chunk_rows)
            summary = _write_summary(out, rows, params, sweep.parameter_keys(), csv)
            bar.update(len(chunk_rows))
            bar.set_postfix(failed=sum(r["status"] != "ok" for r in rows.values()), refresh=False)
    finally:
        bar.close()
    counts = {s: sum(r["status"] == s for r in rows.values()) for s in STATUSES}
    return SweepReport(out, len(cases), skipped, counts, time.perf_counter() - wall0, summary)


def _execute(sweep: Sweep, runs_dir: Path, chunks: list, n_workers: int, scheduler: str | None):
    """Yield each chunk's rows as it completes."""
    if not chunks:
        return
    args = (sweep.document, sweep.file, str(runs_dir))
    if scheduler:
        yield from _execute_dask(scheduler, args, chunks)
        return
    if n_workers == 0:  # in this process, one chunk after the other
        for c in chunks:
            yield run_chunk(*args, c)
        return
    import multiprocessing
    from concurrent.futures import ProcessPoolExecutor, as_completed
    from concurrent.futures.process import BrokenProcessPool

    # no fork of a (possibly threaded) parent: workers fork from a server that preloaded the package
    ctx = multiprocessing.get_context("forkserver")
    ctx.set_forkserver_preload(["contactdyn.sweep", "contactdyn.simulate"])
    pool = ProcessPoolExecutor(max_workers=n_workers, mp_context=ctx, initializer=_worker_init)
    try:
        futures = [pool.submit(run_chunk, *args, c) for c in chunks]
        for fut in as_completed(futures):
            yield fut.result()
    except BrokenProcessPool as exc:
        raise ContactdynError(f"a worker process died ({exc}); the finished runs are saved, "
                              "run the same command again to resume") from None
    except BaseException:  # interrupted: stop the workers now (their results so far are whole files)
        for proc in list((getattr(pool, "_processes", None) or {}).values()):
            proc.terminate()
        pool.shutdown(wait=False, cancel_futures=True)
        raise
    pool.shutdown(wait=True)


def _worker_init() -> None:
    """Ctrl-C reaches the whole process group: only the parent handles it (it stops the workers)."""
    import signal

    signal.signal(signal.SIGINT, signal.SIG_IGN)


def _execute_dask(scheduler: str, args: tuple, chunks: list):
    try:
        from distributed import Client, as_completed
    except ImportError:
        raise SceneError("--scheduler", "dask.distributed installed (pip install 'dask[distributed]')",
                         scheduler) from None
    try:
        client = Client(scheduler, timeout=SCHEDULER_TIMEOUT)
    except (OSError, TimeoutError, ValueError) as exc:
        raise SceneError("--scheduler", "the address of a running Dask scheduler", f"{scheduler} ({exc})") from None
    with client:
        futures = [client.submit(run_chunk, *args, c, pure=False) for c in chunks]
        try:
            for fut in as_completed(futures):
                yield fut.result()
        finally:
            client.cancel(futures)


def _progress(total: int, initial: int, enabled: bool):
    from tqdm import tqdm

    return tqdm(total=total, initial=initial, unit="run", file=sys.stderr, disable=not enabled, dynamic_ncols=True,
                desc="sweep")


# ---- files ---------------------------------------------------------------------------------
def _write_manifest(out: Path, sweep: Sweep, cases: list) -> None:
    path = out / "sweep.json"
    digest = sweep.digest()
    if path.is_file():
        try:
            old = json.loads(path.read_text()).get("scene_digest")
        except (OSError, ValueError, AttributeError):
            old = None
        if old not in (None, digest):
            raise SceneError("<file>", f"a sweep of the same base scene (this one is {sweep.file}); "
                             "choose another --out or remove this folder", "a sweep of another scene", str(path))
    doc = {"scene_file": sweep.file, "scene_digest": digest, "fixed": sweep.fixed, "axes": sweep.axes,
           "runs": sweep.runs, "cases": [{"run_id": rid, "params": p} for rid, p, _ in cases],
           "document": sweep.document}
    _atomic_write(path, json.dumps(doc, indent=1, sort_keys=True, default=str).encode())


def _write_summary(out: Path, rows: dict[str, dict[str, Any]], params: dict[str, dict[str, Any]],
                   keys: list[str], csv: bool) -> Path:
    """summary.parquet (and .csv) of the finished runs, sorted by run id, written atomically."""
    import pandas as pd

    ids = sorted(rows)
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
    _atomic_path(path, lambda tmp: frame.to_parquet(tmp, index=False, engine="pyarrow"))
    if csv:
        _atomic_path(out / "summary.csv", lambda tmp: frame.to_csv(tmp, index=False))
    return path


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


def _atomic_write(path: Path, data: bytes) -> None:
    def write(tmp: str) -> None:
        with open(tmp, "wb") as f:
            f.write(data)

    _atomic_path(path, write)


def _atomic_path(path: Path, write: Callable[[str], None]) -> None:
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    os.close(fd)
    try:
        write(tmp)
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise
