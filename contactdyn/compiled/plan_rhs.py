"""The compiled right-hand side's call: the robot's terms, one product, one small solve.

Per call at (t, x) in the mode a :class:`~contactdyn.compiled.rhsplan.ModePlan` was built for:

1. φ = [H, J_f, J̇q̇_f (per frame f), h, (g), e] from the robot's terms (:mod:`contactdyn.compiled.plan_phi`: computed in
   the compiled call, or Pinocchio's ``computeAllTerms``) and the time terms of the reference and force ramps;
2. y = P φ = [A, b, o]: the KKT matrix, its right-hand side and the affine outputs o
   (:mod:`contactdyn.compiled.plan_kkt`, :mod:`contactdyn.compiled.plan_probe`);
3. what is not affine: Coulomb friction −μ max(F, 0) d with 2-D directions d, the column
   tilt of 2-D sliding, a controller without an affine tip-force law, and motors: the
   command τ goes through the drives' law per call (:func:`~contactdyn.compiled.plan_drives.drive_forces`:
   one product while no voltage clips, the readable law where one does). An affine task law
   with motors gives τ = J_tipᵀ g_ctl + feedforward from o and φ, no controller call;
4. z = A⁻¹ b = [Q̈, λ, w]; ẋ = [Q̇, Q̈, ẏ] with the impulse states' rates ∫F, ∫F_f.

The last four calls' (t, x, z, o) stay in ``plan.ring`` so the event functions read them
without a second solve.
"""

from __future__ import annotations

import math

import numpy as np
import pinocchio as pin

from ..laws.controllers import ControlInput
from ..model.dynamics import set_force_inputs
from ..model.friction import kinetic_coefficient, launch_directions, launching, per_call_coefficient, slip_direction
from ..model.phases import reference_at
from ..numerics.linalg import solve_vector
from .plan_drives import drive_forces
from .plan_fold import contact_torque_of, folded_solve, reaching_rows, row_meta
from .plan_kernel import kernel_of
from .plan_law import compiled_law, operational_command, plan_command
from .plan_operational import operational_kernel_of
from .plan_phi import LWA, phi_function
from .plan_steps import derivatives, stepper

__all__ = ["make_rhs", "controller_call", "controller_input", "impulse_terms"]

def make_rhs(plan):
    """Build ``plan.phi_at`` and return the right-hand side f(t, x) of the plan's mode."""
    s = plan.system
    nQ, m = s.nQ, plan.m
    m2 = m * m
    P = plan.P
    o_y = slice(m2 + m + plan.o_y.start, m2 + m + plan.o_y.stop)
    with_y = s.n > 2 * nQ
    z_slice = plan.z_slice
    cat = np.concatenate
    ring = plan.ring
    phi_and_jacobians = phi_function(plan)
    impulse_rates = _impulse_rates(plan)
    friction = _friction_terms(plan)
    solve = _command_and_solve(plan)
    launch = _launch(plan, friction, solve) if any(launching(mode) for mode in plan.modes) else None
    plan.launch = launch
    plan.friction_terms = friction
    plan.impulse_rates = impulse_rates
    plan.phi = phi_and_jacobians
    plan.phi_at = lambda t, x: phi_and_jacobians(t, x)[0].copy()
    modes = plan.modes  # this call's own, 2-D reference directions included (ModePlan.use)

    terms = impulse_terms(plan)
    kernel = plan.kernel = (kernel_of(plan, row_meta(plan), reaching_rows(plan))  # (no rows: [], [])
                            or operational_kernel_of(plan, terms))
    impulses = bool(terms) and not (kernel is not None and kernel.rates)  # a kernel may write them itself
    at = getattr(kernel, "at", None)  # a kernel writing φ in its own compiled call (contactdyn.compiled.plan_kernel)
    written = phi_and_jacobians.buffer, phi_and_jacobians.jacobians  # where it writes φ, declining or not

    def rhs(t, x):
        if at is not None:
            got = at(t, x)
            phi, Js = written
        else:
            phi, Js = phi_and_jacobians(t, x)
            got = kernel(t, x, phi) if kernel is not None else None
        if got is not None:  # the compiled call (contactdyn.compiled.plan_kernel, contactdyn.compiled.plan_operational)
            xd, z, o = got
            if impulses:
                impulse_rates(xd, z, o, modes, None)
        else:
            xd, z, o = numpy_call(t, x, phi, Js)
        ring.append((t, x, z, o))
        return xd

    def numpy_call(t, x, phi, Js):
        y = P.dot(phi)
        o = y[m2 + m:]  # the affine outputs
        b_ctl = None
        now = modes
        if launch is not None:  # 2-D slides from rest: their directions solved on this call's KKT system
            b_ctl = []
            now = launch(t, x, phi, Js, y, b_ctl)
        dirs = friction(y, Js, now) if friction is not None else None
        z, zdot = solve(t, x, phi, Js, y, b_ctl)
        if with_y:
            xd = cat((x[nQ:2 * nQ], z[:nQ], y[o_y]))
            if zdot is not None:
                xd[z_slice] = zdot
            impulse_rates(xd, z, o, now, dirs)
        else:
            xd = cat((x[nQ:2 * nQ], z[:nQ]))
        return xd, z, o

    return _fused(plan, kernel, numpy_call, written, ring) if at is not None and not impulses else rhs


