"""The robot model: a thin, allocation-light layer over Pinocchio.

A :class:`Robot` is loaded from a URDF path, a file in the project's ``urdf/`` folder, or a
robot name (:mod:`contactdyn.robot.catalog`); :mod:`contactdyn.robot.urdf_model` finds, checks and
builds the URDF. It gives H(q), h(q, q̇), frame placements, world-aligned frame Jacobians and
the drift term J̇q̇. Only the active joints are degrees of freedom: by default the joints on the
chain from the root to the tip frame (fingers, the other arm, a head stay locked), or all
joints when no tip is named. A locked joint holds its value in ``locked``, else its neutral
value: 0 clipped into its limits. A fraction of gravity can be compensated statically.
Every active joint must move some mass (H(q0)ᵢᵢ > 0), else H is singular. Units: SI, radians.
"""

from __future__ import annotations

import functools
import os
from collections.abc import Callable
from typing import TYPE_CHECKING, NamedTuple

import numpy as np
import pinocchio as pin

from ..errors import RobotError, close_matches
from ..numerics.linalg import cross3
from .catalog import example_robots, urdf_dir
from .frames import chain_joints, find_frame
from .rigid_body import rigid_table
from .urdf_check import isolated_build
from .urdf_model import UrdfModel, build_isolated, build_urdf_model, lock_joints, xml_label
from .urdf_source import resolve_robot_path

if TYPE_CHECKING:
    from ..scene.scene_file import RobotSpec

__all__ = ["Robot", "FrameTerms", "EXAMPLE_ROBOTS", "urdf_dir", "resolve_robot_path"]

_LWA = pin.ReferenceFrame.LOCAL_WORLD_ALIGNED

#: example-robot-data names and their URDF files (derived from the installed package)
EXAMPLE_ROBOTS = example_robots()


def joint_unit(model: pin.Model, jid: int) -> str:
    """The unit of joint ``jid``'s coordinate: "m" for a prismatic joint, else "rad"."""
    kind = model.joints[jid].shortname().removeprefix("JointModel")
    return "m" if kind.startswith("Prismatic") or kind in ("PX", "PY", "PZ") else "rad"


def _neutral_value(model: pin.Model, i: int) -> float:
    """0 clipped into the joint's limits [rad or m]."""
    return float(np.clip(0.0, model.lowerPositionLimit[i], model.upperPositionLimit[i]))


def _lock_values(model: pin.Model, names: list[str], locked: dict[str, float], path) -> dict[str, float]:
    """Value of each locked joint [rad or m]: as given, else neutral; within the joint's limits."""
    values = {}
    for name in names:
        jid = model.getJointId(name)
        i, nq = model.idx_qs[jid], model.nqs[jid]
        if nq != 1:
            if name in locked:
                raise RobotError(f"{path}: locked joint {name!r} has {nq} coordinates: only 1-DOF joints can be "
                                 "locked at a value")
            raise RobotError(f"{path}: joint {name!r} has {nq} coordinates (spherical, planar or free): "
                             "not supported")
        value = float(locked[name]) if name in locked else _neutral_value(model, i)
        lo, hi = model.lowerPositionLimit[i], model.upperPositionLimit[i]
        if not lo <= value <= hi:
            unit = joint_unit(model, jid)
            raise RobotError(f"{path}: locked joint {name!r} at {value} {unit} is outside its limits [{lo}, {hi}] "
                             f"{unit}")
        values[name] = value
    return values


def _copy_limits(full: pin.Model, model: pin.Model, active: list[str]) -> None:
    """The full model's position limits (±inf for continuous joints) on the reduced model's joints."""
    lower, upper = model.lowerPositionLimit.copy(), model.upperPositionLimit.copy()
    for name in active:
        i, k = model.idx_qs[model.getJointId(name)], full.idx_qs[full.getJointId(name)]
        lower[i], upper[i] = full.lowerPositionLimit[k], full.upperPositionLimit[k]
    model.lowerPositionLimit, model.upperPositionLimit = lower, upper


def _active_names(urdf: UrdfModel, tip: str | None, active_joints: list[str] | None,
                  locked: dict[str, float]) -> list[str]:
    """The active joints: as given, else the tip's chain (or all joints) minus the locked ones."""
    full, path = urdf.model, urdf.path
    names = [full.names[j] for j in range(1, full.njoints)]
    for key, given in (("robot.locked", list(locked)), ("robot.active_joints", list(active_joints or []))):
        for name in given:
            if name not in names:
                raise RobotError(f"{path}: no joint named {name!r}{_suggest(name, names)}; joints: {names}",
                                 f"{key}.{name}" if key == "robot.locked" else key)
    if active_joints is not None:
        both = sorted(set(active_joints) & set(locked))
        if both:
            raise RobotError(f"{path}: joint(s) {both} are both active and locked", "robot.active_joints")
        return [n for n in names if n in active_joints]
    chain = chain_joints(full, find_frame(full, tip, str(path))) if tip is not None else names
    return [n for n in names if n in chain and n not in locked]


