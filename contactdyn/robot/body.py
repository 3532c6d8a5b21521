"""An environment body from a URDF: its one prismatic joint, the mass that moves with it, its visuals.

``[body.<name>] urdf = "..."`` names a URDF (a path beside the scene, a name in ``urdf/``) whose root is
fixed in the world and whose one joint is prismatic: the body is the links after it. Its mass [kg] is
theirs summed (inertias checked as a robot's, :mod:`contactdyn.robot.inertia`), its axis the joint's
direction in the world at q = 0, its coordinate the joint's value [m] (the cart of the paper is this
with a box for a visual). Several joints, revolute joints or a free-flyer are not bodies yet (issue 32).
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin

from ..errors import RobotError
from .robot import Robot

__all__ = ["UrdfBody", "load_body"]

_PRISMATIC = ("JointModelPX", "JointModelPY", "JointModelPZ", "JointModelPrismaticUnaligned")


class UrdfBody:
    """A body's URDF loaded: ``robot`` (its one joint active, for its visuals), ``mass`` [kg], ``axis`` (unit,
    world)."""

    def __init__(self, robot: Robot, mass: float, axis: np.ndarray) -> None:
        self.robot, self.mass, self.axis = robot, mass, axis


def load_body(source: str) -> UrdfBody:
    """The body of a URDF with one prismatic joint (a RobotError says what the file has instead)."""
    robot = Robot.load(source)
    model = robot.model
    joints = [model.joints[j].shortname() for j in range(1, model.njoints)]
    if len(joints) != 1 or joints[0] not in _PRISMATIC:
        found = ", ".join(f"{model.names[j]} ({model.joints[j].shortname()})" for j in range(1, model.njoints))
        raise RobotError(f"{robot.source}: a body's URDF has one prismatic joint (several joints, revolute or "
                         f"free-flying bodies are not supported yet); found {found or 'no joint'}")
    data = model.createData()
    q = pin.neutral(model)
    pin.computeJointJacobians(model, data, q)
    J = np.asarray(pin.getJointJacobian(model, data, 1, pin.ReferenceFrame.WORLD)).reshape(6, model.nv)
    axis = J[:3, 0].copy()  # [m/m] the joint's motion in the world
    mass = float(sum(model.inertias[j].mass for j in range(1, model.njoints)))
    if not mass > 0.0:
        raise RobotError(f"{robot.source}: a body's links after its joint carry no mass")
    return UrdfBody(robot, mass, axis / np.linalg.norm(axis))