def _fused(plan, kernel, numpy_call, written, ring):
    """make_rhs's right-hand side for a kernel that writes φ in its own compiled call and the impulse rates too:
    the common case, with the fewest Python layers per call; ``fused.step``: its DOP853 step in one compiled call,
    ``fused.derivatives``: its values at many states in one (:mod:`.plan_steps`); None where the kernel
    has none."""
    one_at, (size, n, m, no) = kernel.one_at, kernel.layout

    def fused(t, x):
        out = np.empty(size)
        if one_at(t, x, out):  # declined: the readable way, on the φ the call wrote
            xd, z, o = numpy_call(t, x, *written)
        else:
            xd, z, o = out[:n], out[n:n + m], out[n + m:n + m + no]
        ring.append((t, x, z, o))
        return xd

    compiled = kernel.step_inputs is not None
    fused.step = stepper(plan, kernel.kind, kernel.step_inputs, kernel.layout) if compiled else None
    fused.derivatives = derivatives(kernel.kind, kernel.step_inputs, kernel.layout, fused) if compiled else None
    return fused


def _friction_terms(plan):
    """terms(y, Js, modes) -> {contact index: d}: sliding friction into y = [A, b, o] in place — Coulomb forces
    −μ max(F, 0) d into b where the normal force is known, the column tilt of 2-D sliding into A — with d by
    the modes' rule; returns the 2-D directions it computed, for the impulse rates (None when the mode has
    neither)."""
    s = plan.system
    nQ, nv, nr, m = s.nQ, s.nv, plan.nr, plan.m
    m2 = m * m
    w0 = nQ + nr
    coulomb = []
    for ci, i_fn, mu, T, consts, j in plan.coulomb_terms:
        # G: the Coulomb force's share of y per unit μF along each tangent: its tip force T into b's frame
        # slots, its body columns into the body rows (one product and one subtraction per call)
        G = np.zeros((len(T), plan.P.shape[0]))
        G[:, m2 + w0 + 3 * j:m2 + w0 + 3 * j + 3] = T
        if nQ > nv:
            G[:, m2 + nv:m2 + nQ] = consts
        g1 = np.asarray(plan.modes[ci].slip, float).dot(G) if len(T) == 1 else None  # 1-D: the mode's fixed d
        coulomb.append((m2 + m + i_fn, mu, G, g1, ci))
    # 2-D sliding with the normal force an unknown: the normal row's column nQ + r of A (flat in y, stride m)
    # tilts by μ Jᵀ Tᵀ d on the robot's rows and is μ constsᵀ d over A0 on the bodies' rows
    dyn_tilt = [(slice(nQ + r, nv * m + nQ + r, m), slice(nv * m + nQ + r, nQ * m + nQ + r, m) if nQ > nv else None,
                 plan.A0[nv:nQ, nQ + r].copy(), ci, mu, T, consts, j) for r, ci, mu, T, consts, j in plan.dyn_tilt]
    if not coulomb and not dyn_tilt:
        return None
    o_vt = [plan.o_vt[c.name] for c in s.contacts]

    friction = [c.friction for c in s.contacts]

    def terms(y, Js, modes):
        o = y[m2 + m:]
        dirs = {}
        for i_fn, mu, G, g1, ci in coulomb:
            F_n = y[i_fn]
            if F_n > 0.0:
                if mu is None:  # a speed-dependent law: μ(|v_t|) per call
                    mu = kinetic_coefficient(friction[ci], o[o_vt[ci]])
                if g1 is None:
                    dirs[ci] = d = slip_direction(s, o[o_vt[ci]], modes[ci])
                    y -= (mu * F_n) * d.dot(G)
                else:
                    y -= (mu * F_n) * g1
        for robot_rows, body_rows, a0, ci, mu, T, consts, j in dyn_tilt:
            if mu is None:
                mu = kinetic_coefficient(friction[ci], o[o_vt[ci]])
            dirs[ci] = d = slip_direction(s, o[o_vt[ci]], modes[ci])
            y[robot_rows] += mu * Js[j].T.dot(d.dot(T))
            if body_rows is not None:
                y[body_rows] = a0 + mu * d.dot(consts)
        return dirs

    return terms


