"""Reading nested dictionaries into typed values, with errors that name the key path.

Every scene value goes through a :class:`Reader`, which checks that the key is known,
the type is right and the number is finite and in range. Its errors are
:class:`~contactdyn.errors.SceneError`: file, key path, what was expected, what was found.
"""

from __future__ import annotations

import difflib
import math
from collections.abc import Iterable
from typing import Any

import numpy as np

from .errors import SceneError

__all__ = ["Reader", "MISSING"]

MISSING: Any = object()


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
        if math.isnan(value) or (math.isinf(value) and not (hi is None and value > 0)):
            raise self.error(name, f"a finite number{_unit(unit)}", value)
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
