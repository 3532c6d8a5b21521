"""Task phases at run time: a phase's controller, reference trajectory and force set-points.

A scene's ``[[phase]]`` list is a sequence of task phases (approach, press, slide…), each
ending at a time or at a touch (``until = "touch:<contact>"``). At run time a phase gets
absolute times: its moves and force ramps start when the phase starts. A reference is in
task space (tip position x_d [m]) or joint space (q_d [rad or m]); carried by an active
body (``reference.body``), it rides with that body: x_d = axis · Q_b + reference.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from ..errors import SceneError
from ..laws.controllers import Controller
from ..laws.trajectory import Corner, Ramp, Reference, merge_corners, min_span
from ..scene.scene_file import PhaseSpec

__all__ = ["Phase", "start_phase", "reference_at", "reference_positions"]


@dataclass
class Phase:
    """A task phase at run time: its controller, reference and force set-points (absolute times)."""

    spec: PhaseSpec
    index: int
    t_start: float  #: [s]
    controller: Controller
    z_slice: slice
    reference: Reference | None = None
    forces: dict[str, Ramp] = field(default_factory=dict)
    #: (body coordinate, unit axis) when the reference rides on an active body (``reference.body``):
    #: x_d = axis · Q_b + reference (see :func:`reference_at`)
    carrier: tuple[int, np.ndarray] | None = None
    #: joints pressing on a position limit: (coordinate, +1 lower / −1 upper), see contactdyn.model.limits
    limits: tuple[tuple[int, int], ...] = ()
    #: the corners of its reference and force set-points, in time order (absolute times)
    corners: tuple[Corner, ...] = ()
    #: the dry-friction joints' modes: (coordinate, 0 stuck / ±1 sliding sign), see contactdyn.model.joint_friction
    joint_modes: tuple[tuple[int, int], ...] = ()

    def key(self) -> tuple:
        """What tells this phase's compiled modes apart: the phase itself (its index, its start [s], its bound
        controller) and the joints pressing on a limit and the dry-friction joints' modes. A copy made for a limit or
        a joint's friction mode (``dataclasses.replace``) that returns to an earlier set has the earlier key, so its
        pipelines are found again instead of packed and checked anew."""
        return self.index, self.t_start, id(self.controller), self.limits, self.joint_modes

    def next_corner(self, t: float, t_end: float) -> Corner | None:
        """The first corner not yet passed at t [s] that comes before t_end [s] (by more than min_span), or None."""
        for c in self.corners:
            if c.after > t:
                return c if c.before < t_end - min_span(t_end) else None
        return None


def start_phase(system, index: int, t: float, x: np.ndarray, previous: Phase | None) -> Phase:
    """Phase ``index`` of ``system``'s scene starting at t [s] in state x (after ``previous``).

    A reference without a start continues where the previous reference (same space), or
    the tip, is; moves and force ramps are shifted to start at t.
    """
    spec = system.scene.phases[index]
    controller = system.controllers[index]
    reference = carrier = None
    if spec.reference is not None:
        ref = spec.reference
        if ref.body != "ground":
            carrier = (system.body_index[ref.body], system.scene.bodies[ref.body].axis)
        if ref.start is not None:
            start = ref.start.copy()
        else:  # continue where the previous reference, or the tip, is (absolute), relative to the carrier
            if previous is not None and previous.reference is not None and \
                    previous.spec.reference is not None and previous.spec.reference.space == ref.space:
                start = reference_at(system, previous, t, x)[0]
            else:
                q = x[: system.nv]
                start = system.robot.frame_position(q, system.tip_fid) if ref.space == "task" else q.copy()
            if carrier is not None:
                start = start - carrier[1] * x[carrier[0]]
        dims = 3 if ref.space == "task" else system.nv
        if len(start) != dims:
            raise SceneError(f"phase[{index}].reference", f"{dims}-vectors in {ref.space} space",
                             len(start), system.scene.file)
        moves = tuple(replace(m, start=m.start + t) for m in ref.moves)
        for m in moves:
            if len(m.delta) != dims:
                raise SceneError(f"phase[{index}].reference.moves", f"{dims}-vectors", len(m.delta),
                                 system.scene.file)
        reference = Reference(start, moves)
    forces = {f.key: Ramp(f.ramp.value, f.ramp.start + t, f.ramp.duration, f.ramp.kind, f.ramp.initial)
              for f in spec.forces}
    corners = merge_corners([*(reference.corners() if reference is not None else ()),
                             *(c for ramp in forces.values() for c in ramp.corners())])
    joint_modes = previous.joint_modes if previous is not None else system.joint_friction.initial_modes(x, system.nQ)
    return Phase(spec, index, t, controller, system.z_slices[index], reference, forces, carrier,
                 previous.limits if previous is not None else (), corners, joint_modes)


def reference_at(system, phase: Phase, t: float, x: np.ndarray):
    """The phase's reference (x_d, v_d, a_d) at (t, x), or Nones.

    A reference carried by a body adds the body's origin o = axis · Q_b and its velocity to
    x_d and v_d. Its acceleration axis · Q̈_b is an unknown of the linear system: ``evaluate``
    adds it to a_d there (folded, like measured forces), not here.
    """
    if phase.reference is None:
        return None, None, None
    x_d, v_d, a_d = phase.reference.at(t)
    if phase.carrier is not None:
        i, axis = phase.carrier
        x_d, v_d = x_d + axis * x[i], v_d + axis * x[system.nQ + i]
    return x_d, v_d, a_d


def reference_positions(system, phase: Phase, ts: np.ndarray, X: np.ndarray) -> np.ndarray:
    """x_d of :func:`reference_at` at each sample (ts[k], X[k]), as rows (its arithmetic elementwise over them)."""
    x_d = phase.reference.positions(ts)
    if phase.carrier is not None:
        i, axis = phase.carrier
        x_d = x_d + axis * X[:, i, None]
    return x_d