def _command_and_solve(plan):
    """solve(t, x, φ, Js, y, b_ctl) -> (z = [Q̈, λ, w], ż): the controller's command through the drives (or
    folded into the solve), then A z = b. ``b_ctl``: a list to keep the command's share of b in, so the
    trial solves of a launch (:func:`_launch`) call a controller that reads no force once per call."""
    m = plan.m
    m2 = m * m
    drives = plan.compiled_drives = drive_forces(plan)  # (the output's batched drive channels read it too)
    reads_forces = plan.phase.controller.uses_forces
    folded = folded_solve(plan, controller_input(plan), drives) if (reads_forces and plan.nr) or plan.phase.carrier \
        else None
    command = _command_function(plan, drives)
    isfinite = math.isfinite

    def solve(t, x, phi, Js, y, b_ctl):
        A = y[:m2].reshape(m, m)
        b = y[m2:m2 + m]
        o = y[m2 + m:]
        zdot = None
        if folded is not None:  # a force-reading controller with rows: its forces folded into the solve
            return folded(t, x, Js, phi, o, A, b)
        if command is not None:
            if b_ctl and not reads_forces:
                f_ctl, zdot = b_ctl
            else:
                f_ctl, zdot = command(t, x, Js, phi, o, b)
                if b_ctl is not None:
                    b_ctl[:] = (f_ctl, zdot)
            b[:len(f_ctl)] += f_ctl
        z = solve_vector(A, b)
        if not isfinite(z.dot(z)):
            z = plan._singular(A, b)
        return z, zdot

    return solve


def _command_function(plan, drives):
    """command(t, x, Js, φ, o, b) -> (f_ctl, ż): the controller's command as generalized forces, through
    the drives if any ([N·m or N] on the first len(f_ctl) coordinates); None when the task law is all in
    the map P (no motors)."""
    if (plan.affine_ctl or plan.held is not None) and drives is None:
        return None
    s = plan.system
    nQ, nv = s.nQ, s.nv
    fast, readable = (drives.fast, drives.readable) if drives is not None else (None, None)
    if plan.held is not None:  # a sampled law's held command (x's held slots) through the drives
        return _held_command(plan, fast, readable)
    ctl_call = controller_call(plan)
    if plan.affine_ctl:  # the affine task law through the motors
        tf, o_gctl, i_e, feedforward = plan.tip_frame, plan.o_gctl, plan.i_e, plan._feedforward_torque
        joint_terms = plan.feedforward != "none" or plan.kd_joint != 0.0  # else the feedforward is 0

        def task_law(t, x, Js, phi, o, b):
            tau = Js[tf].T.dot(o[o_gctl])
            f = fast(x, tau + feedforward(phi, phi[i_e:]) if joint_terms else tau)
            if f is None:  # a voltage clips: the controller and the drives' law as they are
                f = readable(x, ctl_call(t, x, x[:nv], x[nQ:nQ + nv], Js, phi, o)[0])
            return f, None

        return task_law
    contact_torque = contact_torque_of(plan) if plan.phase.controller.uses_forces else None

    def generic(t, x, Js, phi, o, b):
        tau_c = contact_torque(b, Js) if contact_torque is not None else None
        tau, zdot = ctl_call(t, x, None, None, Js, phi, o, tau_c)
        if fast is None:
            return tau, zdot
        f = fast(x, tau)
        return (readable(x, tau) if f is None else f), zdot

    return generic


