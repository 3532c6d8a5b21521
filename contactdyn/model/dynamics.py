"""The readable right-hand side: everything the model computes at one (t, x) in one mode.

In a smooth phase (modes and task phase fixed) the state x = [Q, Q̇, y]
(:mod:`contactdyn.model.system`) moves by

    d/dt [Q, Q̇, y] = [Q̇, Q̈, ẏ]

with Q̈ and the active rows' forces λ from the constraint system
(:mod:`contactdyn.model.constraints`): M Q̈ − Cᵀ λ = f, G Q̈ = −γ. One evaluation, in order:

1. Pinocchio's terms at (q, q̇): H, h, the frames' positions, Jacobians and J̇q̇;
2. per contact: its chains' stage forces and bond rows (:mod:`contactdyn.model.chain_forces`),
   then friction (:mod:`contactdyn.model.friction`): stick rows, or the Coulomb force, or the
   tilt of the normal column; a row per joint pressing on its limit (:mod:`contactdyn.model.limits`);
   a row per stuck joint, the joints' damping and sliding friction (:mod:`contactdyn.model.joint_friction`);
3. the phase's controller reads the state (and, if it asks, the measured forces) and
   commands joint torques [N·m or N] or voltages [V] (:mod:`contactdyn.laws.controllers`);
4. the drives turn the command into generalized forces (:mod:`contactdyn.laws.drives`);
5. one solve gives Q̈ and λ (a force-reading controller folded in);
6. the forces are recorded per contact, the impulse and energy states get their rates.

The one pipeline (:mod:`contactdyn.model.pipeline`) is the same model over packed arrays, compiled for the
integrator: the laws by address, the chains' and the dynamic laws' compiled functions shared with this module.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..laws.controllers import ControlInput
from ..laws.sensors import quantise
from .chain_forces import chain_axis, chain_forces
from .constraints import Rows, kkt_condition, kkt_solve, record_row_forces, solve_folded
from .contact import Contact, ContactMode, Kinematics
from .friction import friction_terms, launch_directions_at, launching
from .phases import Phase, reference_at

__all__ = ["Evaluation", "evaluate", "contact_condition", "carried_command", "command_of", "drive_command",
           "set_force_inputs", "surface_keys", "surface_points", "carried_terms", "sample_input",
           "Measurement", "SampleTerms", "measures", "measurement"]


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


def evaluate(system, t: float, x: np.ndarray, modes: list[ContactMode], phase: Phase,
             full: bool = False) -> Evaluation:
    """The right-hand side and its diagnostics at (t, x) in ``modes`` and ``phase`` (``full``: stage detail)."""
    nQ, nv = system.nQ, system.nv
    modes, f, ydot, rows, ev, kins, pending = _forces_and_rows(system, t, x, modes, phase, full)
    jf = system.joint_friction
    inp, ft, x_d, force_d = _control_input(system, t, x, modes, phase, f, kins, ev)
    if jf.any:  # damping and sliding friction: after the controller read the contacts' torque f + h
        joint_tau = jf.torques(phase.joint_modes, x, nQ, nv)
        f[:nv] += joint_tau
    out, qdd, lam, regular, cmd, zdot = _command_and_solve(system, inp, phase, x, x_d, f, rows)
    if zdot is not None:
        ydot[phase.z_slice] = zdot
    if system.energy_slot >= 0:
        ydot[system.energy_slot] = out.power
        ydot[system.energy_slot + 1] += out.dissipation
        if jf.any:
            ydot[system.energy_slot + 1] += jf.dissipation(phase.joint_modes, x, nQ, nv)
    xdot = np.concatenate([x[nQ:2 * nQ], qdd, ydot])
    ev.xdot, ev.lam, ev.tau, ev.body_force, ev.p_tip, ev.x_d = xdot, lam, out.applied[:nv], out.applied[nv:], \
        ft.position, x_d
    ev.tau_cmd, ev.u = cmd[:nv], out.u
    ev.force_d = {k: val[0] for k, val in force_d.items()}
    ev.regular = regular
    record_row_forces(system, ev, rows, lam)
    if jf.any:
        ev.joint_friction = joint_tau
        for i, value in ev.joint_hold.items():
            joint_tau[i] += value
    _finish_friction(system, ev, pending, xdot, ydot)
    return ev


def _forces_and_rows(system, t: float, x: np.ndarray, modes: list[ContactMode], phase: Phase, full: bool):
    """The robot's terms at x, then every contact's forces and rows, the limits' and the stuck joints' rows:
    (modes (a launch's directions found), f, ydot, rows, the Evaluation begun, the kinematics, pending friction)."""
    nQ, nv = system.nQ, system.nv
    if any(launching(m) for m in modes):
        modes = launch_directions_at(system, t, x, modes, phase, evaluate)
    system.robot.update(x[:nv], x[nQ:nQ + nv])
    f = np.zeros(nQ)
    f[:nv] = -system.robot.h
    f[nv:] = system.weights  # the bodies' weights m g·axis [N]
    system.body_forces(x, f)  # an articulated body's −h_b
    ydot = np.zeros(system.ny)
    rows = Rows()
    ev = Evaluation(np.empty(0), np.empty(0), rows.meta, {}, {}, {}, {}, {}, {}, np.empty(0), np.empty(0),
                    np.empty(0), None, {})
    kins, pending = _contact_terms(system, x, modes, f, ydot, rows, ev, full)
    system.limits.add_rows(phase.limits, x, nQ, rows, system.stabilization)  # joints pressing on a limit
    if system.joint_friction.any:  # stuck joints' rows (contactdyn.model.joint_friction)
        system.joint_friction.add_rows(phase.joint_modes, phase.limits, x, nQ, rows, system.stabilization)
    return modes, f, ydot, rows, ev, kins, pending


def contact_condition(system, t: float, x: np.ndarray, modes: list[ContactMode], phase: Phase) -> float:
    """2-norm condition number of the contact system at (t [s], x) (:func:`~.constraints.kkt_condition`)."""
    rows = _forces_and_rows(system, t, x, modes, phase, False)[3]
    return kkt_condition(system, rows)


def _contact_terms(system, x: np.ndarray, modes: list[ContactMode], f: np.ndarray, ydot: np.ndarray, rows: Rows,
                   ev: Evaluation, full: bool) -> tuple[list[Kinematics], list]:
    """Every contact's chain forces, rows and friction into f, ydot, rows and ev; (kinematics, pending friction)."""
    nv = system.nv
    kins: list[Kinematics] = []
    pending: list[tuple[Contact, np.ndarray, float, np.ndarray]] = []
    for c, mode in zip(system.contacts, modes, strict=True):
        kin = system.kinematics(c, x)
        kins.append(kin)
        tip_force = np.zeros(3)
        # normal
        tip_F, row, gamma, F_n, gap = chain_forces(system, c, c.normal, mode.touching, 0.0, kin, x, f, ydot, ev,
                                                   full, mode.relaxing)
        tip_force += tip_F * kin.normal
        ev.gap[c.name] = gap
        # tangential chains (bonded while the normal touches)
        for i, dc in enumerate(c.tangent_chains):
            tF, trow, tgamma, tint, _ = chain_forces(system, c, dc, mode.touching, mode.offsets[i], kin, x, f, ydot,
                                                     ev, full, mode.relaxing)
            tip_force += tF * chain_axis(c, dc, kin)
            ev.interface[f"{c.name}.{dc.label}"] = tint
            if trow is not None:
                rows.add(trow, tgamma, (c.name, dc.label, i))
        # friction
        col = row
        if c.friction is not None and len(c.tangents):
            col = friction_terms(system, c, mode, kin, row, F_n, f, ydot, ev, rows, pending)
        if row is not None:
            rows.add(row, gamma, (c.name, "n", 0), col)
        ev.normal_force[c.name] = F_n
        if np.any(tip_force):
            f[:nv] += kin.J.T @ tip_force
            for i, col in kin.columns:  # an articulated side's coordinates (the relative motion's columns)
                f[i] += col @ tip_force
    return kins, pending


def _control_input(system, t: float, x: np.ndarray, modes: list[ContactMode], phase: Phase, f: np.ndarray,
                   kins: list, ev: Evaluation, ctl=None, z: np.ndarray | None = None, set_forces: bool = True):
    """What the phase's controller (or ``ctl``, with states ``z``) reads: (ControlInput, tip frame terms, x_d,
    force set-points)."""
    nQ, nv = system.nQ, system.nv
    q, v = x[:nv], x[nQ:nQ + nv]
    robot = system.robot
    tip = system.tip_fid
    ft = next((k.frame for c, k in zip(system.contacts, kins, strict=True) if k is not None and c.fid == tip), None)
    if ft is None:
        ft = robot.frame_terms(system.tip_fid)
    p_tip, v_tip, J, drift = ft.position, ft.velocity, ft.jacobian, ft.drift
    x_d, v_d, a_d = reference_at(system, phase, t, x)
    force_d = {name: ramp.at(t) for name, ramp in phase.forces.items()}
    if ctl is None:
        ctl = phase.controller
        z = x[2 * nQ + phase.z_slice.start: 2 * nQ + phase.z_slice.stop]
    inp = ControlInput(t, q, v, system.controller_inertia(robot.H), robot.h,
                       robot.gravity_torque(q) if ctl.needs_gravity else None,
                       p_tip, v_tip, J, drift, x_d, v_d, a_d, {**ev.normal_force, **ev.interface}, force_d,
                       system.force_directions, z, R_tip=ft.rotation, J_ang=ft.angular_jacobian,
                       drift_ang=ft.angular_drift)
    if ctl.uses_forces and set_forces:
        set_force_inputs(system, inp, x, modes, f[:nv] + robot.h)
    return inp, ft, x_d, force_d


@dataclass
class Measurement:
    """What a sampled law measures of a solved right-hand side at one (t, x), beyond the kinematics: from the readable
    model (:func:`measurement`) or from the compiled call
    (:meth:`~contactdyn.hybrid.pipeline_mode.PipelineMode.measurement`)."""

    normal_force: dict[str, float]  #: per contact [N], > 0 pressing
    interface: dict[str, float]  #: per "contact.t1": a tangential chain's interface force [N]
    tau_contact: np.ndarray | None  #: the contacts' generalized force on the joints [N·m or N] (None: not read)
    carrier_acc: float = 0.0  #: the acceleration of the body carrying the reference [m/s² or rad/s²]


@dataclass
class SampleTerms:
    """What a sampled law reads of the robot and its phase at (t, x), besides the measured forces: from the readable
    model (Pinocchio, the phase's reference) or from the compiled call
    (:meth:`~contactdyn.hybrid.pipeline_mode.PipelineMode.sample_terms`)."""

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


def measurement(system, t: float, x: np.ndarray, modes: list[ContactMode], phase: Phase) -> Measurement:
    """The readable model's :class:`Measurement` at (t [s], x) of a sampled phase (:func:`measures`)."""
    ev = evaluate(system, t, x, modes, phase)
    tau_c = _contact_torque(system, t, x, modes, phase, ev) if phase.controller.inner.uses_forces else None
    carrier_acc = float(ev.xdot[system.nQ + phase.carrier[0]]) if phase.carrier is not None else 0.0
    return Measurement(ev.normal_force, ev.interface, tau_c, carrier_acc)


def sample_input(system, t: float, x: np.ndarray, modes: list[ContactMode], phase: Phase,
                 resolution: float = 0.0, measured: Measurement | None = None, terms_at=None) -> ControlInput:
    """What a sampled phase's law (``phase.controller.inner``) measures at a sample instant (t [s], x).

    A law that reads forces gets them from the right-hand side solved there under the command held so far
    (a rigid contact's and a stick's too), and the contacts' generalized force on the joints as the continuous
    model gives it (deformable and friction forces, plus the rows that reach beyond the robot); a reference
    carried by a body gets the body's acceleration. No fold: the command is held, not a function of the forces.
    ``measured``: those (:class:`Measurement`) from the compiled call; None: from the readable model.
    ``terms_at(t, x)``: the robot's and the phase's terms there (:class:`SampleTerms`) from the compiled call;
    None: Pinocchio's and the phase's own.
    The kinematics are computed at the joint positions quantised to the encoders' ``resolution`` [rad or m]
    (0: exact). A law that reads no force sees none (as on the compiled path)."""
    nQ, nv = system.nQ, system.nv
    ctl = phase.controller
    law = ctl.inner
    if measured is None and measures(phase):
        measured = measurement(system, t, x, modes, phase)
    xq = x
    if resolution > 0.0:
        xq = x.copy()
        xq[:nv] = quantise(x[:nv], resolution)
    z_law = x[2 * nQ + phase.z_slice.start + ctl.inner_states.start: 2 * nQ + phase.z_slice.stop].copy()
    forces = measured if law.uses_forces else _NO_FORCES
    if terms_at is None:
        system.robot.update(xq[:nv], xq[nQ:nQ + nv])
        inp, _, _, _ = _control_input(system, t, xq, modes, phase, np.zeros(nQ), [None] * len(system.contacts),
                                      forces, law, z_law, set_forces=False)
        inp.H, inp.h = np.array(inp.H), np.array(inp.h)  # (Pinocchio's buffers: a delayed sample keeps its own)
    else:
        T = terms_at(t, xq)
        inp = ControlInput(t, xq[:nv], xq[nQ:nQ + nv], T.H, T.h, T.gravity, T.p_tip, T.v_tip, T.J, T.drift, T.x_d,
                           T.v_d, T.a_d, {**forces.normal_force, **forces.interface}, T.force_d,
                           system.force_directions, z_law, R_tip=T.R_tip, J_ang=T.J_ang, drift_ang=T.drift_ang)
    if inp.a_d is not None and phase.carrier is not None:  # the carrier's acceleration, known after the solve
        inp.a_d = inp.a_d + phase.carrier[1] * measured.carrier_acc
    if law.uses_forces:
        set_force_inputs(system, inp, x, modes, measured.tau_contact)
    return inp


class _NoForces:
    normal_force: dict = {}
    interface: dict = {}


_NO_FORCES = _NoForces()


def _contact_torque(system, t: float, x: np.ndarray, modes: list[ContactMode], phase: Phase,
                    ev: Evaluation) -> np.ndarray:
    """[N·m or N] the contacts' generalized force on the joints at a solved evaluation ``ev``, as the continuous
    model measures it: the deformable and friction forces, plus the rows' forces λ that reach beyond the robot
    (:func:`~contactdyn.model.constraints.force_columns`)."""
    nQ, nv = system.nQ, system.nv
    robot = system.robot
    if any(launching(m) for m in modes):
        modes = launch_directions_at(system, t, x, modes, phase, evaluate)
    robot.update(x[:nv], x[nQ:nQ + nv])
    f = np.zeros(nQ)
    rows = Rows()
    scratch = Evaluation(np.empty(0), np.empty(0), rows.meta, {}, {}, {}, {}, {}, {}, np.empty(0), np.empty(0),
                         np.empty(0), None, {})
    _contact_terms(system, x, modes, f, np.zeros(system.ny), rows, scratch, False)
    tau = f[:nv].copy()
    for col, lam in zip(rows.cols, ev.lam, strict=False):  # the contacts' rows come first in ev.lam
        if np.any(col[nv:]):
            tau += col[:nv] * lam
    return tau


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


def _command_and_solve(system, inp: ControlInput, phase: Phase, x: np.ndarray, x_d, f: np.ndarray, rows: Rows):
    """The controller's command through the drives, then the solve: (drive output, Q̈, λ, regular, cmd, ż)."""
    ctl = phase.controller
    cmd, zdot, carried = command_of(system, inp, phase, x)
    vmask = system._joint_motors if ctl.outputs == "voltage" else None
    # drives, folded measured forces, solve
    if (ctl.uses_forces and rows) or carried is not None:
        return solve_folded(system, inp, ctl, cmd, zdot, f, rows, x, vmask, carried)
    out = system.drives.apply(cmd, x, system.nQ, f, voltage=vmask)
    qdd, lam, regular = kkt_solve(system, f, rows, None)
    return out, qdd, lam, regular, cmd, zdot


def _finish_friction(system, ev: Evaluation, pending: list, xdot: np.ndarray, ydot: np.ndarray) -> None:
    """Sliding friction once the normal forces are known; the energy audit's friction power; impulse rates."""
    nQ = system.nQ
    for c, d, mu, visc in pending:
        if c.name not in ev.friction:
            ev.friction[c.name] = -mu * max(ev.normal_force[c.name], 0.0) * d + visc
    if system.energy_slot >= 0:
        for c, d, mu, _ in pending:
            ydot[system.energy_slot + 1] += float(mu * max(ev.normal_force[c.name], 0.0) * (d @ ev.slip[c.name]))
        xdot[2 * nQ + system.energy_slot + 1] = ydot[system.energy_slot + 1]
    for name, slot in system.impulse_slots.items():
        if name in ev.friction:
            i0 = 2 * nQ + slot
            xdot[i0] = ev.normal_force[name]
            xdot[i0 + 1: i0 + 1 + len(ev.friction[name])] = ev.friction[name]


def command_of(system, inp: ControlInput, phase: Phase, x: np.ndarray) -> tuple:
    """(drive command, ż, carried reference) of the phase's controller at ``inp``: its τ through
    :func:`drive_command`, and :func:`carried_command`."""
    tau, zdot = phase.controller.command(inp)
    return drive_command(system, tau, x), zdot, carried_command(inp, phase, tau, zdot)


def carried_command(inp: ControlInput, phase: Phase, tau: np.ndarray, zdot) -> tuple | None:
    """(i_b, ∂τ/∂Q̈_b, ∂ż/∂Q̈_b) of a reference carried by body coordinate i_b: the command's part
    proportional to the body's acceleration, an unknown of the solve; None if there is none."""
    if phase.carrier is None or inp.x_d is None:
        return None
    i_b, axis = phase.carrier
    return carried_terms(i_b, *phase.controller.a_d_increment(inp, axis, tau, zdot), zdot)


def carried_terms(i_b: int, dtau: np.ndarray, dzdot, zdot) -> tuple | None:
    """(i_b, Δτ, Δż) of :func:`carried_command` from the command's increments per unit body acceleration;
    None where τ does not depend on it."""
    return (i_b, dtau, None if zdot is None else dzdot) if (dtau != 0.0).any() else None


def drive_command(system, tau: np.ndarray, x: np.ndarray) -> np.ndarray:
    """The command per drive (joints, then bodies): the controller's τ [N·m or N; V], the bodies' servo forces [N]."""
    nQ = system.nQ
    cmd = np.zeros(len(system.drives.specs))
    cmd[:system.nv] = tau
    for idx, v_ref, gain in system.servo:
        cmd[idx] = gain * (v_ref - x[nQ + idx])  # body coordinate idx = drive idx
    return cmd
