"""Where the package's compiled code is cached: one directory per build of the package, so no stale code is loaded.

numba's ``cache=True`` checks a cached function only against its own source file (mtime and size): a
change to a compiled function it calls (in ``linalg.py``, say), or an upgrade that leaves a file's
size and time alike, would load old machine code. Here the cache directory is keyed instead: KEY =
``contactdyn-<version>-<hash>``, the hash being the first HASH_CHARS hex digits of SHA-256 over the package's
place and every compiled module's path, time and source (the modules that take :func:`njit` from here:
:func:`key`). An edit to any of them, another place or another version starts a fresh directory; nothing ever
needs deleting by hand. (numba also freezes the global constants a compiled function reads: they live in compiled
modules, so the hash covers them; ``tests/test_compile_cache.py`` checks that no compiled function reads one from
elsewhere.)

The directory: ``$NUMBA_CACHE_DIR/KEY`` when the user set numba's NUMBA_CACHE_DIR, else
``$XDG_CACHE_HOME/contactdyn/numba/KEY`` (``~/.cache/contactdyn/numba/KEY``), else, where that cannot
be written, ``<tempdir>/contactdyn-numba-<uid>/KEY``. Sibling keys unused for STALE_AFTER days are
removed (a directory's mtime is refreshed by each process that uses it).

numba saves a compiled function to its cache by reading the function's index, adding the entry and writing it
back, with no lock: two processes saving two signatures of one function at once (a first run and its leaves'
helper, a build and a run; :mod:`contactdyn.first_run`) could give both one data file, and a later load the
other's code. In the package's directory each save holds an exclusive lock on its index (:func:`locked_save`,
POSIX ``flock``; elsewhere as numba does it).

Compiled modules decorate with :func:`njit` from here instead of numba's: numba's own ``njit``, with
``numba.config.CACHE_DIR`` (read when a cached function is decorated) pointed at the directory only
while the function is decorated, so the user's own numba functions keep caching where they did. Every
numba compile of the package's functions, wherever a run triggers it, is a block of the compile notice
(:mod:`contactdyn.numerics.notice`, by numba's ``numba:compile`` events): a first run says once that it compiles.
This module is imported only by compiled modules: ``contactdyn --help`` never imports numba.
"""

from __future__ import annotations

import ast
import contextlib
import functools
import hashlib
import importlib.util
import os
import re
import shutil
import sys
import sysconfig
import tempfile
import time
from collections.abc import Callable, Mapping
from pathlib import Path

import numba
from numba.core import caching, event

from .. import __version__
from . import notice

__all__ = ["njit", "cfunc", "directory", "cache_dir", "key", "compiled_modules", "CompileNotice", "PACKAGE",
           "locked_save", "user_modules", "user_sources", "sources_key"]

PACKAGE = Path(__file__).resolve().parents[1]  #: the package's source folder (contactdyn/)
HASH_CHARS = 12  #: [hex digits] of the source hash in KEY
STALE_AFTER = 30.0  #: [days] a sibling key unused this long is removed
clock = time.time  #: [s] since the epoch: the age of a key is measured against it (a test replaces it)
#: a compiled module's mark: a top-level import from here (a line of its own, unindented; not a mention in a comment or
#: docstring, not a function's local import)
_MARK = re.compile(r"^from \.+(?:\w+\.)*compile_cache import ", re.MULTILINE)


def compiled_modules(package: Path = PACKAGE) -> list[Path]:
    """The package's modules that compile functions (import :func:`njit` or :func:`cfunc` from here at their top
    level: :data:`_MARK`), sorted."""
    return sorted(p for p in package.rglob("*.py")
                  if p.name != "compile_cache.py" and _MARK.search(p.read_text("utf-8")))


def key(package: Path = PACKAGE, version: str = __version__) -> str:
    """``contactdyn-<version>-<hash of the package's place, its compiled modules' paths, times and sources>``.

    numba keys each cached function by its source file's absolute path and time: another checkout, or a reinstall of
    the same sources, finds none of this one's code. Their own key gives them their own directory, so a first run
    there is a first run (``contactdyn.first_run``: its kinds' markers live beside the code), not a foreground
    compile behind a marker that says "built"."""
    digest = hashlib.sha256(str(package.resolve()).encode() + b"\0")
    for path in compiled_modules(package):
        digest.update(path.relative_to(package).as_posix().encode() + b"\0" + path.read_bytes() + b"\0"
                      + str(path.stat().st_mtime_ns).encode() + b"\0")
    return f"contactdyn-{version}-{digest.hexdigest()[:HASH_CHARS]}"


