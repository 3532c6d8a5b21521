"""From a URDF file to a checked Pinocchio model of all its joints.

The steps, in order: find the file (:mod:`contactdyn.robot.urdf_source`), parse its XML, check the
links' inertia data (:mod:`contactdyn.robot.inertia`), resolve every visual mesh to an absolute
file, turn ``continuous`` joints into unbounded revolute joints (one coordinate, the angle
[rad], instead of Pinocchio's (cos θ, sin θ) pair), and let Pinocchio build the model from the
rewritten XML. A joint whose limits say lower = upper (double_pendulum's 0, 0) is taken as
unbounded too: no limits given. The XML tree is checked before Pinocchio sees the file, and
every Pinocchio builder runs first in a forked probe (:mod:`contactdyn.robot.urdf_check`). Pinocchio
accepts lower > upper limits silently: that is checked here too.
"""

from __future__ import annotations

import hashlib
import os
import sys
import tempfile
import xml.etree.ElementTree as ET
from collections import OrderedDict
from collections.abc import Callable
from pathlib import Path
from typing import NamedTuple

import numpy as np
import pinocchio as pin

from ..errors import RobotError
from .inertia import INERTIA_MODES, check_inertias
from .urdf_check import check_urdf_tree, isolated_build
from .urdf_source import resolve_robot_path, resolve_uri

__all__ = ["FREE_COORDINATES", "PLANAR_SUFFIXES", "UrdfModel", "add_free_joints", "build_isolated",
           "build_urdf_model", "lock_joints", "split_planar_joints", "urdf_call", "xml_label"]

_UNBOUNDED = 1e9  # [rad] placeholder limits of a continuous joint in the rewritten XML; set to ±inf after


class UrdfModel(NamedTuple):
    """A URDF as built: the file, the rewritten XML Pinocchio read, the model of all joints."""

    path: Path
    xml: str  #: continuous joints as revolute, meshes as absolute paths, inertias as checked/repaired
    model: pin.Model
    package_dirs: list[str]
    notes: list[str]  #: inertia repairs or trusts, one line each
    unbounded: list[str]  #: joints without position limits (±inf): continuous ones, and lower = upper in the file
    visual_notes: list[str]  #: the visual meshes not found, dropped from the drawing (one line)


def urdf_call(path: Path, build: Callable[[], object]) -> object:
    """Run a Pinocchio URDF builder; on failure raise RobotError with urdfdom's reason.

    Pinocchio's exception says only "does not contain a valid URDF model"; urdfdom writes
    the reason to file descriptor 2, which is captured here for the duration of the call.
    """
    sys.stderr.flush()
    with tempfile.TemporaryFile(mode="w+b") as err:
        saved = os.dup(2)
        os.dup2(err.fileno(), 2)
        try:
            return build()
        except (ValueError, RuntimeError) as exc:
            failure: Exception = exc
        finally:
            os.dup2(saved, 2)
            os.close(saved)
        err.seek(0)
        reason = err.read().decode(errors="replace")
    lines = [ln.strip().removeprefix("Error:").strip() for ln in reason.splitlines() if ln.strip().startswith("Error")]
    detail = "; ".join(lines) or str(failure)
    raise RobotError(f"{path}: not a valid URDF: {detail}")


def build_isolated(path: Path, label: str, build: Callable[[], object]) -> object:
    """Run a Pinocchio builder on (a rewrite of) ``path``: first in a forked probe (a crash there is a
    RobotError, see contactdyn.robot.urdf_check; once per ``label``, which names the XML's content), then here,
    with urdfdom's reason on failure."""
    isolated_build(path, label, build)
    return urdf_call(path, build)


def xml_label(builder: str, xml: str) -> str:
    """A probe label naming the builder and the rewritten XML's content."""
    return f"{builder} {hashlib.sha256(xml.encode()).hexdigest()[:16]}"


def _resolve_meshes(root: ET.Element, path: Path, package_dirs: list[str]) -> list[str]:
    """Every visual mesh resolves to a file (not loaded: that is slow); its filename becomes absolute.

    A visual whose mesh is nowhere to be found is dropped, as ROS tools do: the link is drawn without
    it, and the dynamics never read visuals. Returns one note naming them, or none."""
    missing = []
    for link in root.iter("link"):
        for visual in link.findall("visual"):
            mesh = visual.find("geometry/mesh")
            if mesh is None:
                continue
            filename = mesh.get("filename", "")
            file = resolve_uri(filename, path, package_dirs)
            if file is None or not _usable_mesh(file):
                link.remove(visual)
                missing.append(f"link {link.get('name')!r} ({filename!r})")
                continue
            mesh.set("filename", str(file.resolve()))
    if not missing:
        return []
    more = f" and {len(missing) - 2} more" if len(missing) > 2 else ""
    return [f"{path.name}: {len(missing)} visual mesh(es) not found or unusable (searched the URDF's folders, "
            f"example-robot-data and ROS_PACKAGE_PATH; a mesh is a regular .dae, .stl or .obj file): "
            f"{', '.join(missing[:2])}{more}; the viewer draws those links without them"]


