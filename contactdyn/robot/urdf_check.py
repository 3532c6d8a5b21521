"""A URDF's shape checked before Pinocchio reads it, and Pinocchio's builders run where a crash is harmless.

Pinocchio 4.1 (urdfdom underneath) dereferences missing links when the joints do not form a
tree: a cycle or a joint whose parent is its own child ends the process with SIGSEGV inside
``buildGeomFromUrdf`` (and a cycle is silently dropped by ``buildModelFromUrdf``).
:func:`check_urdf_tree` rejects such a file with a :class:`RobotError` that names the links
and joints involved; it also bounds the file's size and its number of links.

:func:`isolated_build` is the second line: it runs a builder first in a forked child, once
per file content, and only if that child survived does it run the builder here. A crash of
Pinocchio on an input the tree check did not foresee becomes a ``RobotError`` naming the
signal, not the end of the user's process or of a sweep worker.
"""

from __future__ import annotations

import faulthandler
import hashlib
import math
import os
import signal
import warnings
import xml.etree.ElementTree as ET
from collections.abc import Callable
from pathlib import Path

from ..errors import RobotError, abbreviate, close_matches, signal_name
from ..scene.reader import MAX_MAGNITUDE

__all__ = ["MAX_URDF_BYTES", "MAX_URDF_LINKS", "MAX_URDF_MOVING_JOINTS", "check_urdf_tree", "isolated_build"]

MAX_URDF_BYTES = 16 * 2**20  #: a URDF larger than this is refused (the largest shipped robot is 0.2 MB)
MAX_URDF_LINKS = 400  #: links at most (example-robot-data's largest, tiago_dual, has 130)
#: moving (non-fixed) joints at most: Pinocchio's data holds second-order tensors of nv³ numbers
#: (~1.8 GB at 400 joints); example-robot-data's largest, tiago_dual, has 101
MAX_URDF_MOVING_JOINTS = 128
PROBE_TIMEOUT = 120.0  #: [s] for the probe child to finish one builder call

_probed: dict[tuple[str, str], None] = {}  #: (content hash, builder name) that a child survived


def check_urdf_tree(path: Path) -> ET.Element:
    """Parse ``path`` and check its joints form one tree; return the XML root.

    One root link, every joint's parent and child a defined link, no joint whose parent is
    its child, no link the child of two joints, no cycle, unique link and joint names,
    every number finite (:data:`NUMERIC`: origins, masses, inertias, limits, shapes...; one where the attribute holds
    one), a joint's <dynamics> in [0, MAX_MAGNITUDE], no misspelt element or attribute (:data:`CHILDREN`) and no
    element given twice where URDF has it once (:data:`ONCE`).
    """
    size = path.stat().st_size
    if size > MAX_URDF_BYTES:
        raise RobotError(f"{path}: the URDF is {size / 2**20:.1f} MB; at most {MAX_URDF_BYTES // 2**20} MB is read")
    try:
        root = ET.parse(path).getroot()
    except ET.ParseError as exc:
        raise RobotError(f"{path}: malformed XML: {exc}") from None
    if root.tag != "robot":
        raise RobotError(f"{path}: expected a <robot> element at the top, found <{root.tag}>")
    links = [link.get("name") for link in root.findall("link")]
    if not links:
        raise RobotError(f"{path}: expected <link> elements in <robot>, found none (a xacro file not yet expanded?)")
    if len(links) > MAX_URDF_LINKS:
        raise RobotError(f"{path}: {len(links)} links; at most {MAX_URDF_LINKS} are supported")
    _unique(path, "link", links)
    defined = set(links)
    parent_of: dict[str, tuple[str, str]] = {}  # child link -> (joint, parent link)
    names = []
    for joint in root.findall("joint"):
        name = joint.get("name")
        names.append(name)
        parent, child = (_link_ref(path, joint, name, tag) for tag in ("parent", "child"))
        for role, link in (("parent", parent), ("child", child)):
            if link not in defined:
                raise RobotError(f"{path}: joint {_q(name)}: {role} link {_q(link)} is not defined (<link name=...>)")
        if parent == child:
            raise RobotError(f"{path}: joint {_q(name)}: link {_q(child)} is its own parent")
        if child in parent_of:
            raise RobotError(f"{path}: link {_q(child)} is the child of two joints, {_q(parent_of[child][0])} "
                             f"and {_q(name)}: the joints must form a tree")
        parent_of[child] = (name, parent)
    _unique(path, "joint", names)
    moving = sum(joint.get("type") != "fixed" for joint in root.findall("joint"))
    if moving > MAX_URDF_MOVING_JOINTS:
        raise RobotError(f"{path}: {moving} moving joints; at most {MAX_URDF_MOVING_JOINTS} are supported")
    roots = [link for link in links if link not in parent_of]
    if len(roots) != 1:
        found = f"{len(roots)} ({', '.join(map(_q, roots[:5]))})" if roots else "none (every link has a parent)"
        raise RobotError(f"{path}: expected one root link (a link that is no joint's child), found {found}")
    _check_numbers(path, root)
    for link in links:  # with one parent per link, a link that never reaches the root sits on a cycle
        seen = [link]
        while seen[-1] in parent_of:
            seen.append(parent_of[seen[-1]][1])
            if seen[-1] in seen[:-1]:
                loop = seen[seen.index(seen[-1]):]
                names = " -> ".join(x if len(x) <= 60 else f"{x[:50]}..." for x in loop[:12])
                raise RobotError(f"{path}: the joints form a cycle through links {names}")
    return root


