"""What a sweep runs: a base scene, fixed overrides, axes (grid, range) and explicit runs; run ids."""

from __future__ import annotations

import hashlib
import itertools
import json
import math
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import SceneError
from ..laws.failures import LawError
from ..scene.reader import Reader, read_toml
from ..scene.scene_file import find_scene, parse_override, parse_scene

__all__ = ["Sweep", "run_id", "parse_grid", "parse_range", "load_sweep_file", "make_sweep", "check_sweep"]


MAX_RUNS = 100_000  #: runs in one sweep at most (each is files on disk and a summary row)


@dataclass
class Sweep:
    """A base scene document, fixed overrides and the varied axes (key -> values)."""

    document: dict[str, Any]
    file: str | None
    fixed: dict[str, Any] = field(default_factory=dict)
    axes: dict[str, list[Any]] = field(default_factory=dict)
    runs: list[dict[str, Any]] = field(default_factory=list)  #: explicit runs, crossed with the axes

    @property
    def name(self) -> str:
        name = self.document.get("name")
        return name if isinstance(name, str) else Path(self.file or "scene").stem

    def cases(self) -> list[tuple[str, dict[str, Any], dict[str, Any]]]:
        """(run id, varied parameters, all overrides) per run, sorted by id; duplicates merged."""
        out: dict[str, tuple[str, dict[str, Any], dict[str, Any]]] = {}
        keys = list(self.axes)
        count = max(1, len(self.runs)) * math.prod(len(v) for v in self.axes.values())
        if count > MAX_RUNS:
            raise SceneError("--grid/--range", f"a sweep of at most {MAX_RUNS} runs (the product of the axes' "
                             "lengths and the explicit runs)", f"{count} runs", self.file)
        for explicit in self.runs or [{}]:
            for values in itertools.product(*(self.axes[k] for k in keys)):
                params = {**explicit, **dict(zip(keys, values, strict=True))}
                overrides = {**self.fixed, **params}
                rid = run_id(overrides)
                out[rid] = (rid, params, overrides)
        return [out[k] for k in sorted(out)]

    def parameter_keys(self) -> list[str]:
        keys = list(self.axes)
        for explicit in self.runs:
            keys += [k for k in explicit if k not in keys]
        return keys

    def digest(self) -> str:
        """A hash of the base document: a resumed sweep must start from the same scene."""
        return hashlib.sha256(_canonical(self.document).encode()).hexdigest()[:16]


def run_id(overrides: dict[str, Any]) -> str:
    """Stable id of a run: the first 12 hex digits of the SHA-256 of its sorted overrides."""
    return hashlib.sha256(_canonical(overrides).encode()).hexdigest()[:12]


def _canonical(obj: Any) -> str:
    return json.dumps(obj, sort_keys=True, separators=(",", ":"), allow_nan=True, default=str)


def parse_grid(text: str) -> tuple[str, list[Any]]:
    """``key=v1,v2,...`` (each value read as TOML, else as a string; commas inside [] are kept)."""
    key, sep, rest = text.partition("=")
    key = key.strip()
    items = _split_top_level(rest)
    if not sep or not key or not items or any(not s for s in items):
        raise SceneError("--grid", "key.path=v1,v2,... with at least one value", text)
    return key, [parse_override(f"{key}={item}")[1] for item in items]


def parse_range(text: str) -> tuple[str, list[float]]:
    """``key=lo:hi:n`` (n values, linear) or ``key=lo:hi:n:log`` (log spacing, lo and hi > 0)."""
    key, sep, rest = text.partition("=")
    parts = rest.split(":")
    expected = "key.path=lo:hi:n or key.path=lo:hi:n:log (numbers, n >= 1)"
    if not sep or not key.strip() or len(parts) not in (3, 4) or (len(parts) == 4 and parts[3].strip() != "log"):
        raise SceneError("--range", expected, text)
    try:
        lo, hi, n = float(parts[0]), float(parts[1]), int(parts[2])
    except ValueError:
        raise SceneError("--range", expected, text) from None
    return key.strip(), _spaced(f"--range {key.strip()}", lo, hi, n, len(parts) == 4)


def _spaced(where: str, lo: float, hi: float, n: int, log: bool, file: str | None = None) -> list[float]:
    if not (math.isfinite(lo) and math.isfinite(hi)):
        raise SceneError(where, "finite lo and hi", [lo, hi], file)
    if not 1 <= n <= MAX_RUNS:
        raise SceneError(where, f"1 <= n <= {MAX_RUNS} values", n, file)
    if log and (lo <= 0 or hi <= 0):
        raise SceneError(where, "lo > 0 and hi > 0 for log spacing", [lo, hi], file)
    values = np.geomspace(lo, hi, n) if log else np.linspace(lo, hi, n)
    return [float(v) for v in values]


