"""Where a robot's URDF is, and where the files it names (``package://``, ``file://``) are.

A robot source is a URDF path, a file in the project's ``urdf/`` folder, or a name of
:mod:`contactdyn.robot.catalog`. A ``package://PKG/rest`` URI resolves the way ROS tools do,
searching in order: the URDF's ancestor folders, example-robot-data's share folder (and its
``robots`` folder), and every ``ROS_PACKAGE_PATH`` entry. A folder D serves the URI when
``D/PKG/rest`` exists, or when D itself is named PKG and ``D/rest`` exists. ``file://`` URIs
and plain paths are absolute or relative to the URDF's folder.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import NamedTuple

from ..errors import RobotError, close_matches
from .catalog import SHORT_NAMES, example_robot_data_share, example_robots, require_example_robot_data, urdf_dir

__all__ = ["UrdfSource", "resolve_robot_path", "package_dirs", "resolve_uri"]


class UrdfSource(NamedTuple):
    """A URDF file and the folders its ``package://`` URIs are searched in (in order)."""

    path: Path
    package_dirs: list[str]


def package_dirs(urdf: Path) -> list[str]:
    """Search folders for ``package://`` URIs of ``urdf`` (see the module docstring)."""
    dirs = list(urdf.resolve().parents)
    share = example_robot_data_share()
    if share is not None:
        dirs += [share.parent, share / "robots"]
    for entry in os.environ.get("ROS_PACKAGE_PATH", "").split(os.pathsep):
        if entry:
            dirs += [Path(entry), Path(entry).parent]
    return [str(d) for d in dict.fromkeys(dirs)]


def resolve_uri(uri: str, urdf: Path, dirs: list[str]) -> Path | None:
    """The file a URDF's mesh URI names, or None when it is nowhere."""
    if uri.startswith("package://"):
        package, _, rest = uri.removeprefix("package://").partition("/")
        for d in map(Path, dirs):
            for candidate in (d / package / rest, d / rest if d.name == package else None):
                if candidate is not None and candidate.is_file():
                    return candidate
        return None
    file = Path(uri.removeprefix("file://"))
    file = file if file.is_absolute() else urdf.parent / file
    return file if file.is_file() else None


def resolve_robot_path(source: str | os.PathLike) -> UrdfSource:
    """Return the URDF and its package search folders for a path, a name in ``urdf/``, or a robot name."""
    text = str(source)
    given = Path(text)
    if given.is_file():
        return UrdfSource(given, package_dirs(given))
    for path in (urdf_dir() / text, urdf_dir() / f"{text}.urdf"):
        if path.suffix == ".urdf" and path.is_file():
            return UrdfSource(path, package_dirs(path))
    known_examples = example_robots()
    if text in known_examples:
        return UrdfSource(known_examples[text], package_dirs(known_examples[text]))
    if text.endswith(".urdf") or os.sep in text and not text.split(os.sep)[0].endswith("_description"):
        raise RobotError(f"{text}: no such URDF file (looked at {given.absolute()} and in {urdf_dir()})")
    if not known_examples:
        require_example_robot_data()
    ours = sorted(p.stem for p in urdf_dir().glob("*.urdf"))
    close = close_matches(text, ours + sorted(known_examples))
    hint = f"; did you mean {', '.join(close)}?" if close else ""
    usual = ours + [n for n in SHORT_NAMES if n in known_examples]
    raise RobotError(f"robot {text!r}: not a URDF file nor a known robot name{hint} (known: {', '.join(usual)} "
                     f"and {len(known_examples) - len(usual) + len(ours)} more: contactdyn list robots)")
