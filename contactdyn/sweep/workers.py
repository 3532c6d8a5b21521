"""A sweep's worker processes: they end with the sweep, and a run that kills its process is recorded.

Every worker (pool worker or a run's own process) starts with :func:`worker_init`:

- Ctrl-C reaches the whole process group: only the parent handles it (it stops the workers);
- ``PR_SET_PDEATHSIG``: the kernel sends SIGKILL when the worker's parent (the forkserver,
  which itself exits when the sweep does) ends;
- a watchdog thread waits on a pidfd of the sweep's own process and kills the worker the
  moment that process ends, however it ends (SIGTERM, SIGKILL, a crash).

So no worker outlives the sweep by more than a scheduling delay, and none writes a run
after it. :func:`run_isolated` runs each given run in a process of its own, so that a run
whose process dies (a segfault in a library, the OOM killer) is recorded as failed with the
signal, and the others go on.
"""

from __future__ import annotations

import os
import signal
import threading
import time
from collections.abc import Callable, Iterator
from multiprocessing.connection import wait
from pathlib import Path
from typing import Any

from ..errors import signal_name
from .store import done_row, record_failure

__all__ = ["worker_init", "run_isolated", "signal_text"]

_PR_SET_PDEATHSIG = 1  #: from <linux/prctl.h>
WATCH_POLL = 0.5  #: [s] polling period of the watchdog where pidfd_open is unavailable


def worker_init(sweep_pid: int) -> None:
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    _die_with_parent()
    threading.Thread(target=_watch, args=(sweep_pid,), name="sweep-watchdog", daemon=True).start()


def _die_with_parent() -> None:
    try:
        import ctypes

        ctypes.CDLL(None, use_errno=True).prctl(_PR_SET_PDEATHSIG, signal.SIGKILL, 0, 0, 0)
    except (OSError, AttributeError):  # not Linux: the watchdog alone
        pass


def _watch(pid: int) -> None:
    """Return never while ``pid`` lives; kill this process once it has ended."""
    try:
        fd = os.pidfd_open(pid)
    except ProcessLookupError:
        fd = None  # already gone
    except (OSError, AttributeError):
        fd = -1  # no pidfd on this system: poll
    if fd is not None and fd >= 0:
        import select

        select.select([fd], [], [])  # readable once the process has exited
    elif fd == -1:
        while _alive(pid):
            time.sleep(WATCH_POLL)
    os.kill(os.getpid(), signal.SIGKILL)


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def signal_text(exitcode: int | None) -> str:
    """How a process ended, for a run's error message."""
    if exitcode is not None and exitcode < 0:
        return f"killed by {signal_name(-exitcode)}"
    return f"exited with code {exitcode}"


def _isolated_run(run_chunk: Callable, document: dict[str, Any], file: str | None, runs_dir: str, rid: str,
                  overrides: dict[str, Any], sweep_pid: int) -> None:
    worker_init(sweep_pid)
    run_chunk(document, file, runs_dir, [(rid, overrides)])


def run_isolated(ctx, run_chunk: Callable, args: tuple, tasks: list[tuple[str, dict[str, Any]]], n_workers: int
                 ) -> Iterator[list[dict[str, Any]]]:
    """Run each task [(id, overrides)] without files in a process of its own, ``n_workers`` at a time.

    ``run_chunk`` is :func:`contactdyn.sweep.execute.run_chunk` (passed in: no import back).

    Yields one row per run: the run's own (from its files) or, if its process died, a failed
    row naming the signal.
    """
    document, file, runs_dir = args
    queue = list(tasks)
    running: dict[int, tuple[Any, str, dict[str, Any], float]] = {}
    try:
        while queue or running:
            while queue and len(running) < max(1, n_workers):
                rid, overrides = queue.pop(0)
                row = done_row(Path(runs_dir), rid, {})
                if row is not None:  # finished before its chunk's worker died
                    yield [row]
                    continue
                proc = ctx.Process(target=_isolated_run, daemon=True,
                                   args=(run_chunk, document, file, runs_dir, rid, overrides, os.getpid()))
                proc.start()
                running[proc.sentinel] = (proc, rid, overrides, time.perf_counter())
            for sentinel in wait(list(running)):
                proc, rid, overrides, t0 = running.pop(sentinel)
                proc.join()
                row = done_row(Path(runs_dir), rid, {}) if proc.exitcode == 0 else None
                if row is None:
                    error = f"the run's process {signal_text(proc.exitcode)}"
                    row = record_failure(Path(runs_dir), rid, overrides, "failed", error, time.perf_counter() - t0)
                yield [row]
    finally:
        for proc, *_ in running.values():
            proc.kill()
            proc.join()