def _split_top_level(text: str) -> list[str]:
    items, depth, quote, cur = [], 0, "", ""
    for ch in text:
        if quote:
            quote = "" if ch == quote else quote
        elif ch in "\"'":
            quote = ch
        elif ch in "[{":
            depth += 1
        elif ch in "]}":
            depth -= 1
        elif ch == "," and depth == 0:
            items.append(cur.strip())
            cur = ""
            continue
        cur += ch
    items.append(cur.strip())
    return items if any(items) else []


def load_sweep_file(path: str | Path) -> tuple[str | None, dict[str, Any], dict[str, list[Any]], list[dict[str, Any]]]:
    """Read a sweep file: (scene, fixed overrides, axes, explicit runs); errors name file and key."""
    path = Path(path)
    file = str(path)
    doc = read_toml(path, "sweep file")
    top = Reader(doc, "", file)
    scene = top.str("scene", None) if top.has("scene") else None
    if scene is not None and not Path(scene).is_absolute() and (path.parent / scene).is_file():
        scene = str(path.parent / scene)
    fixed = _flatten(top.raw("set", {}), "set", file, leaf=lambda v: not isinstance(v, dict))
    axes: dict[str, list[Any]] = {}
    for key, values in _flatten(top.raw("grid", {}), "grid", file, leaf=lambda v: not isinstance(v, dict)).items():
        if not isinstance(values, list) or not values:
            raise SceneError(f"grid.{key}", "a non-empty list of values", values, file)
        axes[key] = values
    spec_leaf = lambda v: not isinstance(v, dict) or "lo" in v  # noqa: E731
    for key, spec in _flatten(top.raw("range", {}), "range", file, leaf=spec_leaf).items():
        r = Reader(spec, f"range.{key}", file)
        lo, hi = r.float("lo"), r.float("hi")
        n, log = r.int("n", lo=1), r.bool("log", False)
        r.finish()
        axes[key] = _spaced(f"range.{key}", lo, hi, n, log, file)
    runs = [_flatten(t.data, t.path, file, leaf=lambda v: not isinstance(v, dict)) for t in top.tables("run")]
    top.finish()
    return scene, fixed, axes, runs


def _flatten(table: Any, where: str, file: str, leaf: Callable[[Any], bool]) -> dict[str, Any]:
    if not isinstance(table, dict):
        raise SceneError(where, "a table of key.path = value", table, file)
    out: dict[str, Any] = {}
    for key, value in table.items():
        if leaf(value):
            out[key] = value
        else:
            out.update({f"{key}.{k}": v for k, v in _flatten(value, f"{where}.{key}", file, leaf).items()})
    return out


def make_sweep(scene: str | Path | None, sets: Iterable[str] = (), grids: Iterable[str] = (),
               ranges: Iterable[str] = (), sweep_file: str | Path | None = None) -> Sweep:
    """Assemble a sweep from command-line pieces (they override the sweep file's)."""
    fixed: dict[str, Any] = {}
    axes: dict[str, list[Any]] = {}
    runs: list[dict[str, Any]] = []
    if sweep_file is not None:
        file_scene, fixed, axes, runs = load_sweep_file(sweep_file)
        scene = scene if scene is not None else file_scene
    if scene is None:
        raise SceneError("scene", "a scene (argument or `scene = ...` in the sweep file)", None,
                         str(sweep_file) if sweep_file else None)
    fixed.update(dict(parse_override(s) for s in sets))
    given = [(parse_grid(s), "--grid") for s in grids] + [(parse_range(s), "--range") for s in ranges]
    seen: set[str] = set()
    for (key, _), option in given:  # a key given twice would keep only its last axis, silently
        if key in seen:
            raise SceneError(option, f"each key once among --grid and --range ({key} is given twice)", key)
        seen.add(key)
    axes.update(dict(axis for axis, _ in given))
    path = find_scene(scene).resolve()  # the workers' working directory may differ (Dask): its imports, its URDF
    document = read_toml(path)
    return Sweep(document, str(path), fixed, axes, runs)


def check_sweep(sweep: Sweep) -> None:
    """Reject a sweep with any invalid case (exit 2) before the first run starts.

    Every case is validated as the run would validate it; the first invalid one is named by
    its varied values (``contact.tip.normal.b = -1``), then the scene's own message. A robot
    that cannot be found is bad input too. A user's law raising as it reads a case is left to that run (recorded as
    failed, the sweep goes on).
    """
    from ..robot.robot import resolve_robot_path

    first = None
    for _, params, overrides in sweep.cases():
        try:
            scene = parse_scene(sweep.document, overrides, sweep.file)
        except SceneError as exc:
            if exc.found == "an unknown key" or not params:
                raise
            values = ", ".join(f"{k} = {_canonical(v)}" for k, v in params.items())
            raise SceneError(f"sweep value {values}: {exc.key}", exc.expected, exc.found, exc.file) from None
        except LawError:  # (a user's law failing to read its values: that run's failure, recorded when it runs)
            continue
        first = first or scene
    if first is not None:
        resolve_robot_path(first.robot.source)