MESH_SUFFIXES = (".dae", ".stl", ".obj")  #: the mesh files meshcat draws


def _usable_mesh(file: Path) -> bool:
    """A regular file with a mesh's suffix (not /etc/passwd, not /proc/self/mem, not a FIFO)."""
    try:
        return file.suffix.lower() in MESH_SUFFIXES and file.is_file() and not str(file.resolve()).startswith(
            ("/proc/", "/sys/", "/dev/"))
    except OSError:
        return False


def _unbind_continuous(root: ET.Element) -> list[str]:
    """Rewrite continuous joints as revolute joints with placeholder limits; return their names."""
    names = []
    for joint in root.findall("joint"):
        if joint.get("type") != "continuous":
            continue
        joint.set("type", "revolute")
        limit = joint.find("limit")
        if limit is None:
            limit = ET.SubElement(joint, "limit", effort="0", velocity="0")
        limit.set("lower", repr(-_UNBOUNDED))
        limit.set("upper", repr(_UNBOUNDED))
        names.append(joint.get("name", ""))
    return names


def _check_limits(model: pin.Model, path: Path) -> None:
    lower, upper = model.lowerPositionLimit, model.upperPositionLimit
    for jid in range(1, model.njoints):
        sl = slice(model.idx_qs[jid], model.idx_qs[jid] + model.nqs[jid])
        if np.any(lower[sl] > upper[sl]):
            raise RobotError(f"{path}: joint {model.names[jid]!r}: "
                             f"lower limit {lower[sl].tolist()} > upper limit {upper[sl].tolist()}")


#: URDFs built in this process: (file, SHA-256 of its content, package dirs, inertia) -> the build, the most
#: recently used last; at most BUILT_MAX kept (a process that loads many robots keeps the latest ones)
_BUILT: OrderedDict[tuple, UrdfModel] = OrderedDict()
BUILT_MAX = 16


def build_urdf_model(source: str | os.PathLike, inertia: str = "check", free: bool = False,
                     body: bool = False) -> UrdfModel:
    """Find, check and build a URDF (see the module docstring); ``inertia`` is one of INERTIA_MODES; ``free``: its
    root link moves freely in the world, by six coordinates (:func:`add_free_joints`); ``body``: a scene body's
    URDF, its planar joints three one-coordinate joints each (:func:`split_planar_joints`; a robot's stay whole).

    A file built before in this process, unchanged since (the same content), is not checked and built again
    (a sweep or a script builds the same robot per run); the caller gets its own copy of the model."""
    if inertia not in INERTIA_MODES:
        raise RobotError(f"robot.inertia must be one of {list(INERTIA_MODES)}, found {inertia!r}")
    path, package_dirs = resolve_robot_path(source)
    key = (str(path.resolve()), hashlib.sha256(path.read_bytes()).hexdigest(), tuple(package_dirs), inertia)
    key += (("free",) if free else ()) + (("body",) if body else ())
    if key not in _BUILT:
        _BUILT[key] = _build(path, package_dirs, inertia, free, body)
        while len(_BUILT) > BUILT_MAX:
            _BUILT.popitem(last=False)
    _BUILT.move_to_end(key)
    built = _BUILT[key]
    return built._replace(model=pin.Model(built.model), package_dirs=list(built.package_dirs),
                          notes=list(built.notes), unbounded=list(built.unbounded),
                          visual_notes=list(built.visual_notes))


def _build(path: Path, package_dirs: list[str], inertia: str, free: bool = False, body: bool = False) -> UrdfModel:
    root = check_urdf_tree(path)  # one root, no cycle...: before Pinocchio reads anything (it crashes)
    notes = check_inertias(root, path, inertia)
    visual_notes = _resolve_meshes(root, path, package_dirs)
    if body:
        split_planar_joints(root, path)
    if free:
        add_free_joints(root, path)
    unbounded = _unbind_continuous(root)
    xml = ET.tostring(root, encoding="unicode")
    model: pin.Model = build_isolated(path, xml_label("buildModelFromXML", xml), lambda: pin.buildModelFromXML(xml))
    lower, upper = model.lowerPositionLimit.copy(), model.upperPositionLimit.copy()
    for jid in range(1, model.njoints):  # lower = upper (double_pendulum's 0, 0) means "no limits given"
        i = model.idx_qs[jid]
        if model.nqs[jid] == 1 and lower[i] == upper[i] and model.names[jid] not in unbounded:
            unbounded.append(model.names[jid])
    for name in unbounded:
        i = model.idx_qs[model.getJointId(name)]
        lower[i], upper[i] = -np.inf, np.inf
    model.lowerPositionLimit, model.upperPositionLimit = lower, upper
    _check_limits(model, path)
    return UrdfModel(path, xml, model, package_dirs, notes, unbounded, visual_notes)


