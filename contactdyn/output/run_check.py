"""What a saved run must look like before anything reads it: sizes, dtypes, shapes, the sidecar's fields.

A run's ``NAME.npz`` is read member by member: each ``.npy`` header is checked (numbers
only, no pickled objects, a size the member holds) before its data is read, and the total
the archive declares is bounded (a 16 GiB header is refused before allocating). Then the
channels: ``t`` finite and non-decreasing, one row per sample everywhere, the documented
shapes (README, "Result channels"). The ``NAME.json`` sidecar: bounded size, an object
with ``events``, ``impacts`` (each with a time ``t``), ``stats``, ``scene``, ``meta``, and
the field types the readers (plots, viewer, sweeps) use. Every failure is one
:class:`~contactdyn.errors.RunFileError` naming the file.
"""

from __future__ import annotations

import json
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import RunFileError, abbreviate
from ..scene.budget import available_memory

__all__ = ["MAX_RUN_BYTES", "MAX_SIDECAR_BYTES", "read_channels", "read_sidecar"]

MAX_RUN_BYTES = 2**31  #: [B] channels a saved run may declare (a run at the sample bound is far below)
MAX_SIDECAR_BYTES = 2**28  #: [B] size of a run's .json sidecar
#: channels under these prefixes are one number per sample (but contact.<c>.F_f and .v_slip)
SCALAR_PREFIXES = ("contact.", "stage.", "mass.", "body.", "energy.")

def read_channels(npz: Path) -> dict[str, np.ndarray]:
    import zipfile

    try:
        with zipfile.ZipFile(npz) as archive:
            declared = sum(info.file_size for info in archive.infolist())
            if declared > MAX_RUN_BYTES:
                raise RunFileError(f"{npz}: declares {declared / 2**30:.3g} GiB of channels; a saved run holds at "
                                   f"most {MAX_RUN_BYTES / 2**30:g} GiB")
            if declared > available_memory():
                raise RunFileError(f"{npz}: declares {declared / 2**30:.3g} GiB of channels, more than the "
                                   f"{available_memory() / 2**30:.2g} GiB of memory available")
            channels = {}
            for info in archive.infolist():
                name = info.filename.removesuffix(".npy")
                with archive.open(info) as member:
                    channels[name] = _read_array(member, info.file_size, npz, name)
    except RunFileError:
        raise
    except (zipfile.BadZipFile, ValueError, OSError, EOFError, RuntimeError, NotImplementedError, MemoryError) as exc:
        raise RunFileError(f"{npz}: not a readable run archive "
                           f"({type(exc).__name__}: {abbreviate(str(exc))})") from None
    _check_shapes(npz, channels)
    return channels


def _check_shapes(npz: Path, channels: dict[str, np.ndarray]) -> None:
    """Time samples finite and increasing; every channel one row per sample, of its documented shape."""
    t = channels.get("t")
    if t is None or t.ndim != 1 or t.size == 0:
        raise RunFileError(f"{npz}: no time channel t (a 1-D array of samples)")
    if not np.all(np.isfinite(t)) or np.any(np.diff(t) < 0.0):
        raise RunFileError(f"{npz}: the time channel t is not finite and non-decreasing")
    n = t.size
    for name, value in channels.items():
        if name in ("tip", "tip_ref"):
            expected = f"({n}, 3)"
            ok = value.shape == (n, 3)
        elif name.startswith(SCALAR_PREFIXES) and not name.endswith((".F_f", ".v_slip")):
            expected, ok = f"({n},)", value.shape == (n,)
        else:
            expected, ok = f"({n},) or ({n}, k)", value.ndim in (1, 2) and value.shape[0] == n
        if not ok:
            raise RunFileError(f"{npz}: channel {abbreviate(name)} has shape {value.shape}, expected {expected}: "
                               "one row per sample of t")
    joints = {channels[k].reshape(n, -1).shape[1] for k in ("q", "v") if k in channels}
    if len(joints) > 1:
        raise RunFileError(f"{npz}: channels q and v have different numbers of joints")


def _read_array(member, size: int, npz: Path, name: str) -> np.ndarray:
    """One .npy member: a numeric array whose header agrees with the member's size."""
    from numpy.lib import format as npy

    read_header = {(1, 0): npy.read_array_header_1_0, (2, 0): npy.read_array_header_2_0}.get(npy.read_magic(member))
    if read_header is None:
        raise RunFileError(f"{npz}: channel {abbreviate(name)} is in an unknown .npy format version")
    shape, fortran, dtype = read_header(member)
    if dtype.kind not in "biuf" or dtype.hasobject:
        raise RunFileError(f"{npz}: channel {abbreviate(name)} holds {dtype}, expected numbers")
    count = int(np.prod(shape, dtype=object))
    if count * dtype.itemsize > size:
        raise RunFileError(f"{npz}: channel {abbreviate(name)} declares {count} values in a {size}-byte member")
    data = member.read(count * dtype.itemsize)
    if len(data) != count * dtype.itemsize:
        raise RunFileError(f"{npz}: channel {abbreviate(name)} is truncated")
    array = np.frombuffer(data, dtype=dtype).reshape(shape, order="F" if fortran else "C")
    return array.astype(float) if dtype.kind != "f" else array.copy()


