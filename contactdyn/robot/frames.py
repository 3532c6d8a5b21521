"""Frames of a robot model: finding one by name, the joints above it, the kinematic tree.

A URDF name can belong to several Pinocchio frames: a link and the fixed joint that carries it
share it on some robots (z1's ``gripperStator``). :func:`find_frame` then picks by type, in the
order of :data:`FRAME_PREFERENCE` (the body first), so the choice never depends on file order.
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin

from ..errors import FrameError, close_matches

__all__ = ["FRAME_PREFERENCE", "find_frame", "chain_joints", "frame_tree"]

_T = pin.FrameType
#: frame types in the order a shared name is resolved
FRAME_PREFERENCE = (_T.BODY, _T.OP_FRAME, _T.FIXED_JOINT, _T.JOINT, _T.SENSOR)


def find_frame(model: pin.Model, name: str, source: str) -> int:
    """Index of the frame called ``name`` (body first when several share it); a clear error lists close matches."""
    matches = [model.getFrameId(name, t) for t in FRAME_PREFERENCE if model.existFrame(name, t)]
    if not matches:
        names = list(dict.fromkeys(f.name for f in model.frames))
        close = close_matches(name, names, n=5, cutoff=0.5)
        hint = f"; close matches: {', '.join(map(repr, close))}" if close else ""
        raise FrameError(f"{source}: no frame named {name!r}{hint} (contactdyn list frames ROBOT shows them all)")
    return matches[0]  # in FRAME_PREFERENCE's order


def chain_joints(model: pin.Model, fid: int) -> list[str]:
    """Names of the joints from the root down to the frame, root first."""
    jid = model.frames[fid].parentJoint
    chain = []
    while jid > 0:
        chain.append(model.names[jid])
        jid = model.parents[jid]
    return chain[::-1]


def _joint_text(model: pin.Model, jid: int, unbounded: set[str]) -> str:
    joint = model.joints[jid]
    kind = joint.shortname().removeprefix("JointModel")
    name = model.names[jid]
    if joint.nq != 1:
        return kind
    lo, hi = model.lowerPositionLimit[joint.idx_q], model.upperPositionLimit[joint.idx_q]
    unit = "m" if kind.startswith("P") else "rad"
    limits = "unbounded (continuous)" if name in unbounded or not np.isfinite(lo) else f"[{lo:.4g}, {hi:.4g}] {unit}"
    return f"{kind} {limits}"


def frame_tree(model: pin.Model, unbounded: set[str] | frozenset = frozenset()) -> list[str]:
    """The kinematic tree as indented lines: each frame with its type (joints with their kind and limits)."""
    children: dict[int, list[int]] = {}
    for i, f in enumerate(model.frames):
        if i:
            children.setdefault(f.parentFrame, []).append(i)
    lines = []
    stack = [(0, 0)]
    while stack:
        fid, depth = stack.pop()
        f = model.frames[fid]
        kind = str(f.type).rsplit(".", 1)[-1]
        extra = f" {_joint_text(model, f.parentJoint, unbounded)}" if f.type == _T.JOINT else ""
        lines.append(f"{'  ' * depth}{f.name} [{kind}{extra}]")
        stack += [(c, depth + 1) for c in reversed(children.get(fid, []))]
    return lines