def _root(environ: Mapping[str, str]) -> Path | None:
    """The folder the keys live in: the user's NUMBA_CACHE_DIR, else the user's cache folder (None: no home)."""
    if environ.get("NUMBA_CACHE_DIR"):
        return Path(environ["NUMBA_CACHE_DIR"]).expanduser()
    try:
        user = Path(environ["XDG_CACHE_HOME"]) if environ.get("XDG_CACHE_HOME") else Path.home() / ".cache"
    except RuntimeError:  # no HOME and no user entry
        return None
    return user / "contactdyn" / "numba"


def _writable(folder: Path) -> bool:
    try:
        folder.mkdir(parents=True, exist_ok=True)
        with tempfile.TemporaryFile(dir=folder):
            return True
    except OSError:
        return False


def _prune(root: Path, keep: str) -> None:
    """Remove the keys in ``root`` other than ``keep`` that no process used for STALE_AFTER days."""
    oldest = clock() - STALE_AFTER * 86400.0  # [s] since the epoch
    for entry in root.glob("contactdyn-*"):
        try:
            if entry.name != keep and entry.is_dir() and entry.stat().st_mtime < oldest:
                shutil.rmtree(entry, ignore_errors=True)
        except OSError:
            continue


def cache_dir(environ: Mapping[str, str], package: Path = PACKAGE) -> Path:
    """The compiled code's directory for this environment and package (created; see the module's docstring)."""
    name = key(package)
    fallback = Path(tempfile.gettempdir()) / f"contactdyn-numba-{getattr(os, 'getuid', str)()}"
    for root in (_root(environ), fallback):
        if root is not None and _writable(root / name):
            with contextlib.suppress(OSError):
                os.utime(root / name)  # in use: not stale
            _prune(root, name)
            return root / name
    return fallback / name  # nothing writable: numba falls back to its own locations (as without this module)


@functools.cache
def directory() -> Path:
    """This process's compiled-code directory (found once)."""
    return cache_dir(os.environ)


#: where the standard library and installed packages live: a module there is not a user's own
_INSTALLED = tuple({Path(p).resolve() for name, p in sysconfig.get_paths().items()
                    if name in ("stdlib", "platstdlib", "purelib", "platlib")})


def _user_file(module) -> Path | None:
    """The source file of a user's own module (outside this package, the standard library and installed
    packages), else None."""
    file = getattr(module, "__file__", None)
    if not file or not file.endswith(".py") or not os.path.isfile(file):
        return None
    path = Path(file).resolve()
    if path.is_relative_to(PACKAGE) or any(path.is_relative_to(p) for p in _INSTALLED):
        return None
    return path