def read_sidecar(sidecar: Path) -> dict[str, Any]:
    if sidecar.stat().st_size > MAX_SIDECAR_BYTES:
        raise RunFileError(f"{sidecar}: {sidecar.stat().st_size / 2**20:.0f} MB, more than a run's sidecar "
                           f"({MAX_SIDECAR_BYTES // 2**20} MB at most)")
    try:
        doc = json.loads(sidecar.read_bytes())
    except (ValueError, RecursionError, OSError) as exc:
        raise RunFileError(f"{sidecar}: not a run's JSON sidecar "
                           f"({type(exc).__name__}: {abbreviate(str(exc))})") from None
    if not isinstance(doc, dict):
        raise RunFileError(f"{sidecar}: expected a JSON object, found {type(doc).__name__}")
    doc.setdefault("meta", {})
    for key, kind in (("events", list), ("impacts", list), ("stats", dict), ("scene", dict), ("meta", dict)):
        if not isinstance(doc.get(key), kind):
            raise RunFileError(f"{sidecar}: {key!r} must be a JSON {'array' if kind is list else 'object'}, "
                               f"found {abbreviate(doc.get(key, 'nothing'))}")
    for key in ("events", "impacts"):
        for i, item in enumerate(doc[key]):
            if not (isinstance(item, dict) and isinstance(item.get("t"), int | float)):
                raise RunFileError(f"{sidecar}: {key}[{i}] must be an object with a time t, found {abbreviate(item)}")
            _check_fields(sidecar, f"{key}[{i}]", item, SIDECAR_FIELDS)
    _check_fields(sidecar, "meta", doc["meta"], SIDECAR_FIELDS)
    for key in ("contact", "body"):  # the tables plots read from the scene document
        table = doc["scene"].get(key, {})
        if not (isinstance(table, dict) and all(isinstance(v, dict) for v in table.values())):
            raise RunFileError(f"{sidecar}: scene.{key} must be a table of tables, found {abbreviate(table)}")
    return doc


def _check_fields(sidecar: Path, where: str, doc: dict[str, Any], fields: dict[str, Callable[[Any], bool]]) -> None:
    for key, valid in fields.items():
        if key in doc and not valid(doc[key]):
            raise RunFileError(f"{sidecar}: {where}.{key} has the wrong type: {abbreviate(doc[key])}")


def _texts(value: Any) -> bool:
    return isinstance(value, list) and all(isinstance(v, str) for v in value)


#: fields of the sidecar's meta, events and impacts that readers use, and what each must be
SIDECAR_FIELDS: dict[str, Callable[[Any], bool]] = {
    "joints": _texts, "contacts": _texts, "bodies": _texts,
    "name": lambda v: isinstance(v, str), "robot": lambda v: isinstance(v, str), "tip": lambda v: isinstance(v, str),
    "kind": lambda v: isinstance(v, str), "contact": lambda v: isinstance(v, str),
    "duration": lambda v: isinstance(v, int | float) and not isinstance(v, bool),
}


def check_drawable(result) -> Any:
    """What every command that draws a run (``plot``, ``view``) needs of it, checked the same way: a joint
    channel ``q`` with finite values, a finite duration, and a scene document that still validates (returned,
    or None without one); friction channels with one column per tangent. A RunFileError names the run."""
    from ..errors import ContactdynError
    from ..scene.scene_file import parse_scene

    name = result.meta.get("name", "?")
    if "q" not in result.channels:
        raise RunFileError(f"run {name}: no joint channel q, nothing to draw")
    q = np.asarray(result.channels["q"], float).reshape(len(result.channels["t"]), -1)
    if not np.all(np.isfinite(q)):
        raise RunFileError(f"run {name}: channel q holds non-finite values, the robot cannot be drawn")
    duration = result.meta.get("duration", 0.0)
    if not isinstance(duration, int | float) or not np.isfinite(duration):
        raise RunFileError(f"run {name}: its duration {abbreviate(duration)} is not a finite number")
    if not result.scene:
        return None
    try:
        where = result.meta.get("scene_file")  # paths in it (a body's URDF) read beside the scene, as the run did
        scene = parse_scene(drawing_document(result.scene), None, where if isinstance(where, str) else None)
    except ContactdynError as exc:
        raise RunFileError(f"run {name}: its scene document no longer validates, cannot draw it: {exc}") from None
    for c in scene.contacts.values():
        for key in (f"contact.{c.name}.F_f", f"contact.{c.name}.v_slip"):
            columns = result.channels[key].reshape(len(q), -1).shape[1] if key in result.channels else None
            if columns is not None and columns != len(c.tangents):
                raise RunFileError(f"run {name}: channel {key} has {columns} columns but the scene gives contact "
                                   f"{c.name!r} {len(c.tangents)} tangents")
    return scene


def drawing_document(document: dict[str, Any]) -> dict[str, Any]:
    """A saved scene document as drawing reads it: no ``imports`` (viewing or plotting a run received from
    someone never runs its code) and every controller table emptied (a user's law is not needed to draw)."""
    doc = {k: v for k, v in document.items() if k != "imports"}
    if "controller" in doc:
        doc["controller"] = {}
    if isinstance(doc.get("phase"), list):
        doc["phase"] = [{k: v for k, v in p.items() if k != "controller"} if isinstance(p, dict) else p
                        for p in doc["phase"]]
    return doc
