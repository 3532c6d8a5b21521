"""What the model answers at one (t, x) in one mode, and what a sampled law measures there.

The right-hand side itself is the one pipeline's call (:mod:`contactdyn.model.pipeline`: robot terms, contacts and
their chains, friction, limit and stuck-joint rows, the controller, the drives, one KKT solve, the rates and the
event values), compiled or interpreted. Its answers at an instant, read off one call with its diagnostics on
(:meth:`~contactdyn.hybrid.pipeline_mode.PipelineMode.evaluation`, :meth:`~.measurement`, :meth:`~.sample_terms`),
are the records here: :class:`Evaluation`, :class:`Measurement`, :class:`SampleTerms`. A sampled law's input at a
sample instant is :func:`sample_input`, through the encoders' resolution.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..laws.controllers import ControlInput
from ..laws.sensors import quantise
from .contact import ContactMode
from .phases import Phase, reference_at

__all__ = ["Evaluation", "Measurement", "SampleTerms", "measures", "sample_input", "set_force_inputs", "surface_keys",
           "surface_points"]


@dataclass
class Evaluation:
    """Everything the right-hand side computes at one (t, x) in one mode."""

    xdot: np.ndarray
    lam: np.ndarray  #: forces of the active rows [N]
    row_meta: list[tuple[str, str, int]]  #: (owner, kind, index) per row (see contactdyn.model.constraints)
    normal_force: dict[str, float]  #: interface force per contact [N], > 0 pressing
    friction: dict[str, np.ndarray]  #: friction force per contact, tangent coordinates [N]
    slip: dict[str, np.ndarray]  #: slip velocity per contact, tangent coordinates [m/s]
    gap: dict[str, float]  #: normal gap [m] (0 while touching)
    stages: dict[str, tuple[float, float, float]]  #: label -> (x [m], ẋ [m/s], F [N])
    interface: dict[str, float]  #: tangential chain interface forces per "contact.t1" [N]
    tau: np.ndarray  #: joint torques [N·m or N]
    body_force: np.ndarray  #: drive force on each body coordinate [N]
    p_tip: np.ndarray  #: controlled tip position [m]
    x_d: np.ndarray | None  #: reference
    force_d: dict[str, float]
    regular: bool = True  #: False when the linear solve fell back to least squares
    tau_cmd: np.ndarray | None = None  #: the controller's command per joint [N·m or N; V for voltage controllers]
    u: np.ndarray | None = None  #: motor voltage per drive (joints, then bodies) [V], NaN for ideal drives
    limit_torque: dict[int, float] = field(default_factory=dict)  #: joint -> limit torque [N·m or N] (pressing)
    joint_hold: dict[int, float] = field(default_factory=dict)  #: stuck joint -> holding torque [N·m or N]
    #: per joint: its damping and dry friction torque [N·m or N] (a stuck joint's: its holding torque); None: none
    joint_friction: np.ndarray | None = None
    #: per chain ("contact.label"): its nodes' positions [m] (where damped ends start relaxing at a separation)
    node_positions: dict[str, np.ndarray] = field(default_factory=dict)


@dataclass
class Measurement:
    """What a sampled law measures of a solved right-hand side at one (t, x), beyond the kinematics: off the mode's call
    (:meth:`~contactdyn.hybrid.pipeline_mode.PipelineMode.measurement`)."""

    normal_force: dict[str, float]  #: per contact [N], > 0 pressing
    interface: dict[str, float]  #: per "contact.t1": a tangential chain's interface force [N]
    tau_contact: np.ndarray | None  #: the contacts' generalized force on the joints [N·m or N] (None: not read)
    carrier_acc: float = 0.0  #: the acceleration of the body carrying the reference [m/s² or rad/s²]


@dataclass
class SampleTerms:
    """What a sampled law reads of the robot and its phase at (t, x), besides the measured forces: off the mode's call
    (:meth:`~contactdyn.hybrid.pipeline_mode.PipelineMode.sample_terms`; :func:`sample_input` without a call: Pinocchio
    and the phase's reference)."""

    H: np.ndarray  #: the law's inertia matrix, reflected rotors included [kg·m²]
    h: np.ndarray  #: Coriolis, centrifugal and uncompensated gravity [N·m or N]
    gravity: np.ndarray | None  #: the uncompensated gravity load [N·m or N], where the law asks
    p_tip: np.ndarray  #: [m]
    v_tip: np.ndarray  #: [m/s]
    J: np.ndarray  #: the tip's Jacobian (3, nv)
    drift: np.ndarray  #: J̇q̇ [m/s²]
    R_tip: np.ndarray  #: the tip frame's orientation (3, 3)
    J_ang: np.ndarray  #: the tip's angular Jacobian (3, nv)
    drift_ang: np.ndarray  #: J̇_ω q̇ [rad/s²]
    x_d: np.ndarray | None  #: the reference (carried by its body, if one carries it); None: the phase has none
    v_d: np.ndarray | None  #: the reference's velocity [m/s]
    a_d: np.ndarray | None  #: the reference's acceleration [m/s²] (without a carrier's: the Measurement's)
    force_d: dict[str, tuple[float, float]]  #: per set-point (F_d [N], Ḟ_d [N/s])


def measures(phase: Phase) -> bool:
    """Does the sampled phase's law measure a solved right-hand side: does it read forces, or is its reference
    carried by a body (its acceleration)?"""
    return phase.controller.inner.uses_forces or phase.carrier is not None


def sample_input(system, t: float, x: np.ndarray, modes: list[ContactMode], phase: Phase,
                 resolution: float = 0.0, measured: Measurement | None = None, terms_at=None) -> ControlInput:
    """What a sampled phase's law (``phase.controller.inner``) measures at a sample instant (t [s], x).

    A law that reads forces gets them from the right-hand side solved there under the command held so far
    (a rigid contact's and a stick's too), and the contacts' generalized force on the joints as the continuous
    model gives it (deformable and friction forces, plus the rows that reach beyond the robot); a reference
    carried by a body gets the body's acceleration. No fold: the command is held, not a function of the forces.
    ``measured``: those (:class:`Measurement`) from the mode's call (required where the law measures forces or its
    reference is carried). ``terms_at(t, x)``: the robot's and the phase's terms there (:class:`SampleTerms`) from
    the mode's call; None: Pinocchio's and the phase's own.
    The kinematics are computed at the joint positions quantised to the encoders' ``resolution`` [rad or m]
    (0: exact). A law that reads no force sees none (as on the compiled path)."""
    nQ, nv = system.nQ, system.nv
    ctl = phase.controller
    law = ctl.inner
    if measured is None and measures(phase):
        raise ValueError("sample_input: the phase's law measures a solved call: pass its Measurement "
                         "(PipelineMode.measurement)")
    xq = x
    if resolution > 0.0:
        xq = x.copy()
        xq[:nv] = quantise(x[:nv], resolution)
    z_law = x[2 * nQ + phase.z_slice.start + ctl.inner_states.start: 2 * nQ + phase.z_slice.stop].copy()
    forces = measured if law.uses_forces else _NO_FORCES
    T = terms_at(t, xq) if terms_at is not None else _pinocchio_terms(system, t, xq, phase, law.needs_gravity)
    inp = ControlInput(t, xq[:nv], xq[nQ:nQ + nv], T.H, T.h, T.gravity, T.p_tip, T.v_tip, T.J, T.drift, T.x_d, T.v_d,
                       T.a_d, {**forces.normal_force, **forces.interface}, T.force_d, system.force_directions, z_law,
                       R_tip=T.R_tip, J_ang=T.J_ang, drift_ang=T.drift_ang)
    if inp.a_d is not None and phase.carrier is not None:  # the carrier's acceleration, known after the solve
        inp.a_d = inp.a_d + phase.carrier[1] * measured.carrier_acc
    if law.uses_forces:
        set_force_inputs(system, inp, x, modes, measured.tau_contact)
    return inp


def _pinocchio_terms(system, t: float, x: np.ndarray, phase: Phase, gravity: bool) -> SampleTerms:
    """:class:`SampleTerms` at (t [s], x) from Pinocchio and the phase's own reference and set-points (no call)."""
    nQ, nv = system.nQ, system.nv
    robot = system.robot
    robot.update(x[:nv], x[nQ:nQ + nv])
    ft = robot.frame_terms(system.tip_fid)
    x_d, v_d, a_d = reference_at(system, phase, t, x)
    return SampleTerms(np.array(system.controller_inertia(robot.H)), np.array(robot.h),  # (copies of Pinocchio's)
                       robot.gravity_torque(x[:nv]) if gravity else None, ft.position, ft.velocity, ft.jacobian,
                       ft.drift, ft.rotation, ft.angular_jacobian, ft.angular_drift, x_d, v_d, a_d,
                       {name: ramp.at(t) for name, ramp in phase.forces.items()})


class _NoForces:
    normal_force: dict = {}
    interface: dict = {}


_NO_FORCES = _NoForces()


def set_force_inputs(system, inp: ControlInput, x: np.ndarray, modes: list[ContactMode],
                     tau_contact: np.ndarray) -> None:
    """What a force-reading controller reads beyond the forces: the contacts' generalized force on the
    joints [N·m or N], the surfaces (and tangential chains' anchors) it presses on, the contact modes."""
    inp.tau_contact = tau_contact
    inp.surfaces = dict(zip(surface_keys(system), surface_points(system, x, modes), strict=True))
    inp.touching = {c.name: m.touching for c, m in zip(system.contacts, modes, strict=True)}


def surface_keys(system) -> list[str]:
    """The keys of :func:`surface_points`: per contact its name, then "<contact>.<label>" per tangential chain."""
    return [key for c in system.contacts for key in (c.name, *(f"{c.name}.{dc.label}" for dc in c.tangent_chains))]


def surface_points(system, x: np.ndarray, modes: list[ContactMode]) -> list[tuple[np.ndarray, np.ndarray]]:
    """[(p [m], v [m/s])] in the order of :func:`surface_keys`: per contact a point of its undeformed surface
    and that point's velocity, per tangential chain its anchor (where it is undeformed since the latest touch)."""
    out = []
    for c, m in zip(system.contacts, modes, strict=True):
        p_env, v_env = c.surface(x, system.nQ)
        out.append((p_env, v_env))
        for i, dc in enumerate(c.tangent_chains):
            out.append((p_env + dc.u * m.offsets[i], v_env))
    return out


