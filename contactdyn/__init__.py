"""contactdyn: dynamics of robot contact tasks on Pinocchio (Potkonjak, Vukobratović, Matijević 1999).

The public names load on first use (PEP 562), so ``contactdyn --help`` and the light commands
start without importing the simulator (Pinocchio, numba, scipy).
"""

from __future__ import annotations

import os
import sys
import types
from importlib import import_module
from typing import TYPE_CHECKING

from .errors import ContactdynError, RobotError, SceneError, SimulationError

if TYPE_CHECKING:
    from .identify import fit
    from .output.result import Result, load_result
    from .robot.robot import Robot
    from .scene.scene_file import Scene, load_scene, parse_scene
    from .simulate import simulate

#: public name -> the module that defines it
_LAZY = {"fit": ".identify", "Result": ".output.result", "load_result": ".output.result", "Robot": ".robot.robot",
         "Scene": ".scene.scene_file", "load_scene": ".scene.scene_file", "parse_scene": ".scene.scene_file",
         "simulate": ".simulate"}

__all__ = [
    "ContactdynError", "RobotError", "SceneError", "SimulationError", "Result", "load_result", "Robot",
    "Scene", "load_scene", "parse_scene", "simulate", "fit",
]
__version__ = "0.1.0"
# While it types a function numba formats a message for every overload it rules out, in colour where colorama is
# installed (a terminal set up and reset per message): ~4 % of a first run's compile. Plain, unless the user set it.
os.environ.setdefault("NUMBA_DISABLE_ERROR_MESSAGE_HIGHLIGHTING", "1")


def __getattr__(name: str):
    if name not in _LAZY:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    value = globals()[name] = getattr(import_module(_LAZY[name], __name__), name)
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(__all__))


class _Package(types.ModuleType):
    """The package: ``contactdyn.simulate`` stays the function when its module ``contactdyn/simulate.py``
    is imported (Python binds a submodule on its package; the eager ``from .simulate import simulate``
    this replaces rebound the function)."""

    def __setattr__(self, name: str, value) -> None:
        if name == "simulate" and isinstance(value, types.ModuleType):
            value = value.simulate
        super().__setattr__(name, value)


sys.modules[__name__].__class__ = _Package
