"""Sampled-data control: a controller running at a fixed rate with a zero-order hold, delayed measurements
and sensor models.

A phase whose controller table sets ``sample_rate`` [Hz] runs its law (any kind: built-in or a user's) as a
real controller would: at the sample instants t_k = k / rate [s] it measures (:mod:`contactdyn.laws.sensors`),
pushes the measurement into a delay line, computes its command from the measurement of ``delay`` samples ago
and holds that command until the next sample (zero-order hold).

The held command lives in the state: :class:`SampledController` wraps the law, and its states are
[held command (nv), the law's own states]; all of them have ẏ = 0 between samples, and its command is the held
slots. What is held (``hold``): the law's command as it gives it (``"command"``: torques, which DC motors then
realise between samples as an ideal current loop would, their voltage following the back-EMF), or, with a motor on
every joint, the voltages a torque law's command asks of the motors at the sample (``"voltage"``: eq. 51 inverted at
the measured speeds, as a drive without a current loop holds its PWM; between samples the motors' torque falls
with their speed).
So the right-hand side between two samples is an ordinary smooth one (the one pipeline's call reads the held command
off the state, torques or voltages, through the drives where there are motors), and at every sample instant (a step
boundary of the compiled DOP853, a segment boundary for other methods: :mod:`contactdyn.hybrid.sampling`) the new
command is written into the state and the events its jump fires are checked. The law's own states (integrators)
advance once per sample, by forward Euler over the hold to the next sample: z_{k+1} = z_k + (t_{k+1} − t_k) ż_k. A
phase starts sampling at its start (the delay line filled with that first measurement; a new phase starts a new line
and new sensor states) and then on the scene's grid k / rate: a hold is the period T, the first one shorter where
the phase starts off the grid (z then integrates ż over the time that passed, as the continuous law does).

What the law computes on at t_k is the whole input it measured at t_{k−d} (time, state, references, forces),
with its own states as they are at t_k: a delay of d samples shifts a law of the measured input alone by
exactly d samples.
"""

from __future__ import annotations

import math
from collections import deque

import numpy as np

from ...errors import SimulationError
from ..failures import counted_states
from ..sensors import ForceSensor, Sampling
from .base import BindContext, ControlInput, Controller

__all__ = ["SampledController", "Sampler", "Sampling"]  # Sampling (the keys): contactdyn.laws.sensors


class SampledController(Controller):
    """A phase's law run at samples with a zero-order hold: its command is the held slots of its states."""

    name = ""  # (not registered: it wraps a registered law)
    uses_forces = False  # the held command reads no force between samples
    needs_gravity = False
    reads_orientation = False

    def __init__(self, inner: Controller, sampling: Sampling, nv: int):
        super().__init__(inner.config, nv)
        self.inner, self.sampling = inner, sampling
        self.outputs = "voltage" if sampling.hold == "voltage" else inner.outputs

    @property
    def holds_voltage(self) -> bool:
        """Does the hold keep the motors' voltages of a torque law's command (``hold = "voltage"``)?"""
        return self.sampling.hold == "voltage" and self.inner.outputs == "torque"

    def bind(self, context: BindContext) -> None:
        self.inner.bind(context)
        self.n_states = self.nv + counted_states(self.inner)
        if self.sampling.hold == "voltage":
            context.require_motors(f"{context.key}.hold", 'hold = "voltage"')

    @property
    def held(self) -> slice:
        """The held command's slots within the controller's states."""
        return slice(0, self.nv)

    @property
    def inner_states(self) -> slice:
        """The law's own states within the controller's states."""
        return slice(self.nv, self.n_states)

    def command(self, inp: ControlInput) -> tuple[np.ndarray, np.ndarray | None]:
        """τ = the held command [N·m or N; V]; ẏ = 0 for every slot."""
        return inp.z[: self.nv].copy(), np.zeros(self.n_states) if self.n_states else None


#: [periods] a grid instant this close after a sample is that sample: a phase begun at a touch 1e-13 s before an
#: instant of the grid takes one sample, not two 1e-13 s apart (which would shorten its delay line by one period)
SAME_SAMPLE = 1e-9


class Sampler:
    """One run of a sampled phase: the sample counter, the delay line and the sensors."""

    def __init__(self, controller: SampledController, stream: int = 0):
        self.controller = controller
        s = controller.sampling
        self.rate, self.period, self.delay = s.rate, s.period, s.delay
        self.force_sensor = ForceSensor(s.sensor, s.period, stream)
        self.line: deque = deque(maxlen=s.delay + 1)  #: the latest delay + 1 readings (hybrid.sampled_law)
        self.next_index = 0  #: k of the next sample instant k / rate on the grid

    @property
    def resolution(self) -> float:
        """[rad or m] the joint encoders' resolution (0: exact)."""
        return self.controller.sampling.sensor.encoder_resolution

    def next_time(self) -> float:
        """[s] the next sample instant on the grid."""
        return self.next_index / self.rate

    def passed(self, t: float) -> None:
        """A sample taken at t [s]: the next on the grid comes after it, and not within SAME_SAMPLE periods of it
        (a phase begun just before an instant of the grid samples there, not twice)."""
        self.next_index = max(self.next_index, math.floor(t * self.rate) + 1)
        while self.next_index / self.rate <= t + SAME_SAMPLE * self.period:  # (also: floor of a rounded product)
            self.next_index += 1

    def sense(self, forces: dict[str, float]) -> dict[str, float]:
        """The force sensor's readings [N] of the true ``forces`` [N] by key (contacts, tangential chains)."""
        return self.force_sensor.read(forces)

    def update(self, t: float, reading, z_law: np.ndarray, command) -> tuple[np.ndarray, np.ndarray]:
        """At the sample at t [s]: push ``reading`` (what was measured now), compute on the one of ``delay`` samples ago
        with the law's states ``z_law`` as they are now (``command(reading, z) -> (τ, ż)``); (the new held command,
        the law's states at the next sample). The next sample on the grid comes after it (:meth:`passed`)."""
        if not self.line:  # a phase's first sample: the line filled with it
            self.line.extend([reading] * (self.delay + 1))
        else:
            self.line.append(reading)
        tau, zdot = command(self.line[0], z_law)
        on_grid = t == self.next_time()
        self.passed(t)
        hold = self.period if on_grid else self.next_time() - t  # [s] shorter from a phase's start off the grid
        z_new = z_law + hold * zdot if zdot is not None and len(z_law) else z_law.copy()
        if not all(map(math.isfinite, z_new.tolist())):  # (held until the next sample: every call there would fail)
            raise SimulationError(f"t = {t:.6g} s: {self.controller.inner.name}: the law's own states are not finite "
                                  f"after this sample (z = {np.asarray(z_law).tolist()}, ż = "
                                  f"{np.asarray(zdot).tolist()}, over {hold:g} s)")
        return np.asarray(tau, float), z_new
