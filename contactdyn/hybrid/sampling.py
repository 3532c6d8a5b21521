"""The hybrid loop's side of sampled-data control: sample instants as step or segment boundaries.

A phase whose controller is sampled (:mod:`contactdyn.laws.controllers.sampled`) holds its command in the
state between samples. With the compiled DOP853 the integrator takes the sample instants t_k = k / rate [s] as
step boundaries (:class:`Hold`, :mod:`contactdyn.numerics.held_steps`: no step straddles the hold's jump, one
segment carries many samples); with any other method the loop (:mod:`contactdyn.hybrid.loop`) ends a segment at
every t_k. Either way :meth:`SampledPhases.take` runs there: what the law measures at (t_k, x) (a
:class:`~contactdyn.hybrid.sampled_law.Reading`: the joint positions through the encoders, the forces through the
sensors, the contacts' torque on the joints and a carrier's acceleration off the mode's compiled call,
:meth:`~contactdyn.hybrid.pipeline_mode.PipelineMode.measurement`), its command on the reading of ``delay`` samples
ago (by the law's own controller stage: :class:`~contactdyn.hybrid.sampled_law.SampledLaw`) written into the held
slots, its own states advanced by one period.
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
from ..laws.trajectory import min_span
from ..model.contact import ContactMode
from ..model.joint_friction import STUCK
from ..model.phases import Phase
from .events import JUMPING, StageWatch, fired_across, segment_events
from .sampled_law import Reading, SampledLaw, sampled_slots

__all__ = ["SampledPhases", "Hold"]


def _acting(ev, holds: str, gave: str, nv: int) -> np.ndarray:
    """What acts at a sampled phase's start, in what its hold keeps (``holds``: its controller's outputs, "voltage"
    or torques), from the Evaluation ``ev`` of the phase before (whose controller ``gave`` its outputs): its command
    where the two agree, else the motors' voltages [V] or the drives' torques [N·m or N] that act there."""
    if holds == gave:
        return ev.tau_cmd
    return ev.u[:nv] if holds == "voltage" else ev.tau[:nv]


def _command(reading: Reading, z: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(τ, ż) of the law on ``reading``, on the mode it was measured in."""
    return reading.law.command(reading, z)


class SampledPhases:
    """One run's samplers, one per sampled phase (by phase index), and its sample count."""

    def __init__(self, system, stats: dict, runner):
        self.system = system
        #: runner(modes, phase): the run's mode runner (a PipelineMode)
        self.runner = runner
        self.stats = stats
        self.samplers: dict[int, Sampler] = {}
        #: per sampled phase (by index) the slots of x of its held command and of its law's own states
        self.slots: dict[int, tuple[slice, slice]] = {}
        self.laws: dict[object, SampledLaw] = {}  #: per mode's runner its sampled law
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

    def period(self, phase: Phase) -> float:
        """[s] The sample period of a sampled phase."""
        return self.samplers[phase.index].period

    def start(self, t: float, x: np.ndarray, modes: list[ContactMode], phase: Phase, previous: Phase | None
              ) -> np.ndarray:
        """A phase starting at t [s]: if sampled, its sampler and its first sample; the state to go on with."""
        ctl = phase.controller
        if not isinstance(ctl, SampledController):
            return x
        self.samplers[phase.index] = Sampler(ctl, stream=phase.index)
        self.slots[phase.index] = sampled_slots(self.system, phase)
        if previous is not None:  # what acts until this first sample: the previous phase's command
            x = x.copy()
            x[self.slots[phase.index][0]] = _acting(self.runner(modes, previous).evaluation(t, x), ctl.outputs,
                                                    previous.controller.outputs, self.system.nv)
        return self.take(t, x, phase, self.runner(modes, phase))

    def take(self, t: float, x: np.ndarray, phase: Phase, runner) -> np.ndarray:
        """The sample at t [s] of the phase's law: the state with its new held command and states. ``runner``: the
        mode's call (a PipelineMode): what the law measures (the forces, a carrier's acceleration) and its command
        (:class:`~contactdyn.hybrid.sampled_law.SampledLaw`)."""
        sampler = self.samplers[phase.index]
        held, states = self.slots[phase.index]
        law = self.laws.get(runner)
        if law is None:
            law = self.laws[runner] = SampledLaw(runner)
        reading = law.reading(t, x, sampler.resolution, sampler.sense)
        tau, z_law = sampler.update(t, reading, x[states], _command)
        x = x.copy()
        x[held] = tau
        x[states] = z_law
        self.stats["samples"] += 1
        return x

    def hold(self, modes: list[ContactMode], phase: Phase, stop: float, runner) -> Hold:
        """The phase's samples before ``stop`` [s] as step boundaries of one integration (numerics.held_steps),
        measured on ``runner`` (:meth:`take`)."""
        return Hold(self, modes, phase, stop, runner)

    def jumps(self, modes: list[ContactMode], phase: Phase) -> bool:
        """Can a held command's jump fire an event in this mode: a separate, slip, release or joint_slip event
        (the others read the state alone)?"""
        stuck_joint = any(mode == STUCK for _, mode in phase.joint_modes)  # its holding torque jumps with τ
        return bool(phase.limits) or stuck_joint or any(m.touching and (m.stuck or not c.spec.bonded)
                                                        for c, m in zip(self.system.contacts, modes, strict=True))

    def jumped(self, t: float, before: np.ndarray, after: np.ndarray, modes: list[ContactMode], phase: Phase,
               runner) -> list:
        """The events whose function falls through zero from ``before`` to ``after`` at t [s] (a held command's
        jump), in list order; only a mode with a function of forces is checked (:data:`JUMPING`)."""
        if not self.jumps(modes, phase):
            return []  # (no separate, slip, release or joint_slip event in this mode: the others read the state alone)
        events, _ = segment_events(self.system, modes, phase, t, before, runner)
        events = [e for e in events if e.kind in JUMPING]
        return fired_across(events, t, t, before, after) if events else []


class Hold:
    """A sampled phase's samples inside one integration (:mod:`contactdyn.numerics.held_steps`): the instants
    before a segment's stop [s] (one at the stop itself the loop takes, as at a corner), the jump of the held
    command there, and which events the jump can fire (:data:`~contactdyn.hybrid.events.JUMPING`)."""

    def __init__(self, sampled: SampledPhases, modes: list[ContactMode], phase: Phase, stop: float, runner):
        self.sampled, self.modes, self.phase, self.runner = sampled, modes, phase, runner
        self.sampler = sampled.samplers[phase.index]
        self.last = stop - min_span(stop)  #: [s] samples strictly before this
        self.any_jumps = sampled.jumps(modes, phase)

    def next_time(self) -> float:
        """[s] The next sample instant within the segment (inf: none left)."""
        t_k = self.sampler.next_time()
        return t_k if t_k < self.last else math.inf

    def take(self, t: float, x: np.ndarray) -> np.ndarray:
        """The state after the sample at t [s] (:meth:`SampledPhases.take`)."""
        return self.sampled.take(t, x, self.phase, self.runner)

    def event_value(self, event):
        """The function whose fall through zero across a jump fires ``event`` (fired_across's), or None."""
        if not self.any_jumps or getattr(event, "kind", "") not in JUMPING:
            return None
        return event.value if isinstance(event, StageWatch) else event
