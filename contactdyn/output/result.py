"""A run's result: time-series channels, events, impacts and solver statistics.

Saved as two files side by side: ``NAME.npz`` (the channels) and ``NAME.json`` (scene
document, events, impacts, statistics), each written atomically with the user's umask.
``NAME`` is taken as given (``mu0.2`` -> ``mu0.2.npz``); a trailing ``.npz`` or ``.json`` is
dropped. Channel names are stable and documented in the README.

:func:`load_result` checks what it reads before anything uses it (:mod:`contactdyn.output.run_check`)
and answers a damaged or foreign file with one :class:`~contactdyn.errors.RunFileError`
naming it.
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

from ..errors import RunFileError, close_matches
from .run_check import read_channels, read_sidecar

__all__ = ["Result", "load_result", "run_files", "atomic_path", "atomic_write", "jsonable"]


@dataclass(repr=False)
class Result:
    """One run: named channels sampled on the output grid, the events, the impacts, solver statistics.

    ``result["contact.table.F_n"]`` is a channel (names and units: the README's "Result channels");
    ``result.t`` the sample times [s]; ``result.events`` the mode switches (``t``, ``kind``, ``name``);
    ``result.impacts`` the impacts' impulses and velocities; ``result.stats`` the solver's counts and
    wall time; ``result.meta`` the robot, the contacts, the sanity warnings and the run's physics
    checks (``meta["checks"]``, ``meta["check_warnings"]``). In a notebook: :meth:`to_pandas`,
    :meth:`show`, and a summary table as the cell's output.
    """

    channels: dict[str, np.ndarray]
    events: list[dict[str, Any]] = field(default_factory=list)
    impacts: list[dict[str, Any]] = field(default_factory=list)
    stats: dict[str, Any] = field(default_factory=dict)
    scene: dict[str, Any] = field(default_factory=dict)  #: the scene document that produced the run
    meta: dict[str, Any] = field(default_factory=dict)  #: joint names, contact names, labels

    @property
    def t(self) -> np.ndarray:
        """Sample times [s]."""
        return self.channels["t"]

    def __getitem__(self, name: str) -> np.ndarray:
        """The channel ``name`` (a KeyError names the close ones and lists all)."""
        try:
            return self.channels[name]
        except KeyError:
            close = close_matches(name, self.channels)
            raise KeyError(f"no channel {name!r}; close: {close}; all: {sorted(self.channels)}") from None

    def to_pandas(self):
        """The channels as a pandas DataFrame indexed by ``t`` [s]: a column per scalar channel and per
        component of a vector one (``q[0]``, ``contact.table.F_f[0]``, ...)."""
        import pandas as pd

        columns: dict[str, np.ndarray] = {}
        for name, values in self.channels.items():
            values = np.asarray(values)
            if name == "t":
                continue
            if values.ndim == 1:
                columns[name] = values
            else:
                for k in range(values.reshape(len(values), -1).shape[1]):
                    columns[f"{name}[{k}]"] = values.reshape(len(values), -1)[:, k]
        return pd.DataFrame(columns, index=pd.Index(np.asarray(self.t), name="t"))

    def summary(self) -> dict[str, Any]:
        """What the repr shows: scene, duration [s], counts of events and impacts, each contact's peak
        normal force [N], the warnings (sanity and physics checks)."""
        peaks = {name: float(np.max(self.channels[f"contact.{name}.F_n"], initial=0.0))
                 for name in self.meta.get("contacts", []) if f"contact.{name}.F_n" in self.channels}
        return {"scene": self.meta.get("name", "?"), "duration": float(self.t[-1]) if len(self.t) else 0.0,
                "events": len(self.events), "impacts": len(self.impacts), "peak_F_n": peaks,
                "warnings": list(self.meta.get("warnings", [])) + list(self.meta.get("check_warnings", []))}

    def __repr__(self) -> str:
        s = self.summary()
        peaks = ", ".join(f"{k} {v:.4g} N" for k, v in s["peak_F_n"].items()) or "none"
        return (f"<Result {s['scene']}: {s['duration']:g} s, {s['events']} events, {s['impacts']} impacts, "
                f"peak F_n: {peaks}, {len(s['warnings'])} warnings>")

    def _repr_html_(self) -> str:
        from html import escape

        s = self.summary()
        rows = [("scene", s["scene"]), ("duration", f"{s['duration']:g} s"), ("events", s["events"]),
                ("impacts", s["impacts"])]
        rows += [(f"peak F_n {k}", f"{v:.4g} N") for k, v in s["peak_F_n"].items()]
        rows += [("warning", w) for w in s["warnings"]]
        cells = "".join(f"<tr><th style='text-align:left'>{escape(str(k))}</th><td style='text-align:left'>"
                        f"{escape(str(v))}</td></tr>" for k, v in rows)
        return f"<table>{cells}</table>"

    def show(self, speed: float = 1.0, height: int = 480):
        """The run's 3-D player inline in Jupyter (the page of ``contactdyn view --html``, in an iframe), played
        at ``speed`` × real time; returns an object a notebook displays."""
        from ..viewer.notebook import inline_player  # the viewer draws; a result only asks it to

        return inline_player(self, speed, height)

    def save(self, path: str | os.PathLike) -> Path:
        """Write ``path`` (.npz) and its .json sidecar atomically; return the .npz path."""
        npz, sidecar = run_files(path)
        npz.parent.mkdir(parents=True, exist_ok=True)
        _atomic(npz, lambda f: np.savez(f, **self.channels))
        doc = {"events": self.events, "impacts": self.impacts, "stats": self.stats, "scene": self.scene,
               "meta": self.meta}
        _atomic(sidecar, lambda f: f.write(json.dumps(doc, indent=1, default=jsonable).encode()))
        return npz


def run_files(path: str | os.PathLike) -> tuple[Path, Path]:
    """(NAME.npz, NAME.json) of a run named ``path`` (a trailing .npz or .json is dropped, nothing else)."""
    path = Path(path)
    if path.suffix in (".npz", ".json"):
        path = path.with_suffix("")
    return path.with_name(path.name + ".npz"), path.with_name(path.name + ".json")


def missing_run_message(path: str | os.PathLike) -> str:
    npz, sidecar = run_files(path)
    return f"{path}: not a saved run (need {npz.name} and {sidecar.name}, as `contactdyn run SCENE --out NAME` writes)"


def load_result(path: str | os.PathLike) -> Result:
    """Read a saved run; a missing, damaged or foreign file is a RunFileError naming it."""
    npz, sidecar = run_files(path)
    for file in (npz, sidecar):
        if not file.is_file():
            raise RunFileError(missing_run_message(path))
    channels = read_channels(npz)
    doc = read_sidecar(sidecar)
    return Result(channels, doc["events"], doc["impacts"], doc["stats"], doc["scene"], doc["meta"])


def atomic_path(path: Path, write: Callable[[str], None]) -> None:
    """Call ``write(tmp)`` on a temporary file beside ``path``, then rename it onto ``path``.

    The file gets the mode a plain ``open`` would give (0666 less the umask), not mkstemp's
    0600. An error without a file name (a full disk) is re-raised naming ``path``.
    """
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    os.close(fd)
    try:
        write(tmp)
        os.chmod(tmp, 0o666 & ~_umask())
        os.replace(tmp, path)
    except BaseException as exc:
        if os.path.exists(tmp):
            os.unlink(tmp)
        if isinstance(exc, OSError) and exc.filename is None:
            raise OSError(exc.errno, exc.strerror or str(exc), str(path)) from None
        raise


def _umask() -> int:
    """The process's umask, read without changing it (Linux), else by setting and restoring it."""
    try:
        for line in Path("/proc/self/status").read_text().splitlines():
            if line.startswith("Umask:"):
                return int(line.split()[1], 8)
    except (OSError, ValueError):
        pass
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


def atomic_write(path: Path, data: bytes | str) -> None:
    """Write ``data`` (text as UTF-8) to ``path`` atomically (:func:`atomic_path`)."""
    raw = data.encode() if isinstance(data, str) else data
    _atomic(path, lambda f: f.write(raw))


def _atomic(path: Path, write: Callable[[Any], None]) -> None:
    """Atomic write through a binary file object."""

    def to_file(tmp: str) -> None:
        with open(tmp, "wb") as f:
            write(f)

    atomic_path(path, to_file)


def jsonable(obj: Any) -> Any:
    """What a run's sidecar holds for a value JSON has no type for (``json.dumps(..., default=jsonable)``)."""
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    if isinstance(obj, np.generic):
        return obj.item()
    return str(obj)
