"""A run's result: time-series channels, events, impacts and solver statistics.

Saved as two files side by side: ``NAME.npz`` (the channels) and ``NAME.json`` (scene
document, events, impacts, statistics), each written atomically. Channel names are
stable and documented in the README.
"""

from __future__ import annotations

import json
import os
import tempfile
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from .errors import ContactdynError

__all__ = ["Result", "load_result"]


@dataclass
class Result:
    channels: dict[str, np.ndarray]
    events: list[dict[str, Any]] = field(default_factory=list)
    impacts: list[dict[str, Any]] = field(default_factory=list)
    stats: dict[str, Any] = field(default_factory=dict)
    scene: dict[str, Any] = field(default_factory=dict)  #: the scene document that produced the run
    meta: dict[str, Any] = field(default_factory=dict)  #: joint names, contact names, labels

    @property
    def t(self) -> np.ndarray:
        return self.channels["t"]

    def __getitem__(self, name: str) -> np.ndarray:
        try:
            return self.channels[name]
        except KeyError:
            import difflib

            close = difflib.get_close_matches(name, list(self.channels), n=3)
            raise KeyError(f"no channel {name!r}; close: {close}; all: {sorted(self.channels)}") from None

    def save(self, path: str | os.PathLike) -> Path:
        """Write ``path`` (.npz) and its .json sidecar atomically; return the .npz path."""
        npz = Path(path).with_suffix(".npz")
        npz.parent.mkdir(parents=True, exist_ok=True)
        _atomic(npz, lambda f: np.savez(f, **self.channels))
        doc = {"events": self.events, "impacts": self.impacts, "stats": self.stats, "scene": self.scene,
               "meta": self.meta}
        _atomic(npz.with_suffix(".json"), lambda f: f.write(json.dumps(doc, indent=1, default=_jsonable).encode()))
        return npz


def load_result(path: str | os.PathLike) -> Result:
    npz = Path(path).with_suffix(".npz")
    sidecar = npz.with_suffix(".json")
    if not npz.is_file() or not sidecar.is_file():
        raise ContactdynError(f"{npz}: not a saved run (need {npz.name} and {sidecar.name})")
    with np.load(npz) as data:
        channels = {k: data[k] for k in data.files}
    doc = json.loads(sidecar.read_text())
    return Result(channels, doc["events"], doc["impacts"], doc["stats"], doc["scene"], doc.get("meta", {}))


def atomic_path(path: Path, write: Callable[[str], None]) -> None:
    """Call ``write(tmp)`` on a temporary file beside ``path``, then rename it onto ``path``."""
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    os.close(fd)
    try:
        write(tmp)
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise


def _atomic(path: Path, write: Callable[[Any], None]) -> None:
    """Atomic write through a binary file object."""

    def to_file(tmp: str) -> None:
        with open(tmp, "wb") as f:
            write(f)

    atomic_path(path, to_file)


def _jsonable(obj: Any) -> Any:
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    if isinstance(obj, np.generic):
        return obj.item()
    if isinstance(obj, float):
        return obj
    return str(obj)