#: a free body's six coordinates, in order: the root frame's origin in the world [m], then its ZYX Euler angles
#: [rad] (R = Rz(yaw) Ry(pitch) Rx(roll)); each a joint of the rewritten URDF, chained in this order
FREE_COORDINATES = ("x", "y", "z", "yaw", "pitch", "roll")
_FREE_AXES = ("1 0 0", "0 1 0", "0 0 1", "0 0 1", "0 1 0", "1 0 0")


def add_free_joints(root: ET.Element, path: Path) -> None:
    """Make the URDF's root link free: a massless world link, then six one-coordinate joints (FREE_COORDINATES:
    prismatic along the world's x, y, z, then revolute about z, the new y, the newer x), the root link the last
    one's child. nq = nv = 6 (Pinocchio's free-flyer, a quaternion, has nq 7). A ``floating`` joint from a
    massless root link (a "world" link) is that link's own free motion: it and the link are dropped first."""
    _drop_floating(root, path)
    children = {j.find("child").get("link") for j in root.findall("joint") if j.find("child") is not None}
    links = [link.get("name") for link in root.findall("link")]
    base = next(name for name in links if name not in children)
    clash = sorted({j.get("name") for j in root.findall("joint")} & set(FREE_COORDINATES))
    if clash:
        raise RobotError(f"{path}: a free body's URDF names no joint {', '.join(FREE_COORDINATES)} (its six "
                         f"coordinates); found {', '.join(clash)}")
    chain = [f"{base}__free_world"] + [f"{base}__free_{c}" for c in FREE_COORDINATES[:-1]] + [base]
    for name in chain[:-1]:
        root.insert(0, ET.Element("link", name=name))
    for k, (coordinate, axis) in enumerate(zip(FREE_COORDINATES, _FREE_AXES, strict=True)):
        kind = "prismatic" if k < 3 else "continuous"  # lower = upper = 0 below: unbounded (see _build)
        joint = ET.SubElement(root, "joint", name=coordinate, type=kind)
        ET.SubElement(joint, "parent", link=chain[k])
        ET.SubElement(joint, "child", link=chain[k + 1])
        ET.SubElement(joint, "axis", xyz=axis)
        if k < 3:
            ET.SubElement(joint, "limit", lower="0", upper="0", effort="0", velocity="0")


#: a body's planar joint <j> becomes joints <j>_x, <j>_y (prismatic, in the plane) and <j>_yaw (revolute about its
#: normal), chained in this order at the planar joint's origin
PLANAR_SUFFIXES = ("_x", "_y", "_yaw")


def split_planar_joints(root: ET.Element, path: Path) -> None:
    """Rewrite each ``planar`` joint <j> as three one-coordinate joints at its origin (PLANAR_SUFFIXES): <j>_x and
    <j>_y prismatic along two in-plane unit axes a1, a2 [m], then <j>_yaw continuous about the plane's normal n
    [rad], (a1, a2, n) right-handed; two massless links <j>__planar_x, <j>__planar_y between them. The normal is the
    joint's ``<axis>`` (URDF's planar joint), z when none is given; n = z gives a1 = x, a2 = y: Pinocchio's
    JointModelPlanar (q = (x, y, cos θ, sin θ), which translates in its frame's x-y, then turns about z; its URDF
    reader ignores ``<axis>``: its plane is always x-y). Joint limits are dropped (unbounded). A new name that is
    taken already is one RobotError naming it."""
    names = {j.get("name") for j in root.findall("joint")} | {link.get("name") for link in root.findall("link")}
    for joint in [j for j in root.findall("joint") if j.get("type") == "planar"]:
        name = joint.get("name", "")
        new = [name + s for s in PLANAR_SUFFIXES] + [f"{name}__planar_x", f"{name}__planar_y"]
        taken = sorted(set(new) & names)
        if taken:
            raise RobotError(f"{path}: planar joint {name!r} becomes joints {', '.join(new[:3])} (and links "
                             f"{', '.join(new[3:])}); the URDF has {', '.join(repr(t) for t in taken)} already")
        names |= set(new)
        axis = joint.find("axis")
        n = np.array([float(v) for v in axis.get("xyz", "0 0 1").split()]) if axis is not None else np.eye(3)[2]
        if not np.linalg.norm(n) > 0.0:
            raise RobotError(f"{path}: planar joint {name!r}: its axis (the plane's normal) is zero")
        R = _turning_z_to(n / np.linalg.norm(n))  # columns a1, a2, n
        parent, child = joint.find("parent").get("link"), joint.find("child").get("link")
        origin = joint.find("origin")
        root.remove(joint)
        chain = [parent, new[3], new[4], child]
        for link in new[3:]:
            root.append(ET.Element("link", name=link))
        for k, (kind, column) in enumerate((("prismatic", 0), ("prismatic", 1), ("continuous", 2))):
            part = ET.SubElement(root, "joint", name=new[k], type=kind)
            if k == 0 and origin is not None:
                part.append(origin)
            ET.SubElement(part, "parent", link=chain[k])
            ET.SubElement(part, "child", link=chain[k + 1])
            ET.SubElement(part, "axis", xyz=" ".join(repr(float(c)) for c in R[:, column]))
            if kind == "prismatic":  # lower = upper = 0: unbounded (see _build)
                ET.SubElement(part, "limit", lower="0", upper="0", effort="0", velocity="0")