def _imports(source: bytes, package: str | None) -> set[str]:
    """The module names a module's source imports and their packages (``import a.b``: a.b and a; ``from .m import
    x``: the resolved m, its packages, and m.x, which may be a module), wherever they stand in it."""
    try:
        tree = ast.parse(source)
    except (SyntaxError, ValueError):
        return set()
    names: set[str] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            found = [alias.name for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            try:
                base = importlib.util.resolve_name("." * node.level + (node.module or ""), package) \
                    if node.level else node.module or ""
            except (ImportError, ValueError):
                continue
            found = [f"{base}.{alias.name}" for alias in node.names]
        else:
            continue
        for name in found:  # the name and its packages
            parts = name.split(".")
            names.update(".".join(parts[:i]) for i in range(1, len(parts) + 1))
    return names


def user_modules(module) -> list:
    """The user's own modules ``module`` depends on: itself and, transitively, the user's own modules it imports
    (already imported: :data:`sys.modules`), each after those it imports (``module`` last; [] if it is not a user's
    own)."""
    order: list = []
    seen: set[Path] = set()

    def visit(m) -> None:
        path = _user_file(m)
        if path is None or path in seen:
            return
        seen.add(path)
        for name in sorted(_imports(path.read_bytes(), getattr(m, "__package__", None))):
            if name in sys.modules:
                visit(sys.modules[name])
        order.append(m)

    visit(module)
    return order


def user_sources(function: Callable) -> dict[Path, bytes]:
    """The sources a user's compiled function depends on, path -> source: the files of :func:`user_modules` of its
    module.

    numba keys a cached function by its own file alone and freezes the globals it reads: a constant or a compiled
    helper imported from another of the user's files would stay as it was when cached."""
    modules = user_modules(sys.modules.get(getattr(function, "__module__", None) or ""))
    return {path: path.read_bytes() for path in (_user_file(m) for m in modules)}


def sources_key(function: Callable) -> str:
    """``user-<hash>``: a subdirectory of :func:`directory` for a user's compiled function, keyed by the sources it
    depends on (:func:`user_sources`): an edit of any of them compiles it again."""
    digest = hashlib.sha256()
    for path, source in sorted(user_sources(function).items()):
        digest.update(str(path).encode() + b"\0" + source + b"\0")
    return f"user-{digest.hexdigest()[:HASH_CHARS]}"


@contextlib.contextmanager
def _cached_here(cache: bool, under: str | None = None):
    """numba's cache directory set to :func:`directory` (its subdirectory ``under``) while a cached function is
    decorated (where numba reads it), then the user's setting again."""
    if not cache:
        yield
        return
    saved = numba.config.CACHE_DIR
    numba.config.CACHE_DIR = str(directory() / under if under else directory())
    try:
        yield
    finally:
        numba.config.CACHE_DIR = saved


def cfunc(signature, under: str | None = None, **options) -> Callable:
    """numba's ``cfunc(signature, **options)``; with ``cache=True`` its cache lives in :func:`directory` (its
    subdirectory ``under``)."""
    def decorate(function: Callable) -> Callable:
        with _cached_here(options.get("cache", False), under):
            return numba.cfunc(signature, **options)(function)

    return decorate


def njit(*signatures, under: str | None = None, **options) -> Callable:
    """numba's ``njit(*signatures, **options)``; with ``cache=True`` its cache lives in :func:`directory` (its
    subdirectory ``under``)."""
    def decorate(function: Callable) -> Callable:
        with _cached_here(options.get("cache", False), under):
            return numba.njit(*signatures, **options)(function)

    if len(signatures) == 1 and callable(signatures[0]):  # @njit, or njit(function, cache=True)
        function, signatures = signatures[0], ()
        return decorate(function)
    return decorate


class CompileNotice(event.Listener):
    """numba's compiles of the package's functions as blocks of :mod:`contactdyn.numerics.notice` (others ignored)."""

    WHAT = "the simulator's compiled code and this scene's laws"

    @staticmethod
    def _ours(e: event.Event) -> bool:
        function = getattr((e.data or {}).get("dispatcher"), "py_func", None)
        return (getattr(function, "__module__", None) or "").startswith("contactdyn.")

    def on_start(self, e: event.Event) -> None:
        if self._ours(e):
            notice.begin(notice.subject(self.WHAT))

    def on_end(self, e: event.Event) -> None:
        if self._ours(e):
            notice.end()


event.register("numba:compile", CompileNotice())


def locked_save(save: Callable) -> Callable:
    """numba's ``IndexDataCacheFile.save`` holding an exclusive lock (``<index>.lock``, POSIX ``flock``) while it
    reads, extends and writes the index and writes the data, where the index is in :func:`directory`; elsewhere, or
    without ``fcntl`` (Windows), a lock file or a file system that locks, as it is."""
    try:
        import fcntl
    except ImportError:  # (Windows)
        return save

    @functools.wraps(save)
    def locked(self, key, data):
        if not str(self._cache_path).startswith(str(directory())):
            return save(self, key, data)
        try:
            lock = open(f"{self._index_path}.lock", "a")  # noqa: SIM115 (closed below, after the unlock)
        except OSError:
            return save(self, key, data)
        with lock:
            try:
                fcntl.flock(lock, fcntl.LOCK_EX)
            except OSError:  # (a file system without locks: as numba does it)
                return save(self, key, data)
            try:
                return save(self, key, data)
            finally:
                fcntl.flock(lock, fcntl.LOCK_UN)

    locked.holds_lock = True  # (wrapped once: a second flock of the same file in this process would wait forever)
    return locked


if not getattr(caching.IndexDataCacheFile.save, "holds_lock", False):
    caching.IndexDataCacheFile.save = locked_save(caching.IndexDataCacheFile.save)
