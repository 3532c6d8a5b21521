"""A researcher's own laws, from their own modules: a scene's ``imports``, and installed packages.

A controller, a stage law, a friction law or a drive kind is registered by its module when the
module is imported (``@register`` of :mod:`contactdyn.laws.controllers`, ``@register_stage_law`` of
:mod:`contactdyn.laws.stage_laws`, ``@register_friction_law``, ``@register_drive_kind`` of
:mod:`contactdyn.laws.drive_kinds`). Two ways bring such a module in, everywhere a scene is read
(``run``, every worker of a sweep, ``fit``, ``view``, Python's ``parse_scene``):

- ``imports = ["my_laws"]`` at the top of a scene: module names (never file paths), looked up
  next to the scene file first, then on ``sys.path``; imported before the rest of the scene is
  read, so its ``controller.kind`` may name a law the module registers;
- the entry-point group ``contactdyn.laws`` of installed packages (``[project.entry-points.
  "contactdyn.laws"]`` in their ``pyproject.toml``), loaded once per process.

Importing runs code: ``contactdyn run`` prints each module it imported and from where
(:data:`IMPORTED`), and ``--no-imports`` (:func:`refuse_imports`) makes a scene that names
any an error (exit 2), for scenes received from others.

A process that reads scenes again (a notebook, a sweep's worker) imports a module again where its file, or a
file of the user's own that it imports, changed since: the scene runs the law as its file says now.
"""

from __future__ import annotations

import importlib
import os
import re
import sys
import sysconfig
import traceback
from contextlib import contextmanager
from pathlib import Path

from ..errors import ContactdynError, SceneError, first_line

__all__ = ["IMPORTED", "MODULE_NAME", "import_scene_modules", "load_entry_points", "refuse_imports"]

MODULE_NAME = r"[A-Za-z_][A-Za-z0-9_]*(\.[A-Za-z_][A-Za-z0-9_]*)*"  #: a module name, no path
IMPORTED: dict[str, str] = {}  #: module -> the file it came from, in the order imported (this process)
_SOURCES: dict[str, dict[Path, bytes]] = {}  #: a scene's module -> the sources it depends on, as imported
ENTRY_POINTS = "contactdyn.laws"  #: the entry-point group of installed law packages
_state = {"allowed": True, "entry_points": False}


def refuse_imports(refuse: bool = True) -> None:
    """``--no-imports`` (``refuse``): from now on a scene that names modules to import is an error (each command
    sets it: False allows them again)."""
    _state["allowed"] = not refuse


def load_entry_points() -> None:
    """Import every module of the ``contactdyn.laws`` entry points (once per process)."""
    if _state["entry_points"] or not _state["allowed"]:  # --no-imports: no third-party code either
        return
    _state["entry_points"] = True
    from importlib.metadata import entry_points

    for ep in entry_points(group=ENTRY_POINTS):
        try:
            module = importlib.import_module(ep.module)
        except Exception as exc:  # noqa: BLE001 (a broken package of laws names itself, it does not crash us)
            raise SceneError(f"entry point {ep.name}", f"an importable module of laws ({ENTRY_POINTS})",
                             _import_failure(ep.value, exc)) from None
        _record(ep.module, module)


def _record(name: str, module) -> None:
    """Remember where ``name`` came from (``contactdyn run`` prints it)."""
    IMPORTED.setdefault(name, str(getattr(module, "__file__", "?")))


def import_scene_modules(names: object, file: str | None) -> list[str]:
    """Import the modules a scene's ``imports`` names (next to ``file``, then on ``sys.path``); their names."""
    load_entry_points()
    if names in (None, []):
        return []
    if not isinstance(names, list) or not all(isinstance(n, str) and re.fullmatch(MODULE_NAME, n) for n in names):
        raise SceneError("imports", "a list of module names (like \"my_laws\"; no file paths)", names, file)
    if not _state["allowed"]:
        raise SceneError("imports", "no modules to import (--no-imports: this scene may not run code)", names, file)
    folder = str(Path(file).resolve().parent) if file else None
    for name in names:
        if name in sys.modules:
            _same_module(name, folder, file)
            _import_again_if_edited(name, file)
            _record(name, sys.modules[name])
            continue
        with _on_path([folder]), _naming_failure(name, file):
            module = importlib.import_module(name)
        _SOURCES[name] = _sources(module)
        _record(name, module)
    return list(names)


@contextmanager
def _on_path(folders: list[str | None]):
    """Inside: ``folders`` (those not on it yet) first on ``sys.path``."""
    added = [f for f in dict.fromkeys(folders) if f is not None and f not in sys.path]
    sys.path[:0] = added
    try:
        yield
    finally:
        for f in added:
            sys.path.remove(f)


