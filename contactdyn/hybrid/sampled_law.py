"""A sampled law's command at a sample instant, on the one pipeline's own controller stage.

At a sample the law computes its command from what it measured (:mod:`contactdyn.hybrid.sampling`): the state with
the joint positions as the encoders read them, the forces as the sensors read them (a :class:`Reading`).
:class:`SampledLaw` packs the mode once more with the law itself in place of its held command, as a continuous run
of that law packs it, and evaluates that pipeline's controller stage on the measured forces
(:func:`~contactdyn.model.pipeline.pipeline.law_at`: one compiled call; no fold: the forces are measured, not solved
with the command). So a law runs the same stage at a sample as in a continuous run: compiled where numba compiles it,
its declared Python stage where not.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from ..errors import SimulationError
from ..laws.abi import raise_python_stage_error
from ..laws.failures import naming_laws, no_command_error
from ..laws.sensors import quantise
from ..model.evaluation import measures
from ..model.pipeline.actuation import held_voltages
from ..model.pipeline.pack import EV_FN, EV_W, NQ, W_DIAG
from ..model.pipeline.pipeline import Pipeline, law_at
from ..numerics.twins import Twins

__all__ = ["Reading", "SampledLaw", "sampled_slots"]

_NOTHING = np.zeros(0)  #: a reading's generalized contact force where the law reads none


def sampled_slots(system, phase) -> tuple[slice, slice]:
    """The slots of x of a sampled phase's held command and of its law's own states."""
    ctl = phase.controller
    z0 = 2 * system.nQ + phase.z_slice.start
    return tuple(slice(z0 + part.start, z0 + part.stop) for part in (ctl.held, ctl.inner_states))


@dataclass
class Reading:
    """What a sampled law measured at one sample instant: an entry of its delay line."""

    t: float  #: [s] the sample instant
    x: np.ndarray  #: the state there, its joint positions as the encoders read them
    forces: dict[str, float]  #: [N] per contact and tangential chain ("contact.t1"), as the sensors read them
    tau_contact: np.ndarray  #: [N·m or N] the contacts' generalized force on the joints (empty: not read)
    carrier_acc: float  #: [m/s² or rad/s²] the acceleration of the body carrying the reference (0: none)
    law: SampledLaw  #: the law on the mode measured in (its contacts' states: touching, the surfaces)


class SampledLaw:
    """A sampled phase's law on one mode (a :class:`~contactdyn.hybrid.pipeline_mode.PipelineMode` of the phase): what
    it measures there (:meth:`reading`) and its command on a :class:`Reading`."""

    def __init__(self, mode):
        system, phase = mode.system, mode.phase
        self.states = sampled_slots(system, phase)[1]  #: the law's own states in x, after the held command
        z_at = self.states.start - 2 * system.nQ
        law_phase = replace(phase, controller=phase.controller.inner, z_slice=slice(z_at, phase.z_slice.stop))
        self.pipe = Pipeline(system, mode.modes, law_phase, mode.pipe.twins, law_only=True)
        self.mode, self.modes = mode, mode.modes  #: the mode measured on, and its modes as last used
        self.controller = phase.controller.inner
        self.holds_voltage = phase.controller.holds_voltage  #: the hold keeps the motors' voltages of τ
        ints = self.pipe.packed.ints
        #: per measured key: (True: ``events``' slot, False: ``work``'s) where the stage reads it
        self.slots: dict[str, tuple[bool, int]] = {}
        k = 0
        for ci, c in enumerate(system.contacts):
            self.slots[c.name] = (True, EV_W * ci + EV_FN)
            for i, dc in enumerate(c.chains):
                if i > 0:  # (each chain's interface force, pack's order: the normal chain first)
                    self.slots[f"{c.name}.{dc.label}"] = (False, int(ints[W_DIAG]) + 1 + k)
                k += 1

    def reading(self, t: float, x: np.ndarray, resolution: float = 0.0, sense=None) -> Reading:
        """What the law measures at (t [s], x) on its mode: the joint positions through encoders of ``resolution``
        [rad or m] (0: exact), the forces through ``sense`` (a dict of forces [N] by key -> the sensor's readings;
        None: exact), the contacts' generalized force on the joints and a carrier's acceleration off one call with the
        diagnostics on (:meth:`~contactdyn.hybrid.pipeline_mode.PipelineMode.measurement`), where the law reads them."""
        mode = self.mode
        if mode.modes is not self.modes:  # (a turn's new 2-D reference directions: data of the same packed mode)
            self.pipe.use(mode.modes)
            self.modes = mode.modes
        xq = np.array(x, float)
        if resolution > 0.0:
            nv = self.pipe.system.nv
            xq[:nv] = quantise(xq[:nv], resolution)
        m = mode.measurement(t, x) if measures(mode.phase) else None
        if m is None or not self.controller.uses_forces:  # (at most a carried reference's acceleration)
            return Reading(t, xq, {}, _NOTHING, m.carrier_acc if m is not None else 0.0, self)
        forces = {**m.normal_force, **m.interface}
        return Reading(t, xq, sense(forces) if sense is not None else forces, m.tau_contact, m.carrier_acc, self)

    def command(self, reading: Reading, z: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(τ [N·m or N; V], ż) of the law on ``reading`` with its own states ``z`` as they are now; with ``hold =
        "voltage"`` τ turned into the motors' voltages [V] at the measured speeds (:func:`held_voltages`)."""
        tau, zdot, finite = self._stage(self.pipe, reading, z)
        if not finite:
            self._failed(reading, z, tau)
        if self.holds_voltage:
            p = self.pipe.packed
            u = self.pipe.of(held_voltages)(reading.x, p.ints, p.reals, np.ascontiguousarray(tau, dtype=float))
            if not np.isfinite(u).all():
                raise_python_stage_error(reading.t)  # a drive kind's declared Python stage's own error
                raise SimulationError(f"t = {reading.t:.6g} s: a motor's voltage law gave no finite voltage for the "
                                      f"held command τ = {np.asarray(tau).tolist()} (hold = \"voltage\")")
            return u, zdot
        return tau, zdot

    def _stage(self, pipe: Pipeline, reading: Reading, z: np.ndarray) -> tuple[np.ndarray, np.ndarray, bool]:
        """(τ, ż, τ finite) of ``pipe``'s controller stage on ``reading`` (:func:`law_at`, as ``pipe`` runs it)."""
        x = reading.x.copy()
        x[self.states] = z
        p = pipe.packed
        for key, value in reading.forces.items():
            in_events, k = self.slots[key]
            (p.events if in_events else p.work)[k] = value
        tau, zdot, bq, dq, finite = pipe.of(law_at)(float(reading.t), x, p.ints, p.reals, p.work, p.events,
                                            reading.tau_contact)
        if reading.carrier_acc != 0.0:  # (the law is affine in its reference's acceleration: the fold's column)
            tau, zdot = tau + bq * reading.carrier_acc, zdot + dq * reading.carrier_acc
        return tau, zdot, finite

    def _failed(self, reading: Reading, z: np.ndarray, tau: np.ndarray) -> None:
        """Raise the law's own error at ``reading`` (a user's law's as its LawError): a declared Python stage's, a
        compiled law's (the same stage run interpreted raises it from the law's source), else the controller's words
        (its command τ not finite)."""
        raise_python_stage_error(reading.t)
        pipe = self.pipe
        if pipe.twins is None:
            with naming_laws(reading.t):
                self._stage(Pipeline(pipe.system, pipe.modes, pipe.phase, Twins(), law_only=True), reading, z)
            raise_python_stage_error(reading.t)  # (its law a Python stage there: its exception kept)
        nv, nQ = pipe.system.nv, pipe.packed.ints[NQ]
        raise no_command_error(self.controller, tau, reading.x[:nv], reading.x[nQ:nQ + nv], reading.t)
