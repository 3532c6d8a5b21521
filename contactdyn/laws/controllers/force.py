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

from ...numerics.compile_cache import njit
from ...numerics.linalg import contiguous, mtv
from ...numerics.twins import current
from .base import FEEDFORWARD, ControlInput, Controller, register

__all__ = ["TaskForce", "TaskForceConfig", "task_force", "task_force_torque"]


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
        c, vec = config, lambda a: contiguous(np.asarray(a, float))
        #: task_force's arguments after t: force, rate, start, ramp_time, amplitude, frequency, phase, oscillates
        self.constants = (vec(c.force), vec(c.rate), float(c.start), float(c.ramp_time), vec(c.amplitude),
                          float(c.frequency), vec(c.phase), self._oscillates)

    def force(self, t: float) -> np.ndarray:
        """The commanded tip force f(t) [N]."""
        return task_force(t, *self.constants)

    def command(self, inp: ControlInput) -> tuple[np.ndarray, None]:
        ff = inp.h if self.config.feedforward == "bias" else inp.gravity if self.config.feedforward == "gravity" \
            else None
        tau = current(task_force_torque)(float(inp.t), contiguous(inp.J), *self.constants,
                                         _NONE if ff is None else contiguous(ff))
        return tau, None


_NONE = np.empty(0)


@njit(cache=True)
def task_force(t, force, rate, start, ramp_time, amplitude, frequency, phase, oscillates):
    """f(t) = force + rate · clip(t − start, 0, ramp_time) [+ amplitude ∘ sin(2π frequency t + phase)] [N]."""
    f = force + rate * min(max(t - start, 0.0), ramp_time)
    if oscillates:
        f = f + amplitude * np.sin(2.0 * math.pi * frequency * t + phase)
    return f


@njit(cache=True)
def task_force_torque(t, J, force, rate, start, ramp_time, amplitude, frequency, phase, oscillates, tau_ff):
    """τ = Jᵀ f(t) [+ τ_ff] [N·m or N] (no feedforward: τ_ff of size 0), compiled once for every path."""
    tau = mtv(J, task_force(t, force, rate, start, ramp_time, amplitude, frequency, phase, oscillates))
    if tau_ff.size:
        return tau + tau_ff
    return tau
