"""A line on the terminal while something slow and silent happens: the fast path's first compilation.

A scene's first run with a given set of laws compiles their kernels (numba; cached next to the
package for later runs, keyed by its source): seconds to a couple of minutes on a loaded machine,
during which nothing else would be printed. :func:`compiling` prints one line to stderr when a
build is still running after NOTICE_AFTER seconds (once per process), so a first run never looks
like a hang; a cached build finishes before and prints nothing.
"""

from __future__ import annotations

import sys
import threading
from collections.abc import Iterator
from contextlib import contextmanager

__all__ = ["compiling", "NOTICE_AFTER"]

NOTICE_AFTER = 2.0  #: [s] a build running longer than this is announced
_said = threading.Event()  #: the line was printed in this process


@contextmanager
def compiling(what: str) -> Iterator[None]:
    """Announce ``what`` once if the block runs longer than NOTICE_AFTER seconds."""
    if _said.is_set():  # said once in this process: no timer
        yield
        return

    def say() -> None:
        if not _said.is_set():
            _said.set()
            print(f"contactdyn: compiling {what} (first run with these laws only: ~10 s to 2 min; "
                  "cached for later runs)...", file=sys.stderr, flush=True)

    timer = threading.Timer(NOTICE_AFTER, say)
    timer.daemon = True
    timer.start()
    try:
        yield
    finally:
        timer.cancel()