#: the attributes that hold numbers, by element tag (URDF's specification): each must be finite
NUMERIC = {"origin": ("xyz", "rpy"), "mass": ("value",), "inertia": ("ixx", "ixy", "ixz", "iyy", "iyz", "izz"),
           "axis": ("xyz",), "limit": ("lower", "upper", "effort", "velocity"), "dynamics": ("damping", "friction"),
           "box": ("size",), "cylinder": ("radius", "length"), "sphere": ("radius",), "mesh": ("scale",),
           "color": ("rgba",), "mimic": ("multiplier", "offset"), "calibration": ("rising", "falling"),
           "safety_controller": ("soft_lower_limit", "soft_upper_limit", "k_position", "k_velocity")}


DYNAMICS_MEANING = {"damping": "viscous damping [N·m·s/rad or N·s/m]", "friction": "dry friction [N·m or N]"}


def _check_numbers(path: Path, element: ET.Element, where: str = "") -> None:
    """Every number the URDF states is finite; else a RobotError naming the element and the attribute."""
    for child in element:
        here = f"{child.tag} {_q(child.get('name'))}" if child.tag in ("link", "joint") and not where else \
            f"{where} <{child.tag}>".strip()
        _check_spelling(path, element.tag, child, where, here)
        for attribute in NUMERIC.get(child.tag, ()):
            text = child.get(attribute)
            if text is None:
                continue
            try:
                values = [float(v) for v in text.split()]
            except ValueError:
                values = [math.nan]
            if not values or not all(math.isfinite(v) for v in values):
                raise RobotError(f"{path}: {here}: {attribute}={_q(text)}: expected finite numbers")
            if len(values) != 1 and (child.tag, attribute) not in VECTORS:
                raise RobotError(f"{path}: {here}: {attribute}={_q(text)}: expected one number")
            if child.tag == "dynamics" and not 0.0 <= values[0] <= MAX_MAGNITUDE:  # (Pinocchio's own words: jargon)
                raise RobotError(f"{path}: {here}: {attribute}={_q(text)}: expected a number >= 0 and "
                                 f"<= {MAX_MAGNITUDE:g} (the joint's {DYNAMICS_MEANING[attribute]})")
        _check_numbers(path, child, here)
        _check_once(path, child, here)


#: the numeric attributes that hold several numbers (every other one holds one)
VECTORS = {("origin", "xyz"), ("origin", "rpy"), ("axis", "xyz"), ("box", "size"), ("mesh", "scale"), ("color", "rgba")}
#: the elements URDF's specification gives a joint, a link or an inertial once at most (the parsers read the first and
#: drop the others without a word: a second <dynamics> or <mass> would silently not count)
ONCE = {"joint": ("origin", "parent", "child", "axis", "calibration", "dynamics", "limit", "mimic",
                  "safety_controller"), "link": ("inertial",), "inertial": ("origin", "mass", "inertia")}


