"""An environment body from a URDF: its joints, the mass that moves with each, its visuals.

``[body.<name>] urdf = "..."`` names a URDF (a path beside the scene, a name in ``urdf/``) whose root is
fixed in the world and whose joints (one to three) are prismatic, in one chain, and mutually orthogonal: the
body translates, one coordinate per joint, its value [m]. Joint k moves the links after it: the mass along
coordinate k [kg] is theirs summed, and with orthogonal axes the body's mass matrix is that diagonal, exactly
(Σ_l m_l a_i·a_j vanishes off it). Inertias are checked as a robot's (:mod:`contactdyn.robot.inertia`); an
axis is the joint's direction in the world at q = 0. The cart of the paper is the one-joint case, with a box
for a visual.

A URDF with any revolute joint (beside prismatic ones, in a tree fixed in the world) is an *articulated body*: its
joints are coordinates of the system (angles [rad], lengths [m]) whose mass matrix H_b(q_b) and bias h_b(q_b, q̇_b)
(gravity the world's) come from its own Pinocchio model, :class:`ArticulatedBody` at run time.

A *free* body (``free = true``; its URDF's root link is the body, or a ``floating`` joint joins a massless world
link to it) is an articulated body whose root link has six coordinates of its own, nq = nv: x, y, z [m] of the
root frame's origin in the world, then its ZYX Euler angles yaw, pitch, roll [rad] (R = Rz(yaw) Ry(pitch)
Rx(roll)), one-coordinate joints of the rewritten URDF (:func:`contactdyn.robot.urdf_model.add_free_joints`). At
pitch = ±90° yaw and roll turn about one axis (H_b singular): the angles then run in a second chart, R = Rz Ry Rx(b)
· C (:mod:`contactdyn.robot.free_chart`; its own Pinocchio model, the same frames), switched by the hybrid loop's
``chart`` event (:mod:`contactdyn.hybrid.charts`); the chart in use is a slot of the state (:class:`ArticulatedBody`).
A ``planar`` joint <j> becomes three one-coordinate joints <j>_x, <j>_y [m] (in the plane) and <j>_yaw [rad] (about
its normal, the joint's ``<axis>``; :func:`contactdyn.robot.urdf_model.split_planar_joints`): an articulated body.
Any other joint of several coordinates (spherical, a floating joint below the root) is one RobotError naming it.
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin

from ..errors import RobotError, SimulationError
from .free_chart import SWITCH_COS, switch, turned_model
from .robot import Robot
from .urdf_model import FREE_COORDINATES, build_urdf_model

__all__ = ["UrdfBody", "ArticulatedBody", "load_body"]

_PRISMATIC = ("JointModelPX", "JointModelPY", "JointModelPZ", "JointModelPrismaticUnaligned")
_REVOLUTE = ("JointModelRX", "JointModelRY", "JointModelRZ", "JointModelRevoluteUnaligned")


class UrdfBody:
    """A body's URDF loaded: ``robot`` (its joints active, for its visuals), ``mass`` [kg] (all its links),
    per joint its name (``joints``), unit axis in the world (``axes``, (k, 3)) and the mass moving along it
    (``masses`` [kg]). An articulated body (``articulated``): ``axes`` its joints' axes in the world at q = 0
    (rotation or travel), ``masses`` zeros (its mass matrix is H_b(q_b), :class:`ArticulatedBody`)."""

    def __init__(self, robot: Robot, mass: float, joints: list[str], axes: np.ndarray, masses: np.ndarray,
                 articulated: bool = False) -> None:
        self.robot, self.mass, self.joints, self.axes, self.masses = robot, mass, joints, axes, masses
        self.articulated = articulated

    @property
    def axis(self) -> np.ndarray:
        """The first joint's unit axis (the one of a one-joint body)."""
        return self.axes[0]


