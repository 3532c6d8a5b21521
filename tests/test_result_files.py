"""Saved runs: names taken as given, the user's umask, errors naming the file, damaged files refused."""

from __future__ import annotations

import errno
import json
import os
import zipfile
from pathlib import Path

import numpy as np
import pytest

from contactdyn.errors import RunFileError
from contactdyn.output.result import Result, atomic_path, load_result, run_files


def small() -> Result:
    t = np.linspace(0.0, 1.0, 5)
    return Result({"t": t, "q": np.c_[t, 2 * t]}, [{"t": 0.5, "kind": "touch"}], [], {"steps": 4}, {}, {"name": "s"})


def test_the_name_is_taken_as_given(tmp_path):
    a, b = small(), small()
    b.channels["q"] = b.channels["q"] * 3
    assert a.save(tmp_path / "mu0.2") == tmp_path / "mu0.2.npz"
    b.save(tmp_path / "mu0.8")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["mu0.2.json", "mu0.2.npz", "mu0.8.json", "mu0.8.npz"]
    assert np.array_equal(load_result(tmp_path / "mu0.2")["q"], a["q"])
    assert np.array_equal(load_result(tmp_path / "mu0.8.json")["q"], b["q"])
    assert run_files("x/run.npz") == (Path("x/run.npz"), Path("x/run.json"))


def test_an_unknown_channel_names_the_close_ones():
    with pytest.raises(KeyError, match=r"no channel 'qq'; close: \['q'\]; all: \['q', 't'\]"):
        small()["qq"]


@pytest.mark.parametrize("mask", [0o022, 0o077, 0o002])
def test_files_get_the_users_umask(tmp_path, mask):
    old = os.umask(mask)
    try:
        npz = small().save(tmp_path / "r")
    finally:
        os.umask(old)
    for path in (npz, npz.with_suffix(".json")):
        assert path.stat().st_mode & 0o777 == 0o666 & ~mask


def test_a_full_disk_names_the_file(tmp_path):
    def full(tmp: str) -> None:
        raise OSError(errno.ENOSPC, "No space left on device")

    with pytest.raises(OSError) as info:
        atomic_path(tmp_path / "r.npz", full)
    assert info.value.filename == str(tmp_path / "r.npz") and info.value.errno == errno.ENOSPC
    assert list(tmp_path.iterdir()) == []  # no tmp file left


def test_a_huge_declared_channel_is_refused_before_reading(tmp_path):
    small().save(tmp_path / "r")
    header = "{'descr': '<f8', 'fortran_order': False, 'shape': (2147483648,), }"
    padded = (header.ljust(117) + "\n").encode()
    raw = b"\x93NUMPY\x01\x00" + len(padded).to_bytes(2, "little") + padded
    with zipfile.ZipFile(tmp_path / "r.npz", "w") as z:
        z.writestr("t.npy", raw)  # 16 GiB declared in a 128-byte member
    with pytest.raises(RunFileError, match="declares 2147483648 values in a 128-byte member"):
        load_result(tmp_path / "r")


def test_sidecar_structure_is_checked(tmp_path):
    small().save(tmp_path / "r")
    (tmp_path / "r.json").write_text(json.dumps({"events": {}, "impacts": [], "stats": {}, "scene": {}}))
    with pytest.raises(RunFileError, match=r"r.json: 'events' must be a JSON array, found \{\}"):
        load_result(tmp_path / "r")
