"""Reading nested dictionaries into typed values, with errors that name the key path.

Every scene value goes through a :class:`Reader`, which checks that the key is known,
the type is right and the number is finite and in range. Its errors are
:class:`~contactdyn.errors.SceneError`: file, key path, what was expected, what was found.
"""

from __future__ import annotations

import math
import re
import sys
import tomllib
from collections.abc import Iterable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np

from ..errors import SceneError, UnknownKeyError, close_matches

__all__ = ["Reader", "MISSING", "MAX_DEPTH", "MAX_MAGNITUDE", "MAX_TOML_BYTES", "read_toml", "check_depth", "KeyRead",
           "recording"]

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


#: a ``str`` key with choices named like this selects a variant of its table (``kind = "task_pd"``)
VARIANT_KEYS = ("kind", "model", "law")


class KeyRead(NamedTuple):
    """One key read by a :class:`Reader`, as :func:`recording` collects it (the scene reference's raw data)."""

    pattern: str  #: key path with indices as ``[]`` and names of named tables as ``<table>``
    variant: tuple[str, ...]  #: the table's selectors in force, e.g. ``("kind = task_pd",)``
    #: "number", "integer", "boolean", "string", "list", "direction", "table", "tables", "named tables",
    #: "any" (read raw), "has" (only asked whether it is there)
    type: str
    default: Any  #: MISSING: required
    unit: str = ""
    lo: float | None = None
    hi: float | None = None
    lo_open: bool = False
    choices: tuple[str, ...] | None = None
    size: int | None = None
    meaning: str = ""  #: a declared parameter's own meaning (contactdyn.laws.params), else keys.MEANINGS says


class _Recording:
    def __init__(self) -> None:
        self.reads: list[KeyRead] = []
        self.names: dict[str, str] = {}  #: key path of a named table -> its pattern


_RECORDING: _Recording | None = None


@contextmanager
def recording() -> Iterator[list[KeyRead]]:
    """Collect every key any :class:`Reader` reads inside the block (how ``docs/scenes.md`` is made)."""
    global _RECORDING
    saved, _RECORDING = _RECORDING, _Recording()
    try:
        yield _RECORDING.reads
    finally:
        _RECORDING = saved


def _pattern(path: str) -> str:
    """``contact.tip.normal.environment[0].k`` -> ``contact.<contact>.normal.environment[].k``."""
    names = _RECORDING.names if _RECORDING else {}
    for prefix in sorted(names, key=len, reverse=True):
        if path == prefix or path.startswith(prefix + ".") or path.startswith(prefix + "["):
            path = names[prefix] + path[len(prefix):]
            break
    return _list_index_free(path)



def _list_index_free(path: str) -> str:
    """``phase[0].force.1`` -> ``phase[].force[]``: a list index, bracketed or dotted, becomes ``[]``."""
    return re.sub(r"\.\d+(?=\.|$)", "[]", re.sub(r"\[\d+\]", "[]", path))