def load_body(source: str, free: bool = False) -> UrdfBody:
    """The body of a URDF whose joints are prismatic, chained and orthogonal, or articulated (a revolute joint
    among them, or ``free``: its root link moves freely; a RobotError says what the file has instead)."""
    robot = _load(source, free)
    model = robot.model
    kinds = [model.joints[j].shortname() for j in range(1, model.njoints)]
    if any(k in _REVOLUTE for k in kinds):
        return _articulated(robot)
    found = ", ".join(f"{model.names[j]} ({model.joints[j].shortname()})" for j in range(1, model.njoints))
    branch = next((f"; joint {model.names[j]}'s parent is {model.names[model.parents[j]]}, not "
                   f"{model.names[j - 1]}" for j in range(1, model.njoints) if model.parents[j] != j - 1), "")
    if not 1 <= model.njoints - 1 <= 3 or branch or \
            any(model.joints[j].shortname() not in _PRISMATIC for j in range(1, model.njoints)):
        raise RobotError(f"{robot.source}: a body's URDF has one to three prismatic joints in one chain (with a "
                         f"revolute joint among them, any tree: an articulated body); found "
                         f"{found or 'no joint'}{branch}")
    data = model.createData()
    pin.computeJointJacobians(model, data, pin.neutral(model))
    J = np.asarray(pin.getJointJacobian(model, data, model.njoints - 1, pin.ReferenceFrame.WORLD)).reshape(6, model.nv)
    axes = J[:3].T.copy()  # [m/m] each joint's motion in the world
    axes /= np.linalg.norm(axes, axis=1)[:, None]
    cosines = np.abs(axes @ axes.T - np.eye(len(axes)))
    if cosines.max() > 1e-9:
        raise RobotError(f"{robot.source}: a body's prismatic joints are mutually orthogonal (its mass matrix is "
                         f"then diagonal); found axes {np.round(axes, 6).tolist()}")
    links = [float(model.inertias[j].mass) for j in range(1, model.njoints)]
    masses = np.array([sum(links[k:]) for k in range(len(links))])  # joint k moves the links after it
    if not masses[-1] > 0.0:
        raise RobotError(f"{robot.source}: a body's links after its last joint carry no mass")
    return UrdfBody(robot, float(masses[0]), [model.names[j] for j in range(1, model.njoints)], axes, masses)


def _load(source: str, free: bool = False) -> Robot:
    """The body's Robot (its planar joints split in three); a joint of several coordinates left (a free-flyer,
    spherical) is one RobotError."""
    urdf = build_urdf_model(source, free=free, body=True)
    model = urdf.model
    several = [f"{model.names[j]} ({model.joints[j].shortname()})" for j in range(1, model.njoints)
               if model.joints[j].nq != 1 or model.joints[j].nv != 1]
    if several:
        raise RobotError(f"{urdf.path}: a body's joints are revolute, prismatic or planar (a planar one becomes three "
                         f"joints of one coordinate each; a free-flying body, a floating joint from a world link or "
                         f"none, is declared free = true); found {', '.join(several)}")
    return Robot.load(source, free=free, body=True)


def _articulated(robot: Robot) -> UrdfBody:
    """An articulated body: its joints' names, their axes in the world at q = 0, its mass [kg]."""
    model = robot.model
    other = [f"{model.names[j]} ({model.joints[j].shortname()})" for j in range(1, model.njoints)
             if model.joints[j].shortname() not in _REVOLUTE + _PRISMATIC]
    if other:
        raise RobotError(f"{robot.source}: a body's joints are revolute or prismatic; found {', '.join(other)}")
    data = model.createData()
    pin.computeJointJacobians(model, data, pin.neutral(model))
    axes = np.zeros((model.nv, 3))
    for j in range(1, model.njoints):
        J = np.asarray(pin.getJointJacobian(model, data, j, pin.ReferenceFrame.WORLD)).reshape(6, model.nv)
        k = model.joints[j].idx_v
        revolute = model.joints[j].shortname() in _REVOLUTE
        axes[k] = J[3:, k] if revolute else J[:3, k]
    mass = float(sum(model.inertias[j].mass for j in range(1, model.njoints)))
    return UrdfBody(robot, mass, list(robot.joint_names), axes, np.zeros(model.nv), articulated=True)


PITCH_LIMIT = 1e-6  #: [-] a free body's |cos(pitch)| of its active chart below this: its chart switch was missed