def _build_visual(path, model: pin.Model, xml: str) -> pin.GeometryModel:
    def build() -> pin.GeometryModel:
        return pin.buildGeomFromUrdfString(model, xml, pin.GeometryType.VISUAL)

    isolated_build(path, xml_label("buildGeomFromUrdfString", xml), build)
    try:
        return build()
    except (ValueError, RuntimeError) as exc:  # the mesh loader's multi-line report: keep its message line
        lines = [ln.strip() for ln in str(exc).splitlines() if ln.strip()]
        detail = next((ln for ln in lines if ln.startswith("message:")), lines[0] if lines else "?")
        raise RobotError(f"{path}: a visual mesh cannot be loaded: {detail}") from None


class FrameTerms(NamedTuple):
    """Kinematics of one frame's origin at the last :meth:`Robot.update` (world-aligned)."""

    position: np.ndarray  #: p [m], shape (3,)
    velocity: np.ndarray  #: ṗ = J q̇ [m/s], shape (3,)
    jacobian: np.ndarray  #: J = ∂p/∂q, linear rows [m/rad or m/m], shape (3, nv)
    drift: np.ndarray  #: J̇ q̇ [m/s²], shape (3,)
    rotation: np.ndarray  #: frame orientation in the world, shape (3, 3)
    angular_jacobian: np.ndarray  #: ω = J_ω q̇ [rad/s per joint unit], shape (3, nv)
    angular_drift: np.ndarray  #: J̇_ω q̇ [rad/s²], shape (3,)

    def point(self, r: np.ndarray, w: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """(p [m], v [m/s], J (3, nv) [m/rad or m/m], J̇q̇ [m/s²]) of the point fixed in the frame at r [m] from its
        origin (world-aligned), the frame turning at ω = ``w`` [rad/s]: p = o + r, v = v_o + ω × r,
        J = J_o − [r]× J_ω, J̇q̇ = a_o + α × r + ω × (ω × r)."""
        skew = np.array([[0.0, -r[2], r[1]], [r[2], 0.0, -r[0]], [-r[1], r[0], 0.0]])
        J = self.jacobian - skew @ self.angular_jacobian
        w_r = cross3(w, r)
        drift = self.drift + cross3(self.angular_drift, r) + cross3(w, w_r)
        return self.position + r, self.velocity + w_r, J, drift


class Robot:
    """A fixed-base robot with only its active joints as degrees of freedom.

    Two Pinocchio data objects: ``data`` holds the state of the last :meth:`update` (read by
    :attr:`H`, :attr:`h`, :meth:`frame_terms`); the allocating convenience functions use their
    own, so calling them between an update and its reads changes nothing.
    """

    def __init__(self, model: pin.Model, source: str, gravity_compensation: float = 0.0, *,
                 locked: dict[str, float] | None = None,
                 visual: pin.GeometryModel | Callable[[], pin.GeometryModel] | None = None):
        self.model = model
        self.data = model.createData()
        self._aux = model.createData()
        self.source = source
        self.gravity_compensation = gravity_compensation  #: fraction of gravity compensated statically
        self.locked = dict(locked or {})  #: locked joint -> value [rad or m]
        self.nq, self.nv = model.nq, model.nv
        self.joint_names = [model.names[j] for j in range(1, model.njoints)]
        self.joint_units = [joint_unit(model, j) for j in range(1, model.njoints)]  #: "rad" or "m" per joint
        self._visual = visual
        self.notes: list[str] = []  #: inertia repairs or trusts (see contactdyn.robot.inertia), one line each
        self.visual_notes: list[str] = []  #: visual meshes not found and left out of the drawing
        self.unbounded: list[str] = []  #: active joints without position limits (continuous in the URDF)
        self.lower = model.lowerPositionLimit.copy()  #: position limits of the active joints [rad or m]
        self.upper = model.upperPositionLimit.copy()
        self.velocity_limit = model.velocityLimit.copy()  #: [rad/s or m/s], 0: none given
        self.effort_limit = model.effortLimit.copy()  #: [N·m or N], 0: none given
        if self.nv == 0:
            raise RobotError(f"{source}: no active joint (the robot has nothing to move)")
        if self.nq != self.nv:
            raise RobotError(
                f"{source}: joints with nq != nv (spherical, planar or free) are not supported as active joints; "
                "lock them"
            )
        diag = np.diag(pin.crba(model, self._aux, pin.neutral(model)))
        if np.any(diag <= 0.0):
            idle = [n for n, d in zip(self.joint_names, diag, strict=True) if d <= 0.0]
            raise RobotError(f"{source}: joint(s) {idle} move no mass or inertia (H(q0) is singular): "
                             "give the links they carry an inertial, or lock them")

    # ---- loading -----------------------------------------------------------------------
    @classmethod
    def load(
        cls,
        source: str | os.PathLike,
        *,
        tip: str | None = None,
        active_joints: list[str] | None = None,
        locked: dict[str, float] | None = None,
        gravity: tuple[float, float, float] = (0.0, 0.0, -9.81),
        gravity_compensation: float = 0.0,
        inertia: str = "check",
        free: bool = False,
        body: bool = False,
    ) -> Robot:
        """Load a robot; keep ``active_joints`` (default: the chain to ``tip``, else all) and lock the rest.

        ``locked`` gives values [rad or m] for locked joints (default: neutral, see the module
        docstring); a value outside the joint's limits is an error. ``gravity`` [m/s²];
        ``gravity_compensation`` is the fraction of the gravity load removed by a static
        compensator (0 ≤ c ≤ 1; case 1 uses 0.7). ``inertia``: "check", "repair" or "trust"
        (see :mod:`contactdyn.robot.inertia`). ``free``: the URDF's root link moves freely, by six coordinates
        (:func:`contactdyn.robot.urdf_model.add_free_joints`); ``body``: a scene body's URDF (its planar joints split,
        :func:`contactdyn.robot.urdf_model.split_planar_joints`). Visual meshes are checked to exist now but loaded on
        first use of :attr:`visual_model`.
        """
        if not 0.0 <= gravity_compensation <= 1.0:
            raise RobotError(f"gravity_compensation must be in [0, 1], found {gravity_compensation}")
        urdf = build_urdf_model(source, inertia, free, body)
        full, path = urdf.model, urdf.path
        locked = dict(locked or {})
        active = _active_names(urdf, tip, active_joints, locked)
        lock_names = [full.names[j] for j in range(1, full.njoints) if full.names[j] not in active]
        values = _lock_values(full, lock_names, locked, path)
        xml = lock_joints(urdf, values) if values else urdf.xml
        model = build_isolated(path, xml_label("buildModelFromXML", xml), lambda: pin.buildModelFromXML(xml)) \
            if values else full
        _copy_limits(full, model, active)
        model.gravity.linear = (1.0 - gravity_compensation) * np.asarray(gravity, dtype=float)
        visual = functools.partial(_build_visual, path, model, xml)
        robot = cls(model, str(path), gravity_compensation, locked=values, visual=visual)
        robot.notes, robot.visual_notes = list(urdf.notes), list(urdf.visual_notes)
        robot.unbounded = [n for n in urdf.unbounded if n in robot.joint_names]
        return robot

    @classmethod
    def from_spec(cls, spec: RobotSpec) -> Robot:
        """The robot a scene's ``[robot]`` table names (what the simulation and the viewer load)."""
        active = list(spec.active_joints) if spec.active_joints else None
        return cls.load(spec.source, tip=spec.tip, active_joints=active, locked=spec.locked,
                        gravity=tuple(spec.gravity), gravity_compensation=spec.gravity_compensation,
                        inertia=spec.inertia)

    def describe(self) -> dict:
        """Which joints move and which are locked where, the inertia and visual notes (stored with a run)."""
        return {"joints": list(self.joint_names), "locked": dict(self.locked), "unbounded": list(self.unbounded),
                "inertia_notes": list(self.notes), "visual_notes": list(self.visual_notes)}

    @property
    def visual_model(self) -> pin.GeometryModel:
        """Visual geometry with meshes resolved, built on first use (loading meshes takes ~0.3 s)."""
        if callable(self._visual):
            self._visual = self._visual()
        return self._visual

    @functools.cached_property
    def rigid_table(self) -> np.ndarray | None:
        """The model's table for the pipeline's own dynamics (:func:`contactdyn.robot.rigid_body.rigid_table`; None: a
        joint it does not compute), built once."""
        return rigid_table(self.model)

    def frame_id(self, name: str) -> int:
        """Index of a named frame (the body's when several share the name); a clear error lists close matches."""
        return find_frame(self.model, name, self.source)

    # ---- the right-hand-side path: one update, then cheap reads ---------------------
    def update(self, q: np.ndarray, v: np.ndarray) -> None:
        """Compute H, h, joint Jacobians and the zero-acceleration kinematics at (q, q̇).

        q, v: float64 arrays of length nv [rad or m], [rad/s or m/s] (not checked here: hot path).
        """
        pin.computeAllTerms(self.model, self.data, q, v)

    @property
    def H(self) -> np.ndarray:
        """Joint-space inertia matrix [kg·m² / kg] at the last update (full, symmetric; a view)."""
        return self.data.M

    @property
    def h(self) -> np.ndarray:
        """Coriolis, centrifugal and uncompensated gravity terms [N·m / N] at the last update (a view)."""
        return self.data.nle

    def frame_terms(self, fid: int) -> FrameTerms:
        """Position, velocity, Jacobian and J̇q̇ of frame ``fid`` at the last update (new arrays)."""
        model, data = self.model, self.data
        placement = pin.updateFramePlacement(model, data, fid)
        J6 = pin.getFrameJacobian(model, data, fid, _LWA).reshape(6, self.nv)  # eigenpy gives (6,) for nv = 1
        drift = pin.getFrameClassicalAcceleration(model, data, fid, _LWA)
        return FrameTerms(
            placement.translation,  # placement is already a copy of data.oMf[fid]
            pin.getFrameVelocity(model, data, fid, _LWA).linear,
            J6[:3],
            drift.linear,
            placement.rotation,
            J6[3:],
            drift.angular,
        )

    # ---- convenience (allocating, own data) ---------------------------------------------
    def _fid(self, frame: str | int) -> int:
        return self.frame_id(frame) if isinstance(frame, str) else int(frame)

    def mass_matrix(self, q: np.ndarray) -> np.ndarray:
        """H(q) [kg·m² / kg], a copy."""
        return pin.crba(self.model, self._aux, np.asarray(q, float)).copy()

    def bias(self, q: np.ndarray, v: np.ndarray) -> np.ndarray:
        """h(q, q̇) = C(q, q̇)q̇ + (1 − compensation)·g(q) [N·m / N], a copy."""
        return pin.nonLinearEffects(self.model, self._aux, np.asarray(q, float), np.asarray(v, float)).copy()

    def gravity_torque(self, q: np.ndarray) -> np.ndarray:
        """Uncompensated part of the gravity load, (1 − compensation)·g(q) [N·m / N], a copy."""
        return pin.computeGeneralizedGravity(self.model, self._aux, np.asarray(q, float)).copy()

    def frame_placement(self, q: np.ndarray, frame: str | int) -> pin.SE3:
        """World placement of the frame [m, rotation matrix], a copy."""
        fid = self._fid(frame)
        pin.framesForwardKinematics(self.model, self._aux, np.asarray(q, float))
        return self._aux.oMf[fid].copy()

    def frame_position(self, q: np.ndarray, frame: str | int) -> np.ndarray:
        """World position of the frame's origin [m]."""
        return self.frame_placement(q, frame).translation.copy()

    def frame_jacobian(self, q: np.ndarray, frame: str | int) -> np.ndarray:
        """World-aligned 6×nv Jacobian (linear rows first) of the frame's origin."""
        fid = self._fid(frame)
        J = pin.computeFrameJacobian(self.model, self._aux, np.asarray(q, float), fid, _LWA)
        return J.reshape(6, self.nv).copy()  # eigenpy gives (6,) for nv = 1

    def frame_drift(self, q: np.ndarray, v: np.ndarray, frame: str | int) -> np.ndarray:
        """J̇q̇ of the world-aligned Jacobian: linear [m/s²] (classical) then angular [rad/s²], shape (6,)."""
        fid = self._fid(frame)
        model, data = self.model, self._aux
        pin.forwardKinematics(model, data, np.asarray(q, float), np.asarray(v, float), np.zeros(self.nv))
        pin.updateFramePlacement(model, data, fid)
        return pin.getFrameClassicalAcceleration(model, data, fid, _LWA).vector.copy()

    def kinetic_energy(self, q: np.ndarray, v: np.ndarray) -> float:
        """½ q̇ᵀ H q̇ [J]."""
        return float(pin.computeKineticEnergy(self.model, self._aux, np.asarray(q, float), np.asarray(v, float)))

    def potential_energy(self, q: np.ndarray) -> float:
        """Potential energy of the uncompensated gravity [J]."""
        return float(pin.computePotentialEnergy(self.model, self._aux, np.asarray(q, float)))


def _suggest(name: str, names: list[str]) -> str:
    close = close_matches(name, names)
    return f" (did you mean {', '.join(map(repr, close))}?)" if close else ""
