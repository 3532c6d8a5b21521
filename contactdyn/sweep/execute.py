"""Running a sweep: chunks of runs in this process, on a local process pool, or on a Dask cluster."""

from __future__ import annotations

import math
import os
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from ..errors import ContactdynError, SceneError, numerical_errors
from ..scene.scene_file import parse_scene
from .plan import Sweep, check_sweep
from .store import STATUSES, done_row, lock_out, record_failure, result_row, write_manifest
from .summary import Summary, cached_rows
from .workers import run_isolated, worker_init

__all__ = ["NUMERICAL", "SweepReport", "run_sweep", "run_chunk", "process_pool", "stop_pool"]

NUMERICAL: tuple[type[Exception], ...] = numerical_errors()  #: (contactdyn.errors.numerical_errors)
CHUNKS_PER_WORKER = 4  #: aim for this many chunks per worker (load balance vs per-chunk cost)
MAX_CHUNK = 32  #: runs per chunk at most, so a run's row reaches the summary's part files soon
SCHEDULER_TIMEOUT = 10.0  #: [s] to connect to a Dask scheduler
PRELOAD = ("contactdyn.sweep", "contactdyn.simulate")  #: modules the workers' forkserver imports once


def run_chunk(document: dict[str, Any], file: str | None, runs_dir: str, tasks: list[tuple[str, dict[str, Any]]]
              ) -> list[dict[str, Any]]:
    """Run ``tasks`` [(id, overrides)] one after the other; write each result; return their rows.

    Runs in a worker process (pool or Dask); results go straight to ``runs_dir`` (which
    Dask workers must see: a shared file system).
    """
    return [_run_one(document, file, Path(runs_dir), rid, overrides) for rid, overrides in tasks]


def _run_one(document: dict[str, Any], file: str | None, runs_dir: Path, rid: str, overrides: dict[str, Any]
             ) -> dict[str, Any]:
    from ..simulate import simulate, without_warning_lines

    wall0 = time.perf_counter()
    try:
        with without_warning_lines():  # (each run's warnings are in its saved result, not lines on the console)
            result = simulate(parse_scene(document, overrides, file))
    except (ContactdynError, *NUMERICAL) as exc:
        status, error = "failed", f"{type(exc).__name__}: {exc}"
    except Exception as exc:  # noqa: BLE001 (a bug or an uncaught blow-up: recorded, the sweep goes on)
        status, error = "crashed", f"{type(exc).__name__}: {exc}"
    else:
        result.save(runs_dir / rid)
        return result_row(rid, result)
    return record_failure(runs_dir, rid, overrides, status, error, time.perf_counter() - wall0)


@dataclass
class SweepReport:
    out: Path
    total: int  #: runs in the sweep
    skipped: int  #: already finished before this call (resumed)
    counts: dict[str, int]  #: runs per status
    wall_s: float  #: [s] wall time of this call
    summary: Path
    #: finished runs whose results hold sanity, outcome or check warnings (the summary's metrics ``warnings`` and
    #: ``check_violations``)
    warned: int = 0

    def as_dict(self) -> dict[str, Any]:
        return {"out": str(self.out), "total": self.total, "skipped": self.skipped, "counts": self.counts,
                "wall_s": self.wall_s, "summary": str(self.summary), "warned": self.warned}


def run_sweep(sweep: Sweep, out: str | Path, *, workers: int | None = None, scheduler: str | None = None,
              chunk: int | None = None, csv: bool = False, retry_failed: bool = False, progress: bool = False,
              check: bool = True) -> SweepReport:
    """Run every case not finished yet; write results and the summary under ``out``.

    ``workers``: local processes (None: all cores, 0: this process); ``scheduler``: a Dask
    scheduler address instead (chunks of ``chunk`` runs are the tasks either way).
    """
    wall0 = time.perf_counter()
    if check:  # bad input touches no file
        check_sweep(sweep)
    out = Path(out).absolute()  # the workers' working directory may differ (Dask)
    runs_dir = out / "runs"
    runs_dir.mkdir(parents=True, exist_ok=True)
    with lock_out(out):  # released when the sweep ends, however it ends
        for stale in runs_dir.glob(".*.tmp"):  # left by a killed writer (we hold the lock: no writer is live)
            stale.unlink(missing_ok=True)
        cases = sweep.cases()
        write_manifest(out, sweep, cases)
        rows = _finished_rows(out, runs_dir, cases, retry_failed)
        todo = [(rid, overrides) for rid, _, overrides in cases if rid not in rows]
        skipped = len(rows)
        summary = Summary(out, rows, {rid: p for rid, p, _ in cases}, sweep.parameter_keys(), csv)
        summary.rewrite()  # merges what a killed sweep left in part files
        n_workers = (os.cpu_count() or 1) if workers is None else max(0, workers)
        size = chunk or max(1, min(MAX_CHUNK, math.ceil(len(todo) / (CHUNKS_PER_WORKER * max(1, n_workers)))))
        chunks = [todo[i:i + size] for i in range(0, len(todo), size)]
        bar = _progress(len(cases), skipped, progress)
        failed = sum(r["status"] != "ok" for r in rows.values())
        try:
            for chunk_rows in _execute(sweep, runs_dir, chunks, n_workers, scheduler):
                summary.add(chunk_rows)
                failed += sum(r["status"] != "ok" for r in chunk_rows)  # each run finishes once per call
                bar.update(len(chunk_rows))
                bar.set_postfix(failed=failed, refresh=False)
        finally:
            bar.close()
            if summary.pending:  # however the sweep ends (a SIGKILL aside: the next sweep merges the parts)
                summary.rewrite()
    counts = {s: sum(r["status"] == s for r in rows.values()) for s in STATUSES}
    warned = sum(_positive(r.get("warnings")) or _positive(r.get("check_violations")) for r in rows.values())
    return SweepReport(out, len(cases), skipped, counts, time.perf_counter() - wall0, summary.path, warned)


