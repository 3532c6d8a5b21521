"""A run's result: time-series channels, events, impacts and solver statistics.

Saved as two files side by side: ``NAME.npz`` (the channels) and ``NAME.json`` (scene
document, events, impacts, statistics), each written atomically with the user's umask.
``NAME`` is taken as given (``mu0.2`` -> ``mu0.2.npz``); a trailing ``.npz`` or ``.json`` is
dropped. Channel names are stable and documented in the README.

:func:`load_result` checks what it reads before anything uses it (sizes declared in the
archive, numeric channels of one length, the sidecar's structure) and answers a damaged
or foreign file with one :class:`~contactdyn.errors.RunFileError` naming it.
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

from .errors import RunFileError

__all__ = ["Result", "load_result", "run_files", "atomic_path"]

MAX_RUN_BYTES = 2**31  #: [B] channels a saved run may declare (a run at the sample bound is far below)
MAX_SIDECAR_BYTES = 2**28  #: [B] size of a run's .json sidecar


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
        npz, sidecar = run_files(path)
        npz.parent.mkdir(parents=True, exist_ok=True)
        _atomic(npz, lambda f: np.savez(f, **self.channels))
        doc = {"events": self.events, "impacts": self.impacts, "stats": self.stats, "scene": self.scene,
               "meta": self.meta}
        _atomic(sidecar, lambda f: f.write(json.dumps(doc, indent=1, default=_jsonable).encode()))
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
    channels = _read_channels(npz)
    doc = _read_sidecar(sidecar)
    return Result(channels, doc["events"], doc["impacts"], doc["stats"], doc["scene"], doc["meta"])


def _read_channels(npz: Path) -> dict[str, np.ndarray]:
    import zipfile

    try:
        with zipfile.ZipFile(npz) as archive:
            declared = sum(info.file_size for info in archive.infolist())
            if declared > MAX_RUN_BYTES:
                raise RunFileError(f"{npz}: declares {declared / 2**30:.3g} GiB of channels; a saved run holds at "
                                   f"most {MAX_RUN_BYTES / 2**30:g} GiB")
            channels = {}
            for info in archive.infolist():
                name = info.filename.removesuffix(".npy")
                with archive.open(info) as member:
                    channels[name] = _read_array(member, info.file_size, npz, name)
    except RunFileError:
        raise
    except (zipfile.BadZipFile, ValueError, OSError, EOFError, RuntimeError, NotImplementedError) as exc:
        raise RunFileError(f"{npz}: not a readable run archive ({type(exc).__name__}: {_short(exc)})") from None
    t = channels.get("t")
    if t is None or t.ndim != 1 or t.size == 0:
        raise RunFileError(f"{npz}: no time channel t (a 1-D array of samples)")
    for name, value in channels.items():
        if value.ndim not in (1, 2) or value.shape[0] != t.size:
            raise RunFileError(f"{npz}: channel {_short(name)} has shape {value.shape}, expected ({t.size},) or "
                               f"({t.size}, n): one row per sample of t")
    return channels


def _read_array(member, size: int, npz: Path, name: str) -> np.ndarray:
    """One .npy member: a numeric array whose header agrees with the member's size."""
    from numpy.lib import format as npy

    read_header = {(1, 0): npy.read_array_header_1_0, (2, 0): npy.read_array_header_2_0}.get(npy.read_magic(member))
    if read_header is None:
        raise RunFileError(f"{npz}: channel {_short(name)} is in an unknown .npy format version")
    shape, fortran, dtype = read_header(member)
    if dtype.kind not in "biuf" or dtype.hasobject:
        raise RunFileError(f"{npz}: channel {_short(name)} holds {dtype}, expected numbers")
    count = int(np.prod(shape, dtype=object))
    if count * dtype.itemsize > size:
        raise RunFileError(f"{npz}: channel {_short(name)} declares {count} values in a {size}-byte member")
    data = member.read(count * dtype.itemsize)
    if len(data) != count * dtype.itemsize:
        raise RunFileError(f"{npz}: channel {_short(name)} is truncated")
    array = np.frombuffer(data, dtype=dtype).reshape(shape, order="F" if fortran else "C")
    return array.astype(float) if dtype.kind != "f" else array.copy()


def _read_sidecar(sidecar: Path) -> dict[str, Any]:
    if sidecar.stat().st_size > MAX_SIDECAR_BYTES:
        raise RunFileError(f"{sidecar}: {sidecar.stat().st_size / 2**20:.0f} MB, more than a run's sidecar "
                           f"({MAX_SIDECAR_BYTES // 2**20} MB at most)")
    try:
        doc = json.loads(sidecar.read_bytes())
    except (ValueError, RecursionError, OSError) as exc:
        raise RunFileError(f"{sidecar}: not a run's JSON sidecar ({type(exc).__name__}: {_short(exc)})") from None
    if not isinstance(doc, dict):
        raise RunFileError(f"{sidecar}: expected a JSON object, found {type(doc).__name__}")
    doc.setdefault("meta", {})
    for key, kind in (("events", list), ("impacts", list), ("stats", dict), ("scene", dict), ("meta", dict)):
        if not isinstance(doc.get(key), kind):
            raise RunFileError(f"{sidecar}: {key!r} must be a JSON {'array' if kind is list else 'object'}, "
                               f"found {_short(doc.get(key, 'nothing'))}")
    for key in ("events", "impacts"):
        for i, item in enumerate(doc[key]):
            if not (isinstance(item, dict) and isinstance(item.get("t"), int | float)):
                raise RunFileError(f"{sidecar}: {key}[{i}] must be an object with a time t, found {_short(item)}")
    return doc


def _short(value: object, limit: int = 80) -> str:
    """repr (or str of an exception), abbreviated to ``limit`` characters, control characters escaped."""
    text = str(value) if isinstance(value, BaseException) else repr(value)
    text = text.encode("unicode_escape", "backslashreplace").decode("ascii")
    return text if len(text) <= limit else f"{text[:limit - 20]}...{text[-15:]} ({len(text)} chars)"


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
