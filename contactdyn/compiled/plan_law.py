"""A force-reading dynamic law on the compiled path: its tip targets as one matrix.

A7 (task space), A10 and the hybrid law compute τ = H q̈*(a*) + h − τ_c (+ Jᵀ f_swap)
around tip targets (a*, f_swap, ż) (:meth:`~contactdyn.laws.controllers.dynamic._ComputedTorque.tip_targets`).
Within one contact mode those targets are affine in

    u = [p_tip, ṗ_tip, (x_d, ẋ_d, ẍ_d), measured forces, (F_d, Ḟ_d) per set-point,
         (p_s, ṗ_s) per surface or anchor, z, 1]

so the plan reads the map [a*; f_swap; ż] = M u off the law itself by unit probes
(:func:`~contactdyn.compiled.plan_probe.affine_map`) at the first call of its mode, checks it at
random u, and from then on a call costs one product and the computed torque; the force
columns of the fold (:func:`~contactdyn.model.constraints.force_columns`) are M's columns of the
measured forces. The plan's call (:func:`plan_command`) writes u from its own slots — φ, o,
x, the reference and the ramps (:func:`plan_inputs`) — and takes τ from the law's own
``torque``, so no ControlInput is built per call. The law stays written once, in
:mod:`contactdyn.laws.controllers.dynamic`.
Joint-space A7, or a law that is not affine in u (a clip, a switch), is declined: the
readable ``command`` runs as before.

The operational_space law (not affine: its Λ depends on q) is called the same way by
:func:`operational_command`: its :meth:`~contactdyn.laws.controllers.operational.OperationalSpace.torque`
at the plan's own slots, with the tip's rotation, angular Jacobian and J̇_ω q̇ read off Pinocchio's
data the plan's φ was computed from.
"""

from __future__ import annotations

import math

import numpy as np
import pinocchio as pin

from ..laws.controllers import ControlInput
from ..laws.controllers.operational import OperationalSpace
from ..laws.trajectory import circle_reference, move_rows, move_table, ramp_rows, ramp_table
from ..model.constraints import force_columns
from ..model.dynamics import surface_keys, surface_points
from ..model.phases import reference_at
from ..numerics.compile_cache import njit
from ..numerics.linalg import mv
from .plan_phi import LWA
from .plan_probe import affine_map

__all__ = ["CompiledLaw", "compiled_law", "plan_inputs", "write_time_part", "reference_of", "reference_tables",
           "NO_REFERENCE", "plan_command", "plan_commands", "operational_command", "reference_rows"]


