"""Reading nested dictionaries into typed values, with errors that name the key path.

Every scene value goes through a :class:`Reader`, which checks that the key is known,
the type is right and the number is finite and in range. Its errors are
:class:`~contactdyn.errors.SceneError`: file, key path, what was expected, what was found.
"""

from __future__ import annotations

import difflib
import math
import tomllib
from collections.abc import Iterable
from pathlib import Path
from typing import Any

import numpy as np

from .errors import SceneError

__all__ = ["Reader", "MISSING", "MAX_DEPTH", "MAX_MAGNITUDE", "MAX_TOML_BYTES", "read_toml", "check_depth"]

MISSING: Any = object()
MAX_MAGNITUDE = 1e12  #: |number| at most where a key sets no bound of its own: larger is a typo, not physics
MAX_DEPTH = 32  #: nesting of tables and arrays at most (a scene uses 5)
MAX_TOML_BYTES = 16 * 2**20  #: a scene or sweep file larger than this is refused


def read_toml(path: Path, what: str = "scene file") -> dict[str, Any]:
    """Read a TOML file; every failure (unreadable, too large, invalid, too deep) is a SceneError naming it."""
    file = str(path)
    try:
        size = path.stat().st_size
        if size > MAX_TOML_BYTES:
            raise SceneError("<file>", f"a {what} of at most {MAX_TOML_BYTES // 2**20} MB", f"{size} bytes", file)
        document = tomllib.loads(path.read_text())
    except tomllib.TOMLDecodeError as exc:
        raise SceneError("<file>", "valid TOML", str(exc), file) from None
    except RecursionError:
        raise SceneError("<file>", f"tables and arrays nested at most {MAX_DEPTH} deep", "deeper", file) from None
    except OSError as exc:
        raise SceneError("<file>", f"a readable {what}", exc.strerror or str(exc), file) from None
    except UnicodeDecodeError as exc:
        raise SceneError("<file>", "UTF-8 text", str(exc), file) from None
    check_depth(document, "<file>", file)
    return document


def check_depth(value: Any, where: str, file: str | None = None) -> None:
    """Refuse values nested deeper than MAX_DEPTH (copies, hashes and messages recurse through them)."""
    level = [value]
    for _ in range(MAX_DEPTH + 1):
        level = [v for item in level if isinstance(item, dict | list)
                 for v in (item.values() if isinstance(item, dict) else item)]
        if not level:
            return
    raise SceneError(where, f"tables and arrays nested at most {MAX_DEPTH} deep", "deeper", file)


