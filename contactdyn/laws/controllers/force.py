"""Open-loop task-space force: a constant, a ramp and a sinusoid applied at the tip.

    f(t) = force + rate · clip(t − start, 0, ramp_time) + amplitude ∘ sin(2π frequency t + phase)
    τ = Jᵀ f [+ feedforward]

All vectors are world-frame 3-vectors acting on the controlled tip frame; t is scene
time [s]. No feedback: the push a test needs to know exactly (a tangential push that
grows until a body breaks away, a rotating push that drives a body round a circle).
Feedforward as for the PD laws: ``none``, ``gravity`` (g(q)) or ``bias`` (h(q, q̇)).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .base import FEEDFORWARD, ControlInput, Controller, register

__all__ = ["TaskForce", "TaskForceConfig"]


@dataclass(frozen=True)
class TaskForceConfig:
    force: np.ndarray  #: constant part [N]
    rate: np.ndarray  #: growth rate [N/s], acting from ``start`` for ``ramp_time``
    start: float  #: [s] scene time the ramp begins
    ramp_time: float  #: [s] how long the ramp grows (inf: for ever)
    amplitude: np.ndarray  #: sinusoid amplitude per axis [N]
    frequency: float  #: [Hz]
    phase: np.ndarray  #: sinusoid phase per axis [rad]
    feedforward: str
    kind: str = "task_force"


@register
class TaskForce(Controller):
    """Open-loop tip force: constant + ramp + sinusoid, tau = J^T f (no feedback)."""

    name = "task_force"

    @staticmethod
    def read(r) -> TaskForceConfig:
        zero = [0.0, 0.0, 0.0]
        return TaskForceConfig(
            force=r.vector("force", zero, size=3, unit="N"),
            rate=r.vector("rate", zero, size=3, unit="N/s"),
            start=r.float("start", 0.0, lo=0.0, unit="s"),
            ramp_time=r.float("ramp_time", math.inf, lo=0.0, unit="s"),
            amplitude=r.vector("amplitude", zero, size=3, unit="N"),
            frequency=r.float("frequency", 0.0, lo=0.0, unit="Hz"),
            phase=r.vector("phase", zero, size=3, unit="rad"),
            feedforward=r.str("feedforward", "none", choices=FEEDFORWARD),
        )

    def __init__(self, config: TaskForceConfig, nv: int):
        super().__init__(config, nv)
        self.needs_gravity = config.feedforward == "gravity"
        self._oscillates = bool(np.any(config.amplitude)) and config.frequency > 0.0

    def force(self, t: float) -> np.ndarray:
        """The commanded tip force f(t) [N]."""
        c = self.config
        f = c.force + c.rate * min(max(t - c.start, 0.0), c.ramp_time)
        if self._oscillates:
            f = f + c.amplitude * np.sin(2.0 * math.pi * c.frequency * t + c.phase)
        return f

    def command(self, inp: ControlInput) -> tuple[np.ndarray, None]:
        tau = inp.J.T @ self.force(inp.t)
        ff = inp.h if self.config.feedforward == "bias" else inp.gravity if self.config.feedforward == "gravity" \
            else None
        return (tau + ff if ff is not None else tau), None