class CompiledLaw:
    """The plan's controller with ``command`` and ``force_columns`` by the matrix M (see the module)."""

    uses_forces = True

    def __init__(self, ctl):
        self.ctl = ctl
        self.outputs, self.n_states = ctl.outputs, ctl.n_states
        self.M: np.ndarray | None = None
        #: why the law runs readable (None: compiled, or not read yet)
        self.reason = None if ctl.in_task_space else f"{ctl.name}: not a task-space tip law"

    # ---- the layout of u, read off the first input ------------------------------------------
    def _layout(self, inp: ControlInput) -> None:
        self.ref = inp.x_d is not None
        self.force_keys = list(inp.forces)
        self.force_index = {k: j for j, k in enumerate(self.force_keys)}
        self.set_keys = list(inp.force_d)
        self.surface_keys = list(inp.surfaces)
        i = 6 + (9 if self.ref else 0)
        self.i_forces = i
        self.nu = i + len(self.force_keys) + 2 * len(self.set_keys) + 6 * len(self.surface_keys) + len(inp.z) + 1

    def inputs(self, inp: ControlInput) -> np.ndarray:
        """u of the module docstring at ``inp``."""
        parts = [inp.p_tip, inp.v_tip]
        if self.ref:
            parts += [inp.x_d, inp.v_d, inp.a_d]
        forces, force_d = inp.forces, inp.force_d
        parts.append([forces[k] for k in self.force_keys])
        parts.append([v for k in self.set_keys for v in force_d[k]])
        for k in self.surface_keys:
            parts += inp.surfaces[k]
        parts += [inp.z, (1.0,)]
        return np.concatenate(parts)

    def _at(self, template: ControlInput, u: np.ndarray) -> ControlInput:
        """``template`` with the fields of u (the inverse of :meth:`inputs`)."""
        ch = {"p_tip": u[0:3], "v_tip": u[3:6]}
        i = 6
        if self.ref:
            ch.update(x_d=u[6:9], v_d=u[9:12], a_d=u[12:15])
            i = 15
        ch["forces"] = {**template.forces, **{k: float(u[i + j]) for j, k in enumerate(self.force_keys)}}
        i += len(self.force_keys)
        ch["force_d"] = {k: (float(u[i + 2 * j]), float(u[i + 2 * j + 1])) for j, k in enumerate(self.set_keys)}
        i += 2 * len(self.set_keys)
        surfaces = dict(template.surfaces)
        for k in self.surface_keys:
            surfaces[k] = (u[i:i + 3], u[i + 3:i + 6])
            i += 6
        ch["surfaces"] = surfaces
        ch["z"] = u[i:self.nu - 1]
        return template.replaced(**ch)

    def _targets(self, inp: ControlInput) -> np.ndarray:
        a, f_swap, zdot = self.ctl.tip_targets(inp)
        return np.concatenate((a, () if f_swap is None else f_swap, () if zdot is None else zdot))

    # ---- reading M --------------------------------------------------------------------------
    def read(self, inp: ControlInput) -> bool:
        """Read M off the law at ``inp``'s mode; False (and ``reason``) where it is not affine in u."""
        if self.reason is not None:
            return False
        self._layout(inp)
        _, f_swap, zdot = self.ctl.tip_targets(inp)
        self.swap = f_swap is not None
        self.zs = slice(6 if self.swap else 3, None) if zdot is not None else None
        M = affine_map(lambda u: self._targets(self._at(inp, u)), self.nu)
        rng = np.random.default_rng(2)
        for _ in range(2):
            u = np.append(rng.normal(size=self.nu - 1), 1.0)
            y = self._targets(self._at(inp, u))
            if not np.allclose(M @ u, y, rtol=1e-9, atol=1e-9 * (1.0 + np.abs(y).max())):
                self.reason = f"{self.ctl.name}: its tip targets are not affine in this mode"
                return False
        self.M = M
        return True

    def targets(self, inp: ControlInput) -> tuple[np.ndarray, np.ndarray | None, np.ndarray | None]:
        """(a* [m/s²], f_swap [N] or None, ż or None) by the matrix."""
        y = self.M.dot(self.inputs(inp))
        return y[:3], (y[3:6] if self.swap else None), (y[self.zs] if self.zs is not None else None)

    # ---- the controller's interface ---------------------------------------------------------
    def command(self, inp: ControlInput) -> tuple[np.ndarray, np.ndarray | None]:
        """The law's (τ, ż): by M once read, else the readable command."""
        if self.M is None and not self.read(inp):
            return self.ctl.command(inp)
        a, f_swap, zdot = self.targets(inp)
        return self.ctl.computed_torque(inp, a, f_swap), zdot

    def a_d_increment(self, inp: ControlInput, axis: np.ndarray, tau: np.ndarray,
                      zdot: np.ndarray | None) -> tuple[np.ndarray, np.ndarray | None]:
        """:meth:`Controller.a_d_increment <contactdyn.laws.controllers.base.Controller.a_d_increment>` from M's
        ẍ_d columns once M is read (the readable law's difference before)."""
        if self.M is None:
            return self.ctl.a_d_increment(inp, axis, tau, zdot)
        return self.carried_increment(inp.H, inp.J, axis)

    def per_reference_acceleration(self, axis: np.ndarray) -> np.ndarray:
        """[a*, f_swap, ż] per unit [m/s²] more of ẍ_d along ``axis``: M's ẍ_d columns (u[12:15]) times the axis."""
        return self.M[:, 12:15].dot(axis)

    def carried_increment(self, H: np.ndarray, J: np.ndarray, axis: np.ndarray) -> tuple:
        """(Δτ, Δż or None) per unit [m/s²] more of ẍ_d along ``axis``, from M's ẍ_d columns and the model's H, J."""
        d = self.per_reference_acceleration(axis)
        dtau = self.ctl.increments(H, J, d[:3, None], d[3:6, None] if self.swap else None)[:, 0]
        return dtau, (d[self.zs] if self.zs is not None else None)

    def row_columns(self, meta: list) -> tuple[np.ndarray, np.ndarray | None, np.ndarray | None]:
        """(D_a, D_f, D_z): the tip targets a* [m/s²], f_swap [N] (None without a swap) and ż per unit force of
        each row: M's column of a normal row's measured force, else 0 (one column per row of ``meta``)."""
        D = np.zeros((self.M.shape[0], len(meta)))
        for j, (name, kind, _) in enumerate(meta):
            if kind == "n":
                D[:, j] = self.M[:, self.i_forces + self.force_index[name]]
        return D[:3], (D[3:6] if self.swap else None), (D[self.zs] if self.zs is not None else None)

    def force_columns(self, inp: ControlInput, tau: np.ndarray, zdot, meta: list, cols: list, nv: int):
        """(B, D_z) of :func:`~contactdyn.model.constraints.force_columns` from M's columns of the measured forces."""
        if self.M is None and not self.read(inp):
            return force_columns(inp, self.ctl, tau, zdot, meta, cols, nv)
        D_a, D_f, D_z = self.row_columns(meta)
        B = self.ctl.torque_increments(inp, D_a, D_f)
        for j in range(len(meta)):
            if np.any(cols[j][nv:]):  # the row reaches beyond the robot: in the measured joint torque
                B[:, j] -= cols[j][:nv]
        return B, (None if zdot is None else D_z)


