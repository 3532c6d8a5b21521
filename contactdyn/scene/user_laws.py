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
"""

from __future__ import annotations

import importlib
import re
import sys
from pathlib import Path

from ..errors import SceneError

__all__ = ["IMPORTED", "MODULE_NAME", "import_scene_modules", "load_entry_points", "refuse_imports"]

MODULE_NAME = r"[A-Za-z_][A-Za-z0-9_]*(\.[A-Za-z_][A-Za-z0-9_]*)*"  #: a module name, no path
IMPORTED: dict[str, str] = {}  #: module -> the file it came from, in the order imported (this process)
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
                             f"{ep.value}: {type(exc).__name__}: {exc}") from None
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
            _record(name, sys.modules[name])
            continue
        added = folder is not None and folder not in sys.path
        if added:
            sys.path.insert(0, folder)
        try:
            module = importlib.import_module(name)
        except Exception as exc:  # noqa: BLE001 (the user's module failed: say which and why)
            raise SceneError("imports", "importable modules (next to the scene file or on sys.path)",
                             f"{name}: {type(exc).__name__}: {exc}", file) from None
        finally:
            if added:
                sys.path.remove(folder)
        _record(name, module)
    return list(names)


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
