"""Write a scene document (what ``tomllib`` reads) back as TOML text.

Tables become ``[a.b]`` sections, lists of tables ``[[a]]``, tables inside arrays inline
tables; floats keep every digit (``repr``). ``tomllib.loads(dumps(doc)) == doc`` for any
document tomllib produced (tested).
"""

from __future__ import annotations

import json
import math
from typing import Any

__all__ = ["dumps", "format_value"]


def dumps(document: dict[str, Any], header: str = "") -> str:
    """TOML text of ``document``; ``header`` lines become comments at the top."""
    lines = [f"# {line}".rstrip() for line in header.splitlines()]
    _table(document, [], lines)
    return "\n".join(lines).lstrip("\n") + "\n"


def _table(table: dict[str, Any], path: list[str], lines: list[str]) -> None:
    subtables, arrays = [], []
    for key, value in table.items():
        if isinstance(value, dict):
            subtables.append((key, value))
        elif _is_table_array(value):
            arrays.append((key, value))
        else:
            lines.append(f"{_key(key)} = {format_value(value)}")
    for key, value in subtables:
        lines += ["", f"[{'.'.join(_key(k) for k in [*path, key])}]"]
        _table(value, [*path, key], lines)
    for key, items in arrays:
        for item in items:
            lines += ["", f"[[{'.'.join(_key(k) for k in [*path, key])}]]"]
            _table(item, [*path, key], lines)


def _is_table_array(value: Any) -> bool:
    return isinstance(value, list) and bool(value) and all(isinstance(v, dict) for v in value)


def _key(key: str) -> str:
    bare = key and all(c.isalnum() or c in "_-" for c in key) and key.isascii()
    return key if bare else json.dumps(key)


def format_value(value: Any) -> str:
    """One TOML value (string, number, bool, array, inline table), escaped as TOML needs."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        if math.isnan(value):
            return "nan"
        if math.isinf(value):
            return "inf" if value > 0 else "-inf"
        return repr(value)
    if isinstance(value, str):
        return json.dumps(value, ensure_ascii=False)
    if isinstance(value, list):
        return "[" + ", ".join(format_value(v) for v in value) + "]"
    if isinstance(value, dict):
        return "{ " + ", ".join(f"{_key(k)} = {format_value(v)}" for k, v in value.items()) + " }"
    raise TypeError(f"cannot write {type(value).__name__} {value!r} as TOML")
