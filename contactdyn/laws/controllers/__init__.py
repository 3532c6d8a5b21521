"""Controllers, registered by name (``kind`` in a scene's controller table)."""

from . import dynamic, force, operational, pd, voltage  # noqa: F401  (register position_dynamic, task_pd, ...)
from .base import CONTROLLERS, BindContext, ControlInput, Controller, read_controller, register

__all__ = ["CONTROLLERS", "BindContext", "ControlInput", "Controller", "read_controller", "register"]
