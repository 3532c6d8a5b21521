"""The parameters to fit: scene keys, their bounds, and the scale the solver sees.

``KEY[=LOW:HIGH]``: a numeric key of the scene document (after ``--set``), e.g.
``contact.tip.normal.k`` or ``phase.0.force.0.value``. A parameter whose starting value
and lower bound are > 0 is fitted on a log scale (the solver moves ln p: a step is a
factor, and the parameter stays positive); other parameters on a linear scale.
Default bounds: [p₀/1000, 1000 p₀] on a log scale, unbounded on a linear one.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..errors import ContactdynError, SceneError

__all__ = ["Parameter", "parse_params", "document_value", "DEFAULT_LOG_SPAN"]

DEFAULT_LOG_SPAN = 1e3  #: default bounds of a log-scale parameter: [p₀ / span, p₀ · span]


@dataclass(frozen=True)
class Parameter:
    key: str  #: scene key path
    start: float  #: the scene's value (after --set)
    low: float  #: lower bound (may be -inf)
    high: float  #: upper bound (may be inf)
    log: bool  #: fitted as ln p

    def internal(self, value: float) -> float:
        """The solver's coordinate of a value."""
        return math.log(value) if self.log else value

    def value(self, z: float) -> float:
        """The value of a solver coordinate."""
        return math.exp(z) if self.log else float(z)

    @property
    def internal_bounds(self) -> tuple[float, float]:
        if self.log:
            return math.log(self.low), (math.log(self.high) if math.isfinite(self.high) else math.inf)
        return self.low, self.high

    @property
    def scale(self) -> float:
        """Typical size of a solver step (``x_scale``): 1 on a log scale (a factor e)."""
        if self.log:
            return 1.0
        if math.isfinite(self.high - self.low):
            return (self.high - self.low) / 10.0
        return abs(self.start) if self.start != 0 else 1.0


def document_value(document: dict[str, Any], key: str) -> Any:
    """The value at ``key`` (dotted path; list items by index) of a scene document, or KeyError."""
    node: Any = document
    for part in key.split("."):
        if isinstance(node, dict) and part in node:
            node = node[part]
        elif isinstance(node, list) and part.isdigit() and int(part) < len(node):
            node = node[int(part)]
        else:
            raise KeyError(key)
    return node


def parse_params(text: str | list[str], document: dict[str, Any], file: str | None = None) -> list[Parameter]:
    """Parameters from ``KEY[=LOW:HIGH],...`` (or a list of such items); errors name the key."""
    items = [s.strip() for part in ([text] if isinstance(text, str) else text) for s in part.split(",")]
    items = [s for s in items if s]
    if not items:
        raise SceneError("--params", "KEY[=LOW:HIGH],... with at least one scene key", text, file)
    params = [_parameter(item, document, file) for item in items]
    keys = [p.key for p in params]
    if len(set(keys)) != len(keys):
        raise SceneError("--params", "each key once", keys, file)
    return params


def _parameter(item: str, document: dict[str, Any], file: str | None) -> Parameter:
    key, sep, bounds = (s.strip() for s in item.partition("="))
    try:
        start = document_value(document, key)
    except KeyError:
        raise SceneError(key, "a number set in the scene to start from (in the file or with --set KEY=VALUE)",
                         "no such key", file) from None
    if isinstance(start, bool) or not isinstance(start, int | float) or not math.isfinite(start):
        raise SceneError(key, "a number in the scene to fit", start, file)
    if isinstance(start, int) and _read_as_integer(document, key, start, file):
        raise SceneError(key, "a key the scene reads as a real number (the fit moves it continuously; this one is a "
                         "count: run a sweep over its values instead)", start, file)
    start = float(start)
    if sep:
        low, high = _bounds(key, bounds, file)
        log = start > 0 and low > 0
    else:
        log = start > 0
        low, high = (start / DEFAULT_LOG_SPAN, start * DEFAULT_LOG_SPAN) if log else (-math.inf, math.inf)
    if not low <= start <= high:
        raise SceneError(key, f"a starting value within its bounds [{low:g}, {high:g}]", start, file)
    return Parameter(key, start, low, high, log)


def _read_as_integer(document: dict[str, Any], key: str, start: int, file: str | None) -> bool:
    """Whether the scene reads ``key`` as an integer (``controller.delay``, a seed): is start + 0.5 refused as one?"""
    from ..scene.scene_file import parse_scene

    try:
        parse_scene(document, {key: start + 0.5}, file)
    except SceneError as exc:
        return exc.key == key and exc.expected.startswith("an integer")
    except ContactdynError:  # (another of the scene's checks: not this key's type)
        return False
    return False


def _bounds(key: str, text: str, file: str | None) -> tuple[float, float]:
    expected = "bounds LOW:HIGH (numbers, LOW < HIGH; one may be empty: unbounded)"
    parts = text.split(":")
    if len(parts) != 2:
        raise SceneError(key, expected, text, file)
    try:
        low = float(parts[0]) if parts[0].strip() else -math.inf
        high = float(parts[1]) if parts[1].strip() else math.inf
    except ValueError:
        raise SceneError(key, expected, text, file) from None
    if np.isnan(low) or np.isnan(high) or not low < high:
        raise SceneError(key, expected, text, file)
    return low, high