class Reader:
    """A view of one table of a scene, at a key path, inside a file."""

    def __init__(self, data: Any, path: str = "", file: str | None = None):
        self.path, self.file = path, file
        if not isinstance(data, dict):
            raise SceneError(path or "<top>", "a table", data, file)
        self.data: dict[str, Any] = data
        self._used: set[str] = set()

    def key(self, name: str) -> str:
        return f"{self.path}.{name}" if self.path else name

    def error(self, name: str, expected: str, found: object) -> SceneError:
        return SceneError(self.key(name), expected, found, self.file)

    def has(self, name: str) -> bool:
        return name in self.data

    def raw(self, name: str, default: Any = MISSING) -> Any:
        self._used.add(name)
        if name not in self.data:
            if default is MISSING:
                raise self.error(name, "a value (required key is missing)", "nothing")
            return default
        return self.data[name]

    def sub(self, name: str, default: Any = MISSING) -> Reader:
        value = self.raw(name, {} if default is MISSING else default)
        if not isinstance(value, dict):
            raise self.error(name, "a table", value)
        return Reader(value, self.key(name), self.file)

    def tables(self, name: str) -> list[Reader]:
        """An array of tables (``[[name]]``), possibly empty."""
        value = self.raw(name, [])
        if not isinstance(value, list):
            raise self.error(name, "an array of tables", value)
        return [Reader(v, f"{self.key(name)}[{i}]", self.file) for i, v in enumerate(value)]

    def named_tables(self, name: str) -> dict[str, Reader]:
        """A table of tables (``[name.foo]``, ``[name.bar]``)."""
        parent = self.sub(name, {})
        return {k: parent.sub(k) for k in parent.data} if parent.data else {}

    def float(self, name: str, default: Any = MISSING, *, lo: float | None = None, hi: float | None = None,
              lo_open: bool = False, unit: str = "") -> float:
        value = self.raw(name, default)
        if value is None and default is None:
            return None  # type: ignore[return-value]
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise self.error(name, f"a number{_unit(unit)}", value)
        value = float(value)
        unbounded = default is not MISSING and default == math.inf  # inf means "no bound" here
        if math.isnan(value) or (math.isinf(value) and not (unbounded and value > 0)):
            raise self.error(name, f"a finite number{_unit(unit)}", value)
        if hi is None and math.isfinite(value) and abs(value) > MAX_MAGNITUDE:
            raise self.error(name, f"a number of magnitude <= {MAX_MAGNITUDE:g}{_unit(unit)}", value)
        if lo is not None and (value < lo or (lo_open and value == lo)):
            op = ">" if lo_open else ">="
            raise self.error(name, f"a number {op} {lo:g}{_unit(unit)}", value)
        if hi is not None and value > hi:
            raise self.error(name, f"a number <= {hi:g}{_unit(unit)}", value)
        return value

    def int(self, name: str, default: Any = MISSING, *, lo: int | None = None) -> int:
        value = self.raw(name, default)
        if isinstance(value, bool) or not isinstance(value, int):
            raise self.error(name, "an integer", value)
        if lo is not None and value < lo:
            raise self.error(name, f"an integer >= {lo}", value)
        return value

    def bool(self, name: str, default: Any = MISSING) -> bool:
        value = self.raw(name, default)
        if not isinstance(value, bool):
            raise self.error(name, "true or false", value)
        return value

    def str(self, name: str, default: Any = MISSING, *, choices: Iterable[str] | None = None) -> str:
        value = self.raw(name, default)
        if not isinstance(value, str):
            raise self.error(name, "a string", value)
        if choices is not None:
            choices = list(choices)
            if value not in choices:
                close = difflib.get_close_matches(value, choices, n=1)
                hint = f" (did you mean {close[0]!r}?)" if close else ""
                raise self.error(name, f"one of {choices}{hint}", value)
        return value

    def vector(self, name: str, default: Any = MISSING, *, size: int | None = None, unit: str = "",
               unit_norm: bool = False) -> np.ndarray:
        value = self.raw(name, default)
        ok = isinstance(value, list | tuple | np.ndarray) and all(
            isinstance(x, int | float) and not isinstance(x, bool) for x in value
        )
        if not ok or (size is not None and len(value) != size):
            what = f"a list of {size} numbers" if size is not None else "a list of numbers"
            raise self.error(name, what + _unit(unit), value)
        arr = np.asarray(value, dtype=float)
        if not np.all(np.isfinite(arr)):
            raise self.error(name, "finite numbers" + _unit(unit), value)
        if np.any(np.abs(arr) > MAX_MAGNITUDE):
            raise self.error(name, f"numbers of magnitude <= {MAX_MAGNITUDE:g}{_unit(unit)}", value)
        if unit_norm:
            norm = float(np.linalg.norm(arr))
            if norm < 1e-12:
                raise self.error(name, "a non-zero direction vector", value)
            arr = arr / norm
        return arr

    def finish(self) -> None:
        """Reject keys nobody read, suggesting the closest known one."""
        for name in self.data:
            if name not in self._used:
                close = difflib.get_close_matches(name, sorted(self._used), n=1)
                hint = f"; did you mean {close[0]!r}?" if close else ""
                known = ", ".join(sorted(self._used)) or "none"
                raise SceneError(self.key(name), f"a known key ({known}){hint}", "an unknown key", self.file)


def _unit(unit: str) -> str:
    return f" [{unit}]" if unit else ""