def compiled_law(plan):
    """The plan's controller for its calls: a :class:`CompiledLaw` for a force-reading tip law, else itself."""
    law = plan.__dict__.get("_compiled_law")
    if law is None:
        ctl = plan.phase.controller
        law = CompiledLaw(ctl) if ctl.in_task_space else ctl
        plan._compiled_law = law
    return law


def plan_inputs(plan, law: CompiledLaw, modes: list | None = None):
    """inputs(t, x, φ, o) -> u: :meth:`CompiledLaw.inputs` read from the plan's own slots (the tip's p and ṗ
    in φ's e, the forces in o, z in x) and the phase's reference, ramps and surfaces, without a ControlInput
    (the values the plan's ControlInput carries, :func:`~contactdyn.compiled.plan_rhs.controller_input`).

    u = time part + state part + the tip and the forces: ``inputs.time_part(t)`` (the reference's moves and
    the ramps; one buffer, rewritten per call) and ``inputs.state_part(x)`` (affine in x: a carrying body's
    offset of the reference, surfaces on bodies, z), so a compiled call (:mod:`contactdyn.compiled.plan_kernel`) can
    take the state part as a matrix (``inputs.state_map()``: [U_x, u_c], u's state part = U_x x + u_c) and
    the tip (φ[inputs.tip:+6]) and forces (o[inputs.forces]) by index. ``modes``: those the call runs with
    (default the plan's current; a call made before a ModePlan.use keeps its own)."""
    s, phase = plan.system, plan.phase
    nQ, n = s.nQ, s.n
    tip = plan.i_e + plan.e_frame[plan.tip_frame]
    o_index = {c.name: plan.o_Fint.start + i for i, c in enumerate(s.contacts)}
    o_index.update({key: sl.start for key, sl in plan.o_iface.items()})
    i_forces = np.array([o_index[k] for k in law.force_keys], dtype=np.intp)
    ramps = ramp_table([phase.forces[k] for k in law.set_keys])
    if surface_keys(s) != law.surface_keys:
        raise ValueError(f"the law's surfaces {law.surface_keys} are not the system's {surface_keys(s)}")
    modes = plan.modes if modes is None else modes  # (a call keeps the modes it was made for: ModePlan.use)
    i_f = law.i_forces
    i_set = i_f + len(i_forces)
    i_surf = i_set + 2 * len(ramps)  # (F_d, Ḟ_d per ramp)
    i_z = i_surf + 6 * len(law.surface_keys)
    z = slice(2 * nQ + phase.z_slice.start, 2 * nQ + phase.z_slice.stop)
    u = np.zeros(law.nu)
    u[-1] = 1.0
    set_points = u[i_set:i_surf]
    # written once where they cannot change within the mode: a reference without moves, surfaces on the ground
    # (Contact.body_index < 0)
    moves = law.ref and bool(phase.reference.moves)
    if law.ref and not moves:
        u[6:15] = np.concatenate(phase.reference.at(phase.t_start))
    surfaces_move = any(c.body_index >= 0 for c in s.contacts)
    if not surfaces_move:
        _write_surfaces(u, i_surf, surface_points(s, np.zeros(n), modes))
    carrier = phase.carrier if law.ref else None
    tables = reference_tables(phase.reference) if moves else NO_REFERENCE
    reference = (lambda t: np.concatenate(phase.reference.at(t))) if tables is None else None

    def time_part(t):
        """u's time part at t [s]: the reference [m, m/s, m/s²] (a carrying body's offset: the state part), then
        F_d [N], Ḟ_d [N/s] per ramp."""
        if tables is None:  # a circle among other moves
            u[6:15] = reference(t)
            ramp_rows(t, ramps, set_points)
        else:
            write_time_part(t, *tables, ramps, u, i_set)
        return u

    def state_part(x):
        v = np.zeros(law.nu)
        if carrier is not None:  # the reference carried by a body: its origin and velocity along the axis
            i, axis = carrier
            v[6:9] = axis * x[i]
            v[9:12] = axis * x[nQ + i]
        if surfaces_move:
            _write_surfaces(v, i_surf, surface_points(s, x, modes))
        v[i_z:-1] = x[z]
        return v

    def inputs(t, x, phi, o):
        out = time_part(t) + state_part(x)
        out[:6] = phi[tip:tip + 6]  # p_tip [m], ṗ_tip [m/s]
        out[i_f:i_set] = o[i_forces]  # measured forces [N]
        return out

    inputs.time_part, inputs.state_part = time_part, state_part
    inputs.state_map = lambda: affine_map(lambda e: state_part(e[:n]), n + 1)
    inputs.tip, inputs.forces = tip, i_forces
    #: for a compiled caller: u's buffer (the time part writes into it) and the tables of :func:`write_time_part`
    #: (the reference's, ramps, i_set), None for a circle among other moves (then ``time_part`` itself)
    inputs.u = u
    inputs.time_tables = None if tables is None else (*tables, ramps, i_set)
    return inputs


