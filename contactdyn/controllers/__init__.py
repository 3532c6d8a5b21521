"""Controllers, registered by name (``kind`` in a scene's controller table)."""

from . import force, pd  # noqa: F401  (registers task_force, task_pd, joint_pd)
from .base import CONTROLLERS, ControlInput, Controller, read_controller, register

__all__ = ["CONTROLLERS", "ControlInput", "Controller", "read_controller", "register"]