def _check_once(path: Path, element: ET.Element, here: str) -> None:
    tags = [c.tag for c in element if c.tag in ONCE.get(element.tag, ())]
    twice = next((t for t in tags if tags.count(t) > 1), None)
    if twice:
        raise RobotError(f"{path}: {here}: <{twice}> {tags.count(twice)} times: expected it once (the URDF's parsers "
                         "read the first and drop the others without a word)")


#: the elements URDF's specification gives a joint and a link (a misspelling of one is dropped by the parsers)
CHILDREN = {"joint": ("origin", "parent", "child", "axis", "calibration", "dynamics", "limit", "mimic",
                      "safety_controller"), "link": ("inertial", "visual", "collision")}


def _check_spelling(path: Path, parent: str, child: ET.Element, where: str, here: str) -> None:
    """A joint's or link's element, or a numeric element's attribute, whose name is a misspelling of a known one (the
    parsers drop it without a word: a joint's ``<dynamic>`` or ``frcition`` would silently give no friction)."""
    unknown = [] if parent not in CHILDREN or child.tag in CHILDREN[parent] else [(child.tag, CHILDREN[parent])]
    known = NUMERIC.get(child.tag, ())
    unknown += [(a, known) for a in child.attrib if known and a not in known]
    for name, choices in unknown:
        close = close_matches(name, choices, n=1, cutoff=0.85)
        if close:
            what = f"{where}: unknown <{name}>" if name == child.tag else f"{here}: unknown attribute {name}="
            raise RobotError(f"{path}: {what} (did you mean {close[0]!r}?): the URDF's parsers drop it without a word")


def _link_ref(path: Path, joint: ET.Element, name: str | None, tag: str) -> str:
    element = joint.find(tag)
    link = element.get("link") if element is not None else None
    if not link:
        raise RobotError(f"{path}: joint {_q(name)}: missing <{tag} link=\"...\"/>")
    return link


def _unique(path: Path, what: str, names: list[str | None]) -> None:
    seen: set[str] = set()
    for name in names:
        if not name:
            raise RobotError(f"{path}: a <{what}> without a name")
        if name in seen:
            raise RobotError(f"{path}: two {what}s named {_q(name)}")
        seen.add(name)


def _q(name: object, limit: int = 80) -> str:
    """A name from the file, quoted and abbreviated (a hostile file may hold megabyte names)."""
    return abbreviate(name, limit)


def isolated_build(path: Path, label: str, build: Callable[[], object]) -> None:
    """Run ``build()`` in a forked child first (once per file content); raise RobotError if it crashed.

    The child's exceptions are ignored (the caller's own call reports them with urdfdom's
    reason); only a death by a signal, or a child still running after ``PROBE_TIMEOUT``, is
    an error here.
    """
    key = (hashlib.sha256(path.read_bytes()).hexdigest(), label)
    if key in _probed:
        return
    with warnings.catch_warnings():  # the child only calls Pinocchio's C++ and exits: no Python lock needed
        warnings.simplefilter("ignore", DeprecationWarning)
        pid = os.fork()
    if pid == 0:  # child: never return into the caller's code
        code = 1
        try:
            faulthandler.disable()  # a crash here is expected and reported by the parent
            null = os.open(os.devnull, os.O_WRONLY)
            os.dup2(null, 1)
            os.dup2(null, 2)
            build()
            code = 0
        finally:
            os._exit(code)
    status, timed_out = _wait(pid)
    if timed_out:
        raise RobotError(f"{path}: Pinocchio did not finish reading this URDF ({label}) in {PROBE_TIMEOUT:g} s")
    if os.WIFSIGNALED(status):
        sig = os.WTERMSIG(status)
        raise RobotError(f"{path}: Pinocchio crashed reading this URDF ({label} died with "
                         f"{signal_name(sig)}); check its joints and links")
    _probed[key] = None


def _wait(pid: int) -> tuple[int, bool]:
    """waitpid with a deadline: (status, whether the child was killed for passing it)."""
    import time

    deadline = time.monotonic() + PROBE_TIMEOUT
    delay = 0.001
    while True:
        done, status = os.waitpid(pid, os.WNOHANG)
        if done:
            return status, False
        if time.monotonic() > deadline:
            os.kill(pid, signal.SIGKILL)
            return os.waitpid(pid, 0)[1], True
        time.sleep(delay)
        delay = min(2 * delay, 0.05)