def reference_rows(reference):
    """rows(t) -> [x_d, ẋ_d, ẍ_d] (9,) of a task-space reference [m, m/s, m/s²], bitwise Reference.at's:
    its sum start + Σ_k (σ_k, σ'_k/T_k, σ''_k/T_k²) ⊗ Δ_k as one product R w over the moves' profiles w (the
    same sums in the same order), or one circle's rows plus the start (Reference.at's one-move sum), both by
    one compiled call (:func:`reference_of`); with a circle among other moves, Reference.at itself."""
    tables = reference_tables(reference)
    if tables is None:
        return lambda t: np.concatenate(reference.at(t))
    return lambda t: reference_of(t, *tables)


def reference_tables(reference) -> tuple | None:
    """(kind, moves, R, circle, terms, start) of :func:`reference_of`: REF_PRODUCT with moves, R of
    :func:`reference_product`, or REF_CIRCLE with circle = (start [s], duration [s], accel fraction, angle [rad]),
    the circle's terms (Move._circle_terms) and the reference's start [m]; None for a circle among other moves."""
    if not any(m.kind == "circle" for m in reference.moves):
        return (REF_PRODUCT, *reference_product(reference), *NO_REFERENCE[3:])
    if len(reference.moves) > 1:
        return None
    m = reference.moves[0]
    circle = np.array([m.start, m.duration, m.accel_fraction, 2.0 * math.pi * m.turns])
    return REF_CIRCLE, *NO_REFERENCE[1:3], circle, m._circle_terms, np.asarray(reference.start, float)


