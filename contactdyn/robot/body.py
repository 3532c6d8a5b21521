"""An environment body from a URDF: its prismatic joints, the mass that moves with each, its visuals.

``[body.<name>] urdf = "..."`` names a URDF (a path beside the scene, a name in ``urdf/``) whose root is
fixed in the world and whose joints (one to three) are prismatic, in one chain, and mutually orthogonal: the
body translates, one coordinate per joint, its value [m]. Joint k moves the links after it: the mass along
coordinate k [kg] is theirs summed, and with orthogonal axes the body's mass matrix is that diagonal, exactly
(Σ_l m_l a_i·a_j vanishes off it). Inertias are checked as a robot's (:mod:`contactdyn.robot.inertia`); an
axis is the joint's direction in the world at q = 0. The cart of the paper is the one-joint case, with a box
for a visual. Revolute joints or a free-flyer are not bodies yet (issue 32).
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin

from ..errors import RobotError
from .robot import Robot

__all__ = ["UrdfBody", "load_body"]

_PRISMATIC = ("JointModelPX", "JointModelPY", "JointModelPZ", "JointModelPrismaticUnaligned")


class UrdfBody:
    """A body's URDF loaded: ``robot`` (its joints active, for its visuals), ``mass`` [kg] (all its links),
    per joint its name (``joints``), unit axis in the world (``axes``, (k, 3)) and the mass moving along it
    (``masses`` [kg])."""

    def __init__(self, robot: Robot, mass: float, joints: list[str], axes: np.ndarray, masses: np.ndarray) -> None:
        self.robot, self.mass, self.joints, self.axes, self.masses = robot, mass, joints, axes, masses

    @property
    def axis(self) -> np.ndarray:
        """The first joint's unit axis (the one of a one-joint body)."""
        return self.axes[0]


def load_body(source: str) -> UrdfBody:
    """The body of a URDF whose joints are prismatic, chained and orthogonal (a RobotError says what the file
    has instead)."""
    robot = Robot.load(source)
    model = robot.model
    found = ", ".join(f"{model.names[j]} ({model.joints[j].shortname()})" for j in range(1, model.njoints))
    branch = next((f"; joint {model.names[j]}'s parent is {model.names[model.parents[j]]}, not "
                   f"{model.names[j - 1]}" for j in range(1, model.njoints) if model.parents[j] != j - 1), "")
    if not 1 <= model.njoints - 1 <= 3 or branch or \
            any(model.joints[j].shortname() not in _PRISMATIC for j in range(1, model.njoints)):
        raise RobotError(f"{robot.source}: a body's URDF has one to three prismatic joints in one chain (revolute "
                         f"or free-flying bodies are not supported yet); found {found or 'no joint'}{branch}")
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
