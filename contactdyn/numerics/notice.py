"""A line on the terminal while something slow and silent happens: compiling the fast path.

A fresh install's first run compiles the package's numba functions (cached for later processes, see
:mod:`contactdyn.numerics.compile_cache`): seconds to minutes on a loaded machine, during which nothing else
would be printed. Every compile is a block: each numba compile of the package's functions (hooked by
``compile_cache`` on numba's compile events, so no call site is missed) and each mode's pipeline the loop
builds (:func:`compiling`). Once this process's blocks have run NOTICE_AFTER seconds in all, one line goes to
stderr, once per process, so a first run never looks like a hang; a run whose code is cached compiles
nothing and prints nothing.
"""

from __future__ import annotations

import sys
import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager

__all__ = ["compiling", "begin", "end", "about", "subject", "NOTICE_AFTER"]

NOTICE_AFTER = 2.0  #: [s] of compiling in one process before it is announced
clock = time.monotonic  #: [s] the clock the blocks are timed by (a test replaces it)


class _Watch:
    """This process's compile time so far and the announcement pending for the open block."""

    def __init__(self) -> None:
        self.lock = threading.RLock()
        self.depth = 0  #: blocks open (nested: a function compiled while a mode's pipeline is built)
        self.spent = 0.0  #: [s] in the closed outermost blocks
        self.started = 0.0  #: [s] clock() at the open outermost block's start
        self.said = False  #: the line was printed in this process
        self.timer: threading.Timer | None = None

    def begin(self, what: str) -> None:
        with self.lock:
            self.depth += 1
            if self.depth > 1:
                return
            self.started = clock()
            left = NOTICE_AFTER - self.spent  # [s]
            if self.said:
                return
            if left <= 0:
                self.say(what)
                return
            self.timer = threading.Timer(left, self.say, (what,))
            self.timer.daemon = True
            self.timer.start()

    def end(self) -> None:
        with self.lock:
            self.depth -= 1
            if self.depth:
                return
            self.spent += clock() - self.started
            if self.timer is not None:
                self.timer.cancel()
                self.timer = None

    def say(self, what: str) -> None:
        with self.lock:
            if self.said:
                return
            self.said = True
        print(f"contactdyn: compiling {what} (once: cached for later runs)...", file=sys.stderr, flush=True)


_watch = _Watch()


def begin(what: str) -> None:
    """A compile of ``what`` starts (blocks nest; the outermost one's ``what`` is announced)."""
    _watch.begin(what)


def end() -> None:
    """The innermost open compile ends."""
    _watch.end()


@contextmanager
def compiling(what: str) -> Iterator[None]:
    """Count the block as compiling ``what``: announced once this process has compiled NOTICE_AFTER seconds."""
    begin(what)
    try:
        yield
    finally:
        end()


_SUBJECTS: list[str] = []  #: what a run names the package's numba compiles (innermost last; none: the default)


def subject(default: str) -> str:
    """What the package's numba compiles are announced as now: the innermost :func:`about`, else ``default``."""
    return _SUBJECTS[-1] if _SUBJECTS else default


@contextmanager
def about(what: str) -> Iterator[None]:
    """Within the block, the package's numba compiles are announced as ``what`` (an interpreted run
    compiles only the leaves it runs compiled: it says so)."""
    _SUBJECTS.append(what)
    try:
        yield
    finally:
        _SUBJECTS.pop()