REF_PRODUCT, REF_CIRCLE = 0, 1  #: :func:`reference_of`'s kinds
#: :func:`reference_tables`' shapes for a reference fixed in the mode or none (kind −1: nothing to write)
NO_REFERENCE = (-1, np.zeros((0, 4)), np.zeros((9, 1)), np.zeros(4), np.zeros((3, 4)), np.zeros(3))


@njit(cache=True)
def reference_of(t, kind, moves, R, circle, terms, start):
    """[x_d, ẋ_d, ẍ_d] (9,) at t [s] of a reference by its tables (:func:`reference_tables`)."""
    if kind == REF_CIRCLE:
        return circle_reference(t, circle[0], circle[1], circle[2], circle[3], terms, start)
    w = np.empty(R.shape[1])  # [1, (σ, σ'/T, σ''/T²) per move]
    w[0] = 1.0
    move_rows(t, moves, w[1:])
    return mv(R, w)


def reference_product(reference) -> tuple[np.ndarray, np.ndarray]:
    """(moves, R) of the product R w of a reference without circles, w = [1, (σ, σ'/T, σ''/T²) per move]
    (moves: trajectory.move_table; R's rows 0:3 [m], 3:6 [m/s] and 6:9 [m/s²] per unit of w)."""
    K = len(reference.moves)
    R = np.zeros((9, 1 + 3 * K))
    R[0:3, 0] = reference.start
    for k, m in enumerate(reference.moves):
        R[0:3, 1 + 3 * k], R[3:6, 2 + 3 * k], R[6:9, 3 + 3 * k] = m.delta, m.delta, m.delta
    return move_table(reference.moves), R


@njit(cache=True)
def write_time_part(t, kind, moves, R, circle, terms, start, ramps, u, i_set):
    """:func:`plan_inputs`' time part into u at t [s]: u[6:15] = the reference's rows by its tables
    (:func:`reference_of`; kind −1: fixed, not written), then F_d [N], Ḟ_d [N/s] per ramp from u[i_set]."""
    if kind >= 0:
        u[6:15] = reference_of(t, kind, moves, R, circle, terms, start)
    ramp_rows(t, ramps, u[i_set:i_set + 2 * ramps.shape[0]])


def _write_surfaces(u: np.ndarray, j: int, points: list) -> None:
    """u[j:] = p₁, v₁, p₂, v₂, …: the surfaces' points [m] and velocities [m/s] of :func:`surface_points`."""
    for p, v in points:
        u[j:j + 3] = p
        u[j + 3:j + 6] = v
        j += 6


def plan_command(plan):
    """command(t, x, Js, φ, o, τ_c) -> (τ [N·m or N], ż, H, J) of the plan's force-reading tip law by its
    matrix M at the plan's own slots (:func:`plan_inputs`; H, J: the model's terms it used), or None while M
    is not read; None for a controller without one (:func:`compiled_law`)."""
    law = compiled_law(plan)
    if not isinstance(law, CompiledLaw) or law.reason is not None:
        return None
    s = plan.system
    nQ, nv = s.nQ, s.nv
    robot, ctl = s.robot, law.ctl
    tf = plan.tip_frame
    i_dr = plan.i_dr[tf]
    inputs, modes = None, plan.modes  # (the modes of the call this command is made for)

    def command(t, x, Js, phi, o, tau_c):
        nonlocal inputs
        if law.M is None:
            return None
        if inputs is None:
            inputs = plan_inputs(plan, law, modes)
        y = law.M.dot(inputs(t, x, phi, o))
        H = s.controller_inertia(robot.H)
        J = Js[tf]
        tau = ctl.torque(H, robot.h, tau_c, J, phi[i_dr:i_dr + 3], x[nQ:nQ + nv], y[:3],
                         y[3:6] if law.swap else None)
        return tau, (y[law.zs] if law.zs is not None else None), H, J

    return command


