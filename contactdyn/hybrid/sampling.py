"""The hybrid loop's side of sampled-data control: sample instants as segment boundaries.

A phase whose controller is sampled (:mod:`contactdyn.laws.controllers.sampled`) holds its command in the
state between samples. The loop (:mod:`contactdyn.hybrid.loop`) ends a segment at every sample instant
t_k = k / rate [s] (no step straddles the hold's jump) and calls :meth:`SampledPhases.take` there: what the law
measures at (t_k, x) (:func:`~contactdyn.model.dynamics.sample_input`, through the sensors), its command from
the measurement of ``delay`` samples ago written into the held slots, its own states advanced by one period.
The events that the command's jump fires (a contact force or a limit torque through zero, a stuck joint's
holding torque past its static limit) are then handled as
at a corner of the set-points (:func:`~contactdyn.hybrid.events.fired_across`). A sampled phase also samples at
its start, its held slots first set to the command in force just before (the previous phase's), so that what
it measures there is what acts.
"""

from __future__ import annotations

import math

import numpy as np

from ..laws.controllers.sampled import SampledController, Sampler
from ..model.contact import ContactMode
from ..model.dynamics import sample_input
from ..model.joint_friction import STUCK
from ..model.phases import Phase
from .events import JUMPING, fired_across, segment_events

__all__ = ["SampledPhases"]


class SampledPhases:
    """One run's samplers, one per sampled phase (by phase index), and its sample count."""

    def __init__(self, system, stats: dict):
        self.system = system
        self.stats = stats
        self.samplers: dict[int, Sampler] = {}
        #: steps of the segments since the last boundary that is not a sample instant: ``auto``'s step budget
        #: (hybrid.events.StepBudget) counts them, as if the samples did not end segments
        self.carried = 0
        self.any = any(isinstance(c, SampledController) for c in system.controllers)
        if self.any:
            stats["samples"] = 0

    def carry(self, sol, sample: bool) -> None:
        """After a segment: its steps carried on if it ended at a sample instant, else none."""
        self.carried = self.carried + len(sol.t) - 1 if sample and sol.status == 0 else 0

    def next_time(self, phase: Phase) -> float:
        """[s] The phase's next sample instant (inf: the phase is continuous)."""
        sampler = self.samplers.get(phase.index) if self.any else None
        return sampler.next_time() if sampler is not None else math.inf

    def start(self, t: float, x: np.ndarray, modes: list[ContactMode], phase: Phase, previous: Phase | None
              ) -> np.ndarray:
        """A phase starting at t [s]: if sampled, its sampler and its first sample; the state to go on with."""
        ctl = phase.controller
        if not isinstance(ctl, SampledController):
            return x
        self.samplers[phase.index] = Sampler(ctl, stream=phase.index)
        if previous is not None:  # what acts until this first sample: the previous phase's command
            x = x.copy()
            held = self._slots(phase, ctl.held)
            x[held] = self.system.evaluate(t, x, modes, previous).tau_cmd
        return self.take(t, x, modes, phase)

    def take(self, t: float, x: np.ndarray, modes: list[ContactMode], phase: Phase) -> np.ndarray:
        """The sample at t [s] of the phase's law: the state with its new held command and states."""
        sampler = self.samplers[phase.index]
        ctl = phase.controller
        inp = sampler.measure(sample_input(self.system, t, x, modes, phase, sampler.resolution))
        tau, z_law = sampler.update(inp, inp.z)
        x = x.copy()
        x[self._slots(phase, ctl.held)] = tau
        x[self._slots(phase, ctl.inner_states)] = z_law
        sampler.passed(t)
        self.stats["samples"] += 1
        return x

    def jumped(self, t: float, before: np.ndarray, after: np.ndarray, modes: list[ContactMode], phase: Phase,
               plan) -> list:
        """The events whose function falls through zero from ``before`` to ``after`` at t [s] (a held command's
        jump), in list order; only a mode with a function of forces is checked (:data:`JUMPING`)."""
        contacts = self.system.contacts
        stuck_joint = any(mode == STUCK for _, mode in phase.joint_modes)  # its holding torque jumps with τ
        if not phase.limits and not stuck_joint and not any(m.touching and (m.stuck or not c.spec.bonded)
                                                            for c, m in zip(contacts, modes, strict=True)):
            return []  # (no separate, slip, release or joint_slip event in this mode: the others read the state alone)
        events, _ = segment_events(self.system, modes, phase, t, before, plan if plan.ok else None)
        events = [e for e in events if e.kind in JUMPING]
        return fired_across(events, t, t, before, after) if events else []

    def _slots(self, phase: Phase, part: slice) -> slice:
        """The slots of x of ``part`` of the phase's controller states."""
        z0 = 2 * self.system.nQ + phase.z_slice.start
        return slice(z0 + part.start, z0 + part.stop)
