"""The controller interface: read the state and measured forces, write joint torques.

A controller never reaches into the integrator. It receives a :class:`ControlInput`
(state, tip kinematics, model terms, references and measured contact forces) and returns
joint torques [N·m or N] and the rates of its own states (integrators), if it has any.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np

__all__ = ["ControlInput", "Controller", "CONTROLLERS", "register", "read_controller", "FEEDFORWARD"]

FEEDFORWARD = ("none", "gravity", "bias")


@dataclass
class ControlInput:
    t: float  #: scene time [s]
    q: np.ndarray  #: joint positions [rad or m]
    v: np.ndarray  #: joint velocities
    H: np.ndarray  #: inertia matrix (true model)
    h: np.ndarray  #: Coriolis, centrifugal and uncompensated gravity
    gravity: np.ndarray | None  #: uncompensated gravity load g(q), when the controller asked for it
    p_tip: np.ndarray  #: tip position [m]
    v_tip: np.ndarray  #: tip velocity [m/s]
    J: np.ndarray  #: tip Jacobian (3, nv)
    drift: np.ndarray  #: J̇q̇ [m/s²]
    x_d: np.ndarray | None  #: reference position (task [m] or joint), None when the phase has none
    v_d: np.ndarray | None
    a_d: np.ndarray | None
    forces: dict[str, float]  #: measured normal contact force per contact [N], > 0 pressing
    force_d: dict[str, tuple[float, float]]  #: force set-point and its rate per contact [N, N/s]
    normals: dict[str, np.ndarray]  #: contact normals (unit, world)
    z: np.ndarray  #: controller states
    R_tip: np.ndarray | None = None  #: tip frame orientation (3, 3)
    J_ang: np.ndarray | None = None  #: tip angular Jacobian (3, nv)


class Controller:
    """Base class: subclasses set ``name``, a ``Config`` and implement :meth:`command`."""

    name: ClassVar[str] = ""
    n_states: int = 0
    needs_gravity: bool = False

    def __init__(self, config: Any, nv: int):
        self.config = config
        self.nv = nv

    def initial_states(self, inp: ControlInput) -> np.ndarray:
        return np.zeros(self.n_states)

    def command(self, inp: ControlInput) -> tuple[np.ndarray, np.ndarray | None]:
        """Joint torques and the rates of the controller's states."""
        raise NotImplementedError


CONTROLLERS: dict[str, type] = {}


def register(cls: type) -> type:
    CONTROLLERS[cls.name] = cls
    return cls


def read_controller(reader) -> Any:
    """Validate a controller table into its kind's config (the kind's ``read`` does the keys)."""
    kind = reader.str("kind", "task_pd", choices=sorted(CONTROLLERS))
    config = CONTROLLERS[kind].read(reader)
    reader.finish()
    return config
