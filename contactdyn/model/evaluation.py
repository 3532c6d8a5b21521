"""What the model answers at one (t, x) in one mode, and what a sampled law measures there.

The right-hand side itself is the one pipeline's call (:mod:`contactdyn.model.pipeline`: robot terms, contacts and
their chains, friction, limit and stuck-joint rows, the controller, the drives, one KKT solve, the rates and the
event values), compiled or interpreted. Its answers at an instant, read off one call with its diagnostics on
(:meth:`~contactdyn.hybrid.pipeline_mode.PipelineMode.evaluation`, :meth:`~.measurement`), are the records here:
:class:`Evaluation`, :class:`Measurement`. A sampled law's command on what it measures is
:class:`~contactdyn.hybrid.sampled_law.SampledLaw`'s.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..laws.controllers.base import ControlInput
from .phases import Phase

__all__ = ["Evaluation", "Measurement", "measures", "surface_keys", "sample_input", "sample_inputs"]


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


def measures(phase: Phase) -> bool:
    """Does the sampled phase's law measure a solved right-hand side: does it read forces, or is its reference
    carried by a body (its acceleration)?"""
    return phase.controller.inner.uses_forces or phase.carrier is not None


def surface_keys(system) -> list[str]:
    """The keys of a readable ControlInput's dictionaries of forces and surfaces (a declared Python stage's, rebuilt
    from its buffer's "keys" field): per contact its name, then "<contact>.<label>" per tangential chain."""
    return [key for c in system.contacts for key in (c.name, *(f"{c.name}.{dc.label}" for dc in c.tangent_chains))]


def sample_input(system, spec, ctl) -> ControlInput:
    """A ControlInput of phase ``spec``'s bound controller ``ctl`` before any run, where its declared properties are
    tried (:func:`~contactdyn.laws.failures.checked_affine_in_forces`): the robot at rest at its ``q0`` (else at 0), the
    reference at its start (else where the robot is) at rest, the set-points 0, every contact touching at the tip with
    its measured forces 0 [N], τ_c = 0 [N·m or N], the states 0."""
    robot, nv, fid = system.robot, system.nv, system.tip_fid
    q0 = system.scene.robot.q0
    q, v = (np.array(q0, float) if q0 is not None and len(q0) == nv else np.zeros(nv)), np.zeros(nv)
    J6, drift6, tip = robot.frame_jacobian(q, fid), robot.frame_drift(q, v, fid), robot.frame_placement(q, fid)
    ref = spec.reference
    x_d = None if ref is None else np.array(ref.start if ref.start is not None else
                                            tip.translation if ref.space == "task" else q, float)
    rest = None if x_d is None else np.zeros_like(x_d)
    keys = surface_keys(system)
    return ControlInput(0.0, q, v, system.controller_inertia(robot.mass_matrix(q)), robot.bias(q, v),
                        robot.gravity_torque(q) if ctl.needs_gravity else None, tip.translation.copy(), np.zeros(3),
                        J6[:3], drift6[:3], x_d, rest, None if rest is None else rest.copy(),
                        forces=dict.fromkeys(keys, 0.0), force_d={f.key: (0.0, 0.0) for f in spec.forces},
                        normals=system.force_directions, z=np.zeros(ctl.n_states), R_tip=tip.rotation.copy(),
                        J_ang=J6[3:], drift_ang=drift6[3:], tau_contact=np.zeros(nv),
                        surfaces={key: (tip.translation.copy(), np.zeros(3)) for key in keys},
                        touching={c.name: True for c in system.contacts})


#: what :func:`sample_inputs` moves: the joints' speed [rad/s or m/s], the set-points [N], the law's states
MOVING_SPEED, MOVING_SET_POINT, MOVING_STATE = 0.5, 10.0, 0.1


def sample_inputs(system, spec, ctl) -> list[ControlInput]:
    """:func:`sample_input`, and the same robot moving (every joint at MOVING_SPEED, h at that speed), its set-points
    at MOVING_SET_POINT and its states at MOVING_STATE: a law affine in the forces at rest but not in motion (its
    command clipped where a speed term adds to it) is tried there too."""
    rest = sample_input(system, spec, ctl)
    v = np.full(system.nv, MOVING_SPEED)
    drift6 = system.robot.frame_drift(rest.q, v, system.tip_fid)
    moving = rest.replaced(v=v, h=system.robot.bias(rest.q, v), v_tip=rest.J @ v, drift=drift6[:3],
                           drift_ang=drift6[3:], z=np.full(ctl.n_states, MOVING_STATE),
                           force_d={key: (MOVING_SET_POINT, 0.0) for key in rest.force_d})
    return [rest, moving]
