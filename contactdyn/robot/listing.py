"""``contactdyn list robots`` and ``contactdyn list frames ROBOT``: what a scene's ``robot.urdf``
and ``robot.tip`` can name."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import pinocchio as pin

from ..errors import ContactdynError
from .catalog import example_robots, urdf_dir
from .frames import frame_tree
from .urdf_check import check_urdf_tree
from .urdf_model import build_urdf_model

__all__ = ["robot_entries", "frames_command", "end_effectors"]


def end_effectors(model: pin.Model) -> list[str]:
    """Body frames with no frame below them, moved by some joint: the tips a scene would usually name."""
    parents = {f.parentFrame for i, f in enumerate(model.frames) if i}
    return [f.name for i, f in enumerate(model.frames)
            if f.type == pin.FrameType.BODY and i not in parents and f.parentJoint > 0]


_JOINT_DOF = {"revolute": 1, "continuous": 1, "prismatic": 1, "fixed": 0, "floating": 6, "planar": 3}


def _entry(name: str, source: str, file: str) -> dict:
    """DOF and leaf links of a URDF, read from its XML (no Pinocchio build: listing stays fast and safe)."""
    entry = {"name": name, "source": source, "file": file}
    try:
        root = check_urdf_tree(Path(file))
    except ContactdynError as exc:
        return {**entry, "dof": None, "end_effectors": [], "error": str(exc)}
    joints = root.findall("joint")
    above = {j.find("child").get("link"): j for j in joints}  # link -> the joint carrying it (a tree)
    parents = {j.find("parent").get("link") for j in joints}

    def moves(link: str) -> bool:  # some moving joint between the root and the link
        while link in above:
            if above[link].get("type") != "fixed":
                return True
            link = above[link].find("parent").get("link")
        return False

    return {**entry, "dof": sum(_JOINT_DOF.get(j.get("type", ""), 0) for j in joints),
            "end_effectors": [link for link in above if link not in parents and moves(link)]}


def robot_entries() -> list[dict]:
    """Every robot known by name: the project's ``urdf/`` files, then example-robot-data's."""
    entries = [_entry(p.stem, "urdf/", str(p)) for p in sorted(urdf_dir().glob("*.urdf"))]
    entries += [_entry(n, "example-robot-data", str(f)) for n, f in example_robots().items()]
    return entries


def print_robots(entries: list[dict]) -> None:
    for r in entries:
        if r["dof"] is None:
            print(f"  {r['name']:<36} unusable: {r['error']}")
            continue
        tips = r["end_effectors"]
        shown = ", ".join(tips[:4]) + (f" (+{len(tips) - 4} more)" if len(tips) > 4 else "")
        print(f"  {r['name']:<36} {r['dof']:>3} DOF  {r['source']:<18}  tips: {shown}")


def frames_command(args: argparse.Namespace) -> int:
    """Print the kinematic tree of the robot ``args.prefix`` names, with frame types (JSON: the frames)."""
    if not args.prefix:
        raise ContactdynError("list frames: name a robot (contactdyn list frames ROBOT)")
    urdf = build_urdf_model(args.prefix, inertia="trust")
    model = urdf.model
    if args.json:
        frames = [{"name": f.name, "type": str(f.type).rsplit(".", 1)[-1], "parent": model.frames[f.parentFrame].name,
                   "joint": model.names[f.parentJoint]} for f in model.frames]
        print(json.dumps({"robot": str(urdf.path), "dof": model.nv, "end_effectors": end_effectors(model),
                          "frames": frames}, indent=1))
        return 0
    print(f"{urdf.path}: {model.nv} DOF; tips (body frames at the leaves): {', '.join(end_effectors(model))}")
    for line in frame_tree(model, set(urdf.unbounded)):
        print(f"  {line}")
    return 0


def run_warnings(meta: dict) -> list[str]:
    """Console warnings of a run about its robot: inertia repairs or trusts, meshes not found, limit violations."""
    return [f"inertia: {note}" for note in meta.get("inertia_notes", [])] + \
        [f"visual: {note}" for note in meta.get("visual_notes", [])] + list(meta.get("limit_warnings", []))


def run_details(meta: dict) -> list[str]:
    """``run --verbose``: which joints move, which are locked where, how the start posture was found."""
    lines = [f"  robot {meta.get('robot')}, tip {meta.get('tip')}",
             f"  active joints ({len(meta.get('joints', []))}): {', '.join(meta.get('joints', []))}"]
    locked = meta.get("locked", {})
    if locked:
        lines.append(f"  locked joints ({len(locked)}): "
                     + ", ".join(f"{name} = {value:.4g}" for name, value in locked.items()))
    if meta.get("unbounded"):
        lines.append(f"  unbounded joints (continuous): {', '.join(meta['unbounded'])}")
    posture = meta.get("posture") or {}
    if posture:
        extra = ", ".join(f"{k} {v:.3g}" if isinstance(v, float) else f"{k} {v}"
                          for k, v in posture.items() if k != "how")
        lines.append(f"  start posture: {posture['how']}" + (f" ({extra})" if extra else ""))
    return lines