class Reader:
    """A view of one table of a scene, at a key path, inside a file."""

    def __init__(self, data: Any, path: str = "", file: str | None = None):
        self.path, self.file = path, file
        if not isinstance(data, dict):
            raise SceneError(path or "<top>", "a table", data, file)
        self.data: dict[str, Any] = data
        self._used: set[str] = set()
        self._asked: set[str] = set()  #: keys looked for (has): known here even when absent
        self.variant: tuple[str, ...] = ()  #: selectors read so far (documentation only, see recording())

    def _note(self, name: str, type_: str, default: Any, **details: Any) -> None:
        if _RECORDING is not None:
            _RECORDING.reads.append(KeyRead(_pattern(self.key(name)), self.variant, type_, default, **details))

    def _child(self, data: Any, name: str) -> Reader:
        child = Reader(data, self.key(name), self.file)
        child.variant = self.variant
        return child

    def key(self, name: str) -> str:
        return f"{self.path}.{name}" if self.path else name

    def error(self, name: str, expected: str, found: object) -> SceneError:
        return SceneError(self.key(name), expected, found, self.file)

    def has(self, name: str) -> bool:
        self._note(name, "has", None)
        self._asked.add(name)
        return name in self.data

    def raw(self, name: str, default: Any = MISSING) -> Any:
        self._note(name, "any", default)
        self._used.add(name)
        if name not in self.data:
            if default is MISSING:
                raise self.missing(name, "a value (required key is missing)")
            return default
        return self.data[name]

    def missing(self, name: str, expected: str) -> SceneError:
        """The error of a required key that is missing, naming a key of the table nobody knows that is close to
        ``name``: ``expected …, the table has 'durration': a misspelling?``."""
        unknown = [k for k in self.data if k not in self._used and k not in self._asked]
        close = close_matches(name, unknown, n=1)
        hint = f"; the table has {close[0]!r}: a misspelling?" if close else ""
        return self.error(name, expected + hint, "nothing")

    def sub(self, name: str, default: Any = MISSING) -> Reader:
        self._note(name, "table", default)
        value = self.raw(name, {} if default is MISSING else default)
        if not isinstance(value, dict):
            raise self.error(name, "a table" + _fields(_pattern(self.key(name))), value)
        return self._child(value, name)

    def tables(self, name: str) -> list[Reader]:
        """An array of tables (``[[name]]``), possibly empty."""
        self._note(name, "tables", [])
        value = self.raw(name, [])
        if not isinstance(value, list) or not all(isinstance(v, dict) for v in value):
            raise self.error(name, "an array of tables" + _fields(_pattern(self.key(name)) + "[]"), value)
        readers = []
        for i, v in enumerate(value):
            readers.append(Reader(v, f"{self.key(name)}[{i}]", self.file))
            readers[-1].variant = self.variant
        return readers

    def named_tables(self, name: str) -> dict[str, Reader]:
        """A table of tables (``[name.foo]``, ``[name.bar]``)."""
        self._note(name, "named tables", {})
        parent = self.sub(name, {})
        if _RECORDING is not None:
            for k in parent.data:
                _RECORDING.names[parent.key(k)] = f"{_pattern(parent.path)}.<{name}>"
        return {k: parent.sub(k) for k in parent.data} if parent.data else {}

    def float(self, name: str, default: Any = MISSING, *, lo: float | None = None, hi: float | None = None,
              lo_open: bool = False, unit: str = "", meaning: str = "") -> float:
        self._note(name, "number", default, unit=unit, lo=lo, hi=hi, lo_open=lo_open, meaning=meaning)
        value = self.raw(name, default)
        if value is None and default is None:
            return None  # type: ignore[return-value]
        if not _is_number(value):
            raise self.error(name, f"a number{_unit(unit)}", value)
        if _beyond_float(value):
            raise self.error(name, f"a finite number{_unit(unit)}", value)
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

    def int(self, name: str, default: Any = MISSING, *, lo: int | None = None, hi: int | None = None,
            unit: str = "") -> int:
        self._note(name, "integer", default, unit=unit, lo=lo, hi=hi)
        given = value = self.raw(name, default)  # (a message shows what was given: 1e+308, not its 309 digits)
        if isinstance(value, np.integer) or (isinstance(value, float) and value.is_integer()):
            value = int(value)  # (NumPy's integers; a whole float, e.g. a sweep's --range point)
        if isinstance(value, bool) or not isinstance(value, int):
            raise self.error(name, "an integer", value)
        if lo is not None and value < lo:
            raise self.error(name, f"an integer >= {lo}{_unit(unit)}", given)
        if hi is not None and value > hi:
            raise self.error(name, f"an integer <= {hi}{_unit(unit)}", given)
        return value

    def bool(self, name: str, default: Any = MISSING) -> bool:
        self._note(name, "boolean", default)
        value = self.raw(name, default)
        if not isinstance(value, bool):
            raise self.error(name, "true or false", value)
        return value

    def str(self, name: str, default: Any = MISSING, *, choices: Iterable[str] | None = None) -> str:
        choices = list(choices) if choices is not None else None
        self._note(name, "string", default, choices=tuple(choices) if choices is not None else None)
        value = self.raw(name, default)
        if not isinstance(value, str):
            raise self.error(name, "a string", value)
        if choices is not None:
            if value not in choices:
                close = close_matches(value, choices, n=1)
                hint = f" (did you mean {close[0]!r}?)" if close else ""
                raise self.error(name, f"one of {choices}{hint}", value)
            if name in VARIANT_KEYS and not any(v.startswith(f"{name} = ") for v in self.variant):
                self.variant = (*self.variant, f"{name} = {value}")
        return value

    def vector(self, name: str, default: Any = MISSING, *, size: int | None = None, unit: str = "",
               unit_norm: bool = False) -> np.ndarray:
        self._note(name, "direction" if unit_norm else "list", default, unit=unit, size=size)
        value = self.raw(name, default)
        ok = isinstance(value, list | tuple | np.ndarray) and all(_is_number(x) for x in value)
        if not ok or (size is not None and len(value) != size):
            what = f"a list of {size} numbers" if size is not None else "a list of numbers"
            raise self.error(name, what + _unit(unit), value)
        if any(_beyond_float(x) for x in value):
            raise self.error(name, "finite numbers" + _unit(unit), value)
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
        """Reject keys nobody read, suggesting the closest known one (read, or looked for)."""
        known = sorted(self._used | self._asked)
        for name in self.data:
            if name not in self._used:
                close = close_matches(name, known, n=1)
                raise UnknownKeyError(self.key(name), known, close[0] if close else None, self.file)


_LARGEST_FLOAT = int(sys.float_info.max)


def _is_number(value: Any) -> bool:
    """A real number: Python's int or float, or NumPy's (np.float32, np.int64 from a user's array); not a bool."""
    return isinstance(value, int | float | np.integer | np.floating) and not isinstance(value, bool)


def _beyond_float(value: Any) -> bool:
    """An integer too large for a float (``float()`` and ``np.asarray`` raise OverflowError on it)."""
    return isinstance(value, int) and abs(value) > _LARGEST_FLOAT


def _unit(unit: str) -> str:
    return f" [{unit}]" if unit else ""


def _fields(pattern: str) -> str:
    """`` with fields a (required), b, ...`` for errors about a table (from the scene reference)."""
    fields = table_fields(pattern)
    return f" with fields {fields}" if fields else ""


def table_fields(path: str) -> str:
    """The fields of the table at ``path`` (``phase[0].force[1]``, ``contact.tip.normal``), required ones first."""
    from .keyfields import TABLE_FIELDS

    path = _list_index_free(path)
    for table, fields in TABLE_FIELDS.items():
        if re.fullmatch(re.sub(r"<\w+>", r"[^.\\[]+", re.escape(table)), path):
            return fields
    return ""