@contextmanager
def _naming_failure(name: str, file: str | None):
    """Inside: the user's module ``name`` failing to import is a SceneError saying which and why."""
    try:
        yield
    except (Exception, SystemExit) as exc:  # noqa: BLE001 (the user's module failed, or exited: say which and why)
        raise SceneError("imports", "importable modules (next to the scene file or on sys.path)",
                         _import_failure(name, exc), file) from None


def _import_failure(name: str, exc: BaseException) -> ContactdynError:
    """What module ``name`` raised while it imported, as the error quotes it whole: ``my_laws: ValueError: <its
    message's first line> (my_laws.py, line 12)``, the file and line of the user's code that raised it (a syntax
    error's own; an installed package of laws: its own file from the package on; none where no frame is either: a
    module not found)."""
    message = first_line(exc.msg if isinstance(exc, SyntaxError) else str(exc))
    where = _raised_at(exc, name.split(":")[0].split(".")[0])
    return ContactdynError(f"{name}: {type(exc).__name__}" + (f": {message}" if message else "") +
                           (f" ({where})" if where else ""))


def _raised_at(exc: BaseException, top: str = "") -> str:
    """``file.py, line N`` where the user's code raised ``exc``: a syntax error's place, else the innermost frame of a
    file that is neither this package's nor Python's nor an installed package's (importlib's, numpy's); where there is
    none, the innermost of the installed package ``top`` being imported (a package of laws an entry point names:
    ``top/file.py, line N``); "" for none."""
    if isinstance(exc, SyntaxError):
        return f"{Path(exc.filename).name}, line {exc.lineno}" if exc.filename and exc.lineno else ""
    frames = [(frame.f_code.co_filename, line) for frame, line in traceback.walk_tb(exc.__traceback__)]
    theirs = [(f, line) for f, line in frames if not f.startswith(("<", *_not_users()))]
    if theirs:
        return f"{Path(theirs[-1][0]).name}, line {theirs[-1][1]}"
    own = [(inside, line) for f, line in frames if (inside := _in_package(Path(f), top))]
    return f"{own[-1][0]}, line {own[-1][1]}" if own else ""


def _in_package(path: Path, top: str) -> str:
    """``path`` from its package ``top`` on (``top/sub/file.py``; a module ``top.py``: its name); "" if not in it."""
    parts = path.parts
    if top and top in parts[:-1]:
        return "/".join(parts[len(parts) - 1 - parts[::-1].index(top):])
    return path.name if top and path.stem == top else ""


def _not_users() -> tuple[str, ...]:
    """The folders whose files are not the user's code: this package's, Python's, the installed packages'."""
    return tuple(str(Path(p)) + os.sep for p in {Path(__file__).resolve().parents[1], *map(sysconfig.get_path, (
        "stdlib", "platstdlib", "purelib", "platlib"))})


def _sources(module) -> dict[Path, bytes]:
    """The sources of the user's own modules ``module`` depends on (itself and those it imports), path -> source."""
    from ..numerics.compile_cache import user_modules  # (numba: not for a scene without imports)

    return {Path(m.__file__): Path(m.__file__).read_bytes() for m in user_modules(module)}


def _import_again_if_edited(name: str, file: str | None) -> None:
    """A module imported earlier in this process (a notebook, a sweep's worker) whose file, or a file of the user's
    it imports, changed since: imported again, each module after those it imports, so that its laws register
    anew (the same module replaces its own: :func:`~contactdyn.laws.params.claim_name`)."""
    from ..numerics.compile_cache import user_modules

    module = sys.modules[name]
    now = _sources(module)
    if _SOURCES.setdefault(name, now) == now:
        return
    modules = user_modules(module)
    with _on_path([str(Path(m.__file__).parent) for m in modules]), _naming_failure(name, file):
        for m in modules:
            importlib.reload(m)
    _SOURCES[name] = _sources(sys.modules[name])


def _same_module(name: str, folder: str | None, file: str | None) -> None:
    """A module already imported under ``name`` must be the one beside this scene, if one is there (a second
    scene's own ``my_laws.py`` cannot replace the first's in one process)."""
    if folder is None:
        return
    top = name.split(".")[0]
    here = [Path(folder) / f"{top}.py", Path(folder) / top / "__init__.py"]
    loaded = getattr(sys.modules[name], "__file__", None)
    if any(p.exists() for p in here) and loaded and Path(loaded).resolve().parent not in \
            (Path(folder).resolve(), (Path(folder) / top).resolve()):
        raise SceneError("imports", f"the module {name} beside the scene file (this process already imported "
                         f"another {name}, from {loaded})", name, file)