def _held_command(plan, fast, readable):
    """command(t, x, Js, φ, o, b) -> (f_ctl, None) of a sampled law (contactdyn.laws.controllers.sampled): the held
    command [N·m or N; V], the state's held slots, through the drives."""
    slots = plan.held

    def held(t, x, Js, phi, o, b):
        tau = x[slots]
        f = fast(x, tau)
        return (readable(x, tau) if f is None else f), None

    return held


def _launch(plan, friction, solve):
    """launch(t, x, φ, Js, y, b_ctl) -> the modes with every 2-D slide from rest given its direction
    (:func:`~contactdyn.model.friction.launch_directions`, the readable rule), each trial direction solved
    on a copy of this call's KKT system: a_t = T (J_f Q̈ + J̇q̇_f) + (body columns) Q̈."""
    s = plan.system
    nv, m = s.nv, plan.m
    m2 = m * m
    o_vt = [plan.o_vt[c.name] for c in s.contacts]
    modes = plan.modes  # this call's own: a later ModePlan.use binds a new list
    tangent = []
    for c in s.contacts:
        T, consts = plan._tangent_terms(c)
        j = plan.frame_of[c.fid]
        tangent.append((T, consts, j, plan.i_dr[j]))

    def launch(t, x, phi, Js, y, b_ctl):
        o = y[m2 + m:]

        def slip_of(i):
            return o[o_vt[i]]

        def acceleration_of(trial, i):
            if any(launching(mode) for mode in trial):  # another slide from rest: resolved inside, as readable
                trial = launch_directions(s, trial, slip_of, acceleration_of)
            yt = y.copy()
            if friction is not None:
                friction(yt, Js, trial)
            z, _ = solve(t, x, phi, Js, yt, b_ctl)
            T, consts, j, i_dr = tangent[i]
            return T.dot(Js[j].dot(z[:nv]) + phi[i_dr:i_dr + 3]) + consts.dot(z[:s.nQ])

        return launch_directions(s, modes, slip_of, acceleration_of)

    return launch


def _impulse_rates(plan):
    """rates(ẋ, z, o, modes, dirs): write the impulse states' rates (∫F dt, ∫F_f dt per friction contact) into ẋ
    from the solution z and the affine outputs o; ``dirs``: the 2-D sliding directions this call's friction
    terms already computed (by contact index), or None."""
    off = plan.m * plan.m + plan.m  # impulse_terms index y = [A, b, o]: o's start
    impulses = [(i0, from_z, k_n if from_z else k_n - off, sliding, mu, d0, k_visc - off, stick, ci)
                for i0, from_z, k_n, sliding, mu, d0, k_visc, stick, ci in impulse_terms(plan)]
    s = plan.system
    o_vt = [plan.o_vt[c.name] for c in s.contacts]

    friction = [c.friction for c in s.contacts]

    def rates(xd, z, o, modes, dirs):
        for i0, from_z, k_n, sliding, mu, d0, k_visc, stick, ci in impulses:
            F_n = z[k_n] if from_z else o[k_n]
            xd[i0] = F_n
            if stick is not None:
                xd[i0 + 1:i0 + 1 + len(stick)] = z[stick]
            elif sliding:
                if mu is None:  # a speed-dependent law: μ(|v_t|) per call
                    mu = kinetic_coefficient(friction[ci], o[o_vt[ci]])
                Fp = F_n if F_n > 0.0 else 0.0
                if d0 is not None:  # 1-D
                    xd[i0 + 1] = -mu * Fp * d0 + o[k_visc]
                else:
                    d = dirs.get(ci) if dirs else None
                    if d is None:
                        d = slip_direction(s, o[o_vt[ci]], modes[ci])
                    xd[i0 + 1:i0 + 1 + len(d)] = -mu * Fp * d + o[k_visc:k_visc + len(d)]

    return rates