def _turning_z_to(n: np.ndarray) -> np.ndarray:
    """The rotation [-] turning z onto the unit vector n by the shortest way (about z × n); identity for n = z."""
    c = float(n[2])
    if c < -1.0 + 1e-12:
        return np.diag([1.0, -1.0, -1.0])  # n = −z: half a turn about x
    k = np.cross([0.0, 0.0, 1.0], n)
    K = np.array([[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]])
    return np.eye(3) + K + K @ K / (1.0 + c)


def _drop_floating(root: ET.Element, path: Path) -> None:
    """Remove a ``floating`` joint from the root link and that link (massless: a world link); a floating joint
    elsewhere, or from a link with mass, is one RobotError."""
    floating = [j for j in root.findall("joint") if j.get("type") == "floating"]
    if not floating:
        return
    children = {j.find("child").get("link") for j in root.findall("joint") if j.find("child") is not None}
    joint = floating[0]
    parent = joint.find("parent").get("link")
    link = next(el for el in root.findall("link") if el.get("name") == parent)
    if len(floating) > 1 or parent in children or link.find("inertial") is not None or \
            sum(j.find("parent").get("link") == parent for j in root.findall("joint")) > 1:
        raise RobotError(f"{path}: a free body's floating joint (at most one) joins a root link without mass or "
                         f"other joints (a world link) to the body; found {joint.get('name')!r} from {parent!r}")
    root.remove(joint)
    root.remove(link)


def _origin(joint: ET.Element) -> pin.SE3:
    el = joint.find("origin")
    xyz = np.array([float(v) for v in (el.get("xyz", "0 0 0") if el is not None else "0 0 0").split()])
    rpy = np.array([float(v) for v in (el.get("rpy", "0 0 0") if el is not None else "0 0 0").split()])
    return pin.SE3(pin.rpy.rpyToMatrix(rpy), xyz)


def lock_joints(urdf: UrdfModel, values: dict[str, float]) -> str:
    """The URDF's XML with each named 1-DOF joint fixed at its value [rad or m].

    A locked joint becomes a fixed joint whose origin includes the joint's motion, so Pinocchio
    builds the reduced model directly (its ``buildReducedModel`` refuses robots where a link and
    a joint share a name, as z1's ``gripperStator``).
    """
    root = ET.fromstring(urdf.xml)
    for joint in root.findall("joint"):
        name = joint.get("name", "")
        if name not in values:
            continue
        axis_el = joint.find("axis")
        axis = np.array([float(v) for v in (axis_el.get("xyz", "1 0 0") if axis_el is not None else "1 0 0").split()])
        axis = axis / np.linalg.norm(axis)
        value = values[name]
        if joint.get("type") == "prismatic":
            motion = pin.SE3(np.eye(3), axis * value)
        else:  # revolute (continuous ones were made revolute)
            motion = pin.SE3(pin.AngleAxis(value, axis).matrix(), np.zeros(3))
        placement = _origin(joint) * motion
        for tag in ("origin", "axis", "limit", "dynamics", "safety_controller", "calibration", "mimic"):
            for el in joint.findall(tag):
                joint.remove(el)
        ET.SubElement(joint, "origin", xyz=" ".join(repr(float(v)) for v in placement.translation),
                      rpy=" ".join(repr(float(v)) for v in pin.rpy.matrixToRpy(placement.rotation)))
        joint.set("type", "fixed")
    return ET.tostring(root, encoding="unicode")