def _positive(count) -> bool:
    """A summary row's count above 0 (None, NaN or pandas' NA: a failed run's, which has none)."""
    try:
        return bool(count > 0)
    except TypeError:
        return False


def _finished_rows(out: Path, runs_dir: Path, cases: list, retry_failed: bool) -> dict[str, dict[str, Any]]:
    """Rows of the runs finished before this call (failed ones forgotten with ``retry_failed``)."""
    rows: dict[str, dict[str, Any]] = {}
    cache = cached_rows(out)
    for rid, _, _ in cases:
        if retry_failed and (runs_dir / f"{rid}.failed.json").is_file():
            (runs_dir / f"{rid}.failed.json").unlink()
        row = done_row(runs_dir, rid, cache)
        if row is not None:
            rows[rid] = row
    return rows


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
    yield from _execute_pool(args, chunks, n_workers)


def _execute_pool(args: tuple, chunks: list, n_workers: int):
    """Chunks on a process pool; the runs of chunks whose worker died go again, each in its own process."""
    from concurrent.futures import as_completed
    from concurrent.futures.process import BrokenProcessPool

    pool = process_pool(n_workers)
    broken: list = []
    try:
        futures = {}
        for c in chunks:
            try:
                futures[pool.submit(run_chunk, *args, c)] = c
            except BrokenProcessPool:  # a worker died while the chunks went in: the rest go again as well
                broken.extend(c)
        for fut in as_completed(futures):
            if isinstance(fut.exception(), BrokenProcessPool):  # a worker died: which run killed it is unknown
                broken.extend(futures[fut])
                continue
            yield fut.result()
    except BaseException:  # interrupted: stop the workers now (their results so far are whole files)
        stop_pool(pool)
        raise
    pool.shutdown(wait=True)
    if broken:
        yield from run_isolated(_forkserver(), run_chunk, args, broken, n_workers)


def process_pool(n_workers: int, preload: tuple[str, ...] = PRELOAD):
    """A local pool of ``n_workers`` processes for runs (sweeps, the fit's Jacobian columns).

    No fork of a (possibly threaded) parent: workers fork from a server that preloaded
    ``preload``; they end with this process and ignore Ctrl-C (:func:`.workers.worker_init`;
    the parent stops them with :func:`stop_pool`).
    """
    from concurrent.futures import ProcessPoolExecutor

    return ProcessPoolExecutor(max_workers=n_workers, mp_context=_forkserver(preload), initializer=worker_init,
                               initargs=(os.getpid(),))


def stop_pool(pool) -> None:
    """Stop a pool's workers now (interrupted or failed), dropping the queued tasks."""
    for proc in list((getattr(pool, "_processes", None) or {}).values()):
        proc.terminate()
    pool.shutdown(wait=False, cancel_futures=True)


def _forkserver(preload: tuple[str, ...] = PRELOAD):
    """The forkserver context, preloading ``preload`` (workers fork from it, not from this process)."""
    import multiprocessing

    ctx = multiprocessing.get_context("forkserver")
    ctx.set_forkserver_preload(list(preload))
    return ctx


def _execute_dask(scheduler: str, args: tuple, chunks: list):
    try:
        from distributed import Client, KilledWorker, as_completed
    except ImportError:
        raise SceneError("--scheduler", "dask.distributed installed (pip install 'dask[distributed]')",
                         scheduler) from None
    try:
        client = Client(scheduler, timeout=SCHEDULER_TIMEOUT)
    except (OSError, TimeoutError, ValueError) as exc:
        raise SceneError("--scheduler", "the address of a running Dask scheduler", f"{scheduler} ({exc})") from None
    broken: list = []
    with client:
        futures = {client.submit(run_chunk, *args, c, pure=False): c for c in chunks}
        try:
            for fut in as_completed(list(futures)):
                try:
                    rows = fut.result()
                except KilledWorker:  # its workers died: which run killed them is unknown
                    broken.extend(futures[fut])
                    continue
                yield rows
        finally:
            client.cancel(list(futures))
    if broken:  # each suspect alone in a local process, to record the culprit with its signal
        yield from run_isolated(_forkserver(), run_chunk, args, broken, os.cpu_count() or 1)


def _progress(total: int, initial: int, enabled: bool):
    from tqdm import tqdm

    return tqdm(total=total, initial=initial, unit="run", file=sys.stderr, disable=not enabled, dynamic_ncols=True,
                desc="sweep")