def impulse_terms(plan) -> list[tuple]:
    """Where the impulse states' rates (∫F dt, ∫F_f dt per friction contact) come from, per contact."""
    s = plan.system
    nQ, m = s.nQ, plan.m
    off = m * m + m  # o's start in y
    out = []
    for name, slot in getattr(s, "impulse_slots", {}).items():
        ci = next(i for i, c in enumerate(s.contacts) if c.name == name)
        c, mode = s.contacts[ci], plan.modes[ci]
        r = plan.normal_row.get(ci)
        from_z, k_n = (True, nQ + r) if r is not None else (False, off + plan.o_Fint.start + ci)
        stick = np.array(plan.stick_rows[ci]) if mode.touching and mode.stuck else None
        sliding = mode.touching and not mode.stuck
        one_d = len(c.tangents) == 1
        d0 = float(mode.slip[0]) if one_d and sliding else None
        k_visc = off + plan.o_visc[name].start
        mu = per_call_coefficient(c.friction) if sliding else 0.0  # None: μ(|v_t|) per call
        out.append((2 * nQ + slot, from_z, k_n, sliding, mu, d0, k_visc, stick, ci))
    return out


def controller_call(plan):
    """The command of a controller without an affine tip-force law: call(t, x, q, v, Js, φ, o, τ_c) -> (τ, ż);
    a tip law read off as a matrix, and the operational_space law, at the plan's own slots
    (:func:`~contactdyn.compiled.plan_law.plan_command`, :func:`~contactdyn.compiled.plan_law.operational_command`)."""
    make = controller_input(plan)
    command = compiled_law(plan).command
    fast = plan_command(plan) or operational_command(plan)
    plan.python_command = fast is None  # the path the run reports (contactdyn.model.paths.path_of)
    nQ, nv = plan.system.nQ, plan.system.nv

    def call(t, x, q, v, Js, phi, o, tau_contact=None):
        """(τ, ż) at (t, x); q, v: x's joint slots (None: sliced here, where the ControlInput needs them)."""
        got = fast(t, x, Js, phi, o, tau_contact) if fast is not None else None
        if got is not None:
            return got[0], got[1]
        if q is None:
            q, v = x[:nv], x[nQ:nQ + nv]
        return command(make(t, x, q, v, Js, phi, o, tau_contact))

    return call


def controller_input(plan):
    """Per-call ControlInput of the plan's controller: make(t, x, q, v, Js, φ, o, τ_c) (τ_c: the contacts'
    generalized force on the joints [N·m or N], for a force-reading controller; see dynamics.set_force_inputs)."""
    s, phase = plan.system, plan.phase
    robot = s.robot
    ctl = phase.controller
    normals = s.force_directions
    names = [c.name for c in s.contacts]
    i_fint = plan.o_Fint.start
    ifaces = [(key, sl.start) for key, sl in plan.o_iface.items()]
    tf = plan.tip_frame
    kt = plan.e_frame[tf]
    nQ = s.nQ
    zs = phase.z_slice
    modes = plan.modes
    i_e, i_dr = plan.i_e, plan.i_dr[tf]
    model, data, fid, nv = robot.model, robot.data, plan.fids[tf], s.nv
    orient, reads_forces = ctl.reads_orientation, ctl.uses_forces

    def make(t, x, q, v, Js, phi, o, tau_contact=None):
        e = phi[i_e:]
        x_d = v_d = a_d = None
        if phase.reference is not None:
            x_d, v_d, a_d = reference_at(s, phase, t, x)
        force_d = {name: ramp.at(t) for name, ramp in phase.forces.items()}
        forces = {}  # measured forces: only a controller that reads them (uses_forces) sees them
        if reads_forces:
            forces = {name: float(o[i_fint + i]) for i, name in enumerate(names)}
            forces.update({key: float(o[k]) for key, k in ifaces})
        R_tip = J_ang = drift_ang = None
        if orient:
            R_tip = pin.updateFramePlacement(model, data, fid).rotation
            J_ang = pin.getFrameJacobian(model, data, fid, LWA).reshape(6, nv)[3:]
            drift_ang = pin.getFrameAcceleration(model, data, fid, LWA).angular
        H = s.controller_inertia(robot.H)
        inp = ControlInput(t, q, v, H, robot.h, robot.gravity_torque(q) if ctl.needs_gravity else None,
                           e[kt:kt + 3].copy(), e[kt + 3:kt + 6].copy(), Js[tf], phi[i_dr:i_dr + 3], x_d, v_d, a_d,
                           forces,
                           force_d, normals, x[2 * nQ + zs.start: 2 * nQ + zs.stop], R_tip=R_tip, J_ang=J_ang,
                           drift_ang=drift_ang)
        if reads_forces:
            set_force_inputs(s, inp, x, modes, tau_contact)
        return inp

    return make