def plan_commands(plan):
    """commands(ts, X, Φ, O, T_c) -> (τ (N, nv), ż (N, ·) or None, H (N, nv, nv), J (N, 3, nv)): :func:`plan_command`
    over N samples at once (Φ: their φ from :meth:`phi_at`, O: their outputs, T_c: their contacts' torque), the
    same arithmetic per sample: u by :func:`plan_inputs` per sample, M u and the law's ``torque`` over the stack;
    None while M is not read; None for a controller without one."""
    law = compiled_law(plan)
    if not isinstance(law, CompiledLaw) or law.reason is not None:
        return None
    s = plan.system
    nQ, nv = s.nQ, s.nv
    ctl = law.ctl
    tf = plan.tip_frame
    i_dr, i_J, i_h = plan.i_dr[tf], plan.i_J[tf], plan.i_h

    def commands(ts, X, Phi, O, T_c):
        if law.M is None:
            return None
        inputs, N = plan_inputs(plan, law), len(ts)
        U = np.empty((N, law.nu))
        for k in range(N):
            U[k] = inputs(ts[k], X[k], Phi[k], O[k])
        Y = np.matmul(law.M, U[:, :, None])[:, :, 0]  # per sample: the same numbers as M.dot(u)
        H = np.ascontiguousarray(Phi[:, :nv * nv].reshape(N, nv, nv).transpose(0, 2, 1))  # φ holds H by columns
        H = s.controller_inertia(H)
        J = np.ascontiguousarray(Phi[:, i_J:i_J + 3 * nv].reshape(N, 3, nv))
        tau = ctl.torque(H, Phi[:, i_h:i_h + nv], T_c, J, Phi[:, i_dr:i_dr + 3], X[:, nQ:nQ + nv], Y[:, :3],
                         Y[:, 3:6] if law.swap else None)
        return tau, (Y[:, law.zs] if law.zs is not None else None), H, J

    return commands


def operational_command(plan):
    """command(t, x, Js, φ, o, τ_c) -> (τ [N·m or N], None, H, J) of the plan's operational_space law at the
    plan's own slots (the values :func:`~contactdyn.compiled.plan_rhs.controller_input` gives it); None for another
    controller. The tip's R, J_ω and J̇_ω q̇ come from Pinocchio's data of this call's φ."""
    ctl = plan.phase.controller
    if not isinstance(ctl, OperationalSpace):
        return None
    s, phase = plan.system, plan.phase
    nQ, nv = s.nQ, s.nv
    robot = s.robot
    model, data = robot.model, robot.data
    tf = plan.tip_frame
    fid, i_dr = plan.fids[tf], plan.i_dr[tf]
    tip = plan.i_e + plan.e_frame[tf]
    ramps = [phase.forces[key] for key in ctl.force_keys]
    referenced, orient = phase.reference is not None, ctl.reads_orientation
    placement, jacobian = pin.updateFramePlacement, pin.getFrameJacobian
    acceleration = pin.getFrameClassicalAcceleration
    H_rigid, h = robot.H, robot.h  # views of Pinocchio's data, as φ's (plan_phi.phi_function)

    def command(t, x, Js, phi, o, tau_c):
        ref = reference_at(s, phase, t, x) if referenced else None
        set_points = [ramp.at(t)[0] for ramp in ramps]  # F_d [N]
        J = Js[tf]
        if orient:  # the 6 rows of the tip's Jacobian and J̇q̇ (φ holds the linear 3, to rounding: plan_phi)
            R_tip = placement(model, data, fid).rotation
            J_tip = jacobian(model, data, fid, LWA).reshape(6, nv)
            drift_tip = acceleration(model, data, fid, LWA).vector
        else:
            R_tip, J_tip, drift_tip = None, J, phi[i_dr:i_dr + 3]
        H = s.controller_inertia(H_rigid)
        tau = ctl.torque(t, x[nQ:nQ + nv], H, h, J_tip, drift_tip, phi[tip:tip + 3], phi[tip + 3:tip + 6], ref,
                         set_points, R_tip)
        return tau, None, H, J

    return command
