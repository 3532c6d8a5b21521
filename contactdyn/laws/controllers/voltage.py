"""Open-loop constant motor voltages: the drives' own response (tests, motor identification)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ...errors import SceneError
from .base import BindContext, ControlInput, Controller, register

__all__ = ["ConstantVoltage"]


@dataclass(frozen=True)
class ConstantVoltageConfig:
    u: np.ndarray  #: [V], one value for every joint or one per joint
    kind: str = "voltage"


@register
class ConstantVoltage(Controller):
    """u = const on every joint's motor (every joint needs a drive that takes a voltage: dc_motor, elastic)."""

    name = "voltage"
    outputs = "voltage"

    @staticmethod
    def read(r) -> ConstantVoltageConfig:
        raw = r.raw("u", 0.0)
        u = r.vector("u", unit="V") if isinstance(raw, list) else np.array([r.float("u", 0.0, unit="V")])
        return ConstantVoltageConfig(u)

    def bind(self, context: BindContext) -> None:
        context.require_motors(f"{context.key}.kind", "a voltage controller")
        if len(self.config.u) not in (1, self.nv):
            raise SceneError(f"{context.key}.u", f"one voltage or {self.nv} (one per joint)", self.config.u.tolist(),
                             context.scene.file)

    def command(self, inp: ControlInput) -> tuple[np.ndarray, None]:
        return np.broadcast_to(self.config.u, (self.nv,)).copy(), None
