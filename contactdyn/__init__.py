"""contactdyn: dynamics of robot contact tasks on Pinocchio (Potkonjak, Vukobratović, Matijević 1999)."""

from .errors import ContactdynError, RobotError, SceneError, SimulationError
from .identify import fit
from .result import Result, load_result
from .robot import Robot
from .scene import Scene, load_scene, parse_scene
from .simulate import simulate

__all__ = [
    "ContactdynError", "RobotError", "SceneError", "SimulationError", "Result", "load_result", "Robot",
    "Scene", "load_scene", "parse_scene", "simulate", "fit",
]
__version__ = "0.1.0"