class ArticulatedBody:
    """An articulated body at run time: its Pinocchio model (gravity the world's) and where its coordinates sit
    in Q (``first``, ``nb`` of them, in the URDF's joint order). A free body has two models, one per chart
    (:mod:`contactdyn.robot.free_chart`: ``robots``, the same frames and ids), the one in use read from the state
    (``chart_index``: its slot in x, 0 chart A, 1 chart B; a discrete state, constant between events).

    :meth:`update` computes its terms at the state's (q_b, q̇_b) once per state (the last one kept): H_b
    [kg·m², kg], h_b [N·m, N] (Coriolis, centrifugal, gravity), and the frames' terms of :meth:`frame`."""

    def __init__(self, name: str, robot: Robot, first: int, free: bool = False) -> None:
        self.name, self.first, self.nb = name, first, robot.nv
        self.free = free  #: its root link moves freely: six coordinates, two charts (contactdyn.robot.free_chart)
        #: a free body's pitch's index in q_b (its coordinates FREE_COORDINATES first), else None
        self.pitch = FREE_COORDINATES.index("pitch") if free else None
        self.robots = (robot,)  #: per chart its model (a free body: A, then B turned by free_chart.C)
        if free:
            turned = turned_model(robot.model, robot.model.getJointId(FREE_COORDINATES[-1]))
            self.robots = (robot, Robot(turned, robot.source))
        self.chart = 0  #: the chart of the last update (0: A, 1: B)
        self.chart_index = -1  #: a free body's chart's index in the state x (System sets it), else −1
        self._key: bytes | None = None
        self._v = np.zeros(self.nb)  #: q̇_b at the last update [rad/s or m/s]

    @property
    def robot(self) -> Robot:
        """The model of the chart in use (the last update's)."""
        return self.robots[self.chart]

    @property
    def indices(self) -> range:
        """The body's coordinates' indices in Q."""
        return range(self.first, self.first + self.nb)

    def chart_of(self, x: np.ndarray) -> int:
        """The chart (0: A, 1: B) the state x is in; 0 for a body that is not free."""
        return int(x[self.chart_index]) if self.chart_index >= 0 else 0

    def update(self, x: np.ndarray, nQ: int) -> None:
        """The body's terms at the state x (its q_b [rad or m] and q̇_b [rad/s or m/s], a free body's chart); nothing
        when unchanged. A free body's pitch within PITCH_LIMIT of ±90° in its chart is a SimulationError: its chart
        switch (at |cos pitch| = free_chart.SWITCH_COS) was missed."""
        q, v = x[self.first:self.first + self.nb], x[nQ + self.first:nQ + self.first + self.nb]
        chart = self.chart_of(x)
        key = q.tobytes() + v.tobytes() + bytes([chart])
        if key != self._key:
            if self.free and abs(float(np.cos(q[self.pitch]))) < PITCH_LIMIT:
                raise SimulationError(f"body {self.name!r}: its pitch reached ±90° in chart {'AB'[chart]} (now "
                                      f"{float(q[self.pitch]):.9g} rad), where its Euler angles are singular: its "
                                      f"chart switch was missed (a step across it); lower solver.max_step")
            self.chart = chart
            self._v = np.array(v, float)
            self.robot.update(np.array(q, float), self._v)
            self._key = key

    def switched(self, x: np.ndarray, nQ: int) -> np.ndarray:
        """x with a free body's six coordinates re-expressed in its other chart (the same position, rotation R, ω
        [rad/s] and origin velocity [m/s]: :func:`contactdyn.robot.free_chart.switch`), and that chart's flag."""
        sl, chart = slice(self.first, self.first + 6), self.chart_of(x)
        x = np.array(x, float)
        x[sl], x[nQ:][sl] = switch(x[sl], x[nQ:][sl], chart)
        x[self.chart_index] = 1 - chart
        return x

    def start_chart(self, x: np.ndarray, nQ: int) -> np.ndarray:
        """x in the chart a free body starts in: A, or B where |cos pitch_A| < free_chart.SWITCH_COS."""
        if not self.free or abs(float(np.cos(x[self.first + self.pitch]))) >= SWITCH_COS:
            return x
        return self.switched(x, nQ)

    @property
    def H(self) -> np.ndarray:
        """H_b [kg·m², kg] at the last update."""
        return self.robot.H

    @property
    def h(self) -> np.ndarray:
        """h_b [N·m, N] at the last update: Coriolis, centrifugal and gravity."""
        return self.robot.h

    def frame(self, fid: int):
        """The frame's FrameTerms at the last update (Jacobians over the body's nb coordinates)."""
        return self.robot.frame_terms(fid)

    def point(self, fid: int, p0: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """(p [m], v [m/s], J (3, nb) [m/rad or m/m], J̇q̇ [m/s²]) of the point p0 [m] fixed in frame fid (its
        coordinates) at the last update (:meth:`FrameTerms.point` at r = R p0)."""
        ft = self.robot.frame_terms(fid)
        return ft.point(ft.rotation @ p0, ft.angular_jacobian @ self._v)

    def energy(self, q: np.ndarray, v: np.ndarray, chart: int = 0) -> float:
        """[J] its kinetic energy ½ q̇_bᵀ H_b q̇_b and its gravity potential at (q_b, q̇_b) in ``chart`` (0: A)."""
        robot = self.robots[chart]
        return robot.kinetic_energy(q, v) + robot.potential_energy(q)
