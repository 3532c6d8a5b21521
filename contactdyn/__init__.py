"""contactdyn: dynamics of robot contact tasks on Pinocchio (Potkonjak, Vukobratović, Matijević 1999).

The public names load on first use (PEP 562), so ``contactdyn --help`` and the light commands
start without importing the simulator (Pinocchio, numba, scipy).
"""

from __future__ import annotations

import sys
import types
from importlib import import_module
from typing import TYPE_CHECKING

from .errors import ContactdynError, RobotError, SceneError, SimulationError

if TYPE_CHECKING:
    from .identify import fit
    from .result import Result, load_result
    from .robot import Robot
    from .scene import Scene, load_scene, parse_scene
    from .simulate import simulate

#: public name -> the module that defines it
_LAZY = {"fit": ".identify", "Result": ".result", "load_result": ".result", "Robot": ".robot", "Scene": ".scene",
         "load_scene": ".scene", "parse_scene": ".scene", "simulate": ".simulate"}

__all__ = [
    "ContactdynError", "RobotError", "SceneError", "SimulationError", "Result", "load_result", "Robot",
    "Scene", "load_scene", "parse_scene", "simulate", "fit",
]
__version__ = "0.1.0"


def __getattr__(name: str):
    if name in _LAZY:
        value = getattr(import_module(_LAZY[name], __name__), name)
        globals()[name] = value
        return value
    raise AttributeError(f"module 'contactdyn' has no attribute {name!r}")


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
