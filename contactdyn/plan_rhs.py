"""The compiled right-hand side's call: Pinocchio's terms, one product, one small solve.

Per call at (t, x) in the mode a :class:`~contactdyn.rhsplan.ModePlan` was built for:

1. φ = [H, J_f, J̇q̇_f (per frame f), h, (g), e] from Pinocchio (``computeAllTerms``) and
   the time terms of the reference and force ramps;
2. y = P φ = [A, b, o]: the KKT matrix, its right-hand side and the affine outputs o
   (:mod:`contactdyn.plan_kkt`, :mod:`contactdyn.plan_probe`);
3. what is not affine: Coulomb friction −μ max(F, 0) d with 2-D directions d, the column
   tilt of 2-D sliding, a controller without an affine tip-force law, and motors: the
   command τ goes through the drives' law per call (:func:`~contactdyn.plan_drives.drive_forces`:
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
from numba import njit

from .controllers import ControlInput
from .dynamics import set_force_inputs
from .friction import launch_directions, launching, slip_direction
from .linalg import solve_vector
from .phases import reference_at
from .plan_drives import drive_forces
from .plan_fold import contact_torque_of, folded_solve, reaching_rows, row_meta
from .plan_kernel import kernel_of
from .plan_law import compiled_law, operational_command, plan_command
from .plan_operational import operational_kernel_of
from .trajectory import move_rows, move_table, ramp_rows, ramp_table

__all__ = ["make_rhs", "controller_call", "controller_input", "impulse_terms", "LWA"]

LWA = pin.ReferenceFrame.LOCAL_WORLD_ALIGNED

def make_rhs(plan):
    """Build ``plan.time_terms``, ``plan.phi_at`` and return the right-hand side f(t, x) of the plan's mode."""
    s = plan.system
    nQ, m = s.nQ, plan.m
    m2 = m * m
    P = plan.P
    o_y = slice(m2 + m + plan.o_y.start, m2 + m + plan.o_y.stop)
    with_y = s.n > 2 * nQ
    z_slice = plan.z_slice
    cat = np.concatenate
    ring = plan.ring
    time_terms, tv = _time_terms(plan)
    phi_and_jacobians = _phi_function(plan, time_terms, tv)
    impulse_rates = _impulse_rates(plan)
    friction = _friction_terms(plan)
    solve = _command_and_solve(plan)
    launch = _launch(plan, friction, solve) if any(launching(mode) for mode in plan.modes) else None
    plan.launch = launch
    plan.friction_terms = friction
    plan.impulse_rates = impulse_rates
    plan.time_terms = time_terms
    plan.phi_at = lambda t, x, tv=None: phi_and_jacobians(t, x, tv)[0].copy()
    modes = plan.modes  # this call's own, 2-D reference directions included (ModePlan.use)

    terms = impulse_terms(plan)
    kernel = plan.kernel = (kernel_of(plan, row_meta(plan), reaching_rows(plan))  # (no rows: [], [])
                            or operational_kernel_of(plan, terms))
    impulses = bool(terms) and not getattr(kernel, "rates", False)  # a kernel may write them itself

    def rhs(t, x):
        phi, Js = phi_and_jacobians(t, x)
        got = kernel(t, x, phi) if kernel is not None else None
        if got is not None:  # the compiled call (contactdyn.plan_kernel, contactdyn.plan_operational)
            xd, z, o = got
            if impulses:
                impulse_rates(xd, z, o, modes, None)
        else:
            xd, z, o = numpy_call(t, x, phi, Js)
        ring[0] = ring[1]
        ring[1] = ring[2]
        ring[2] = ring[3]
        ring[3] = (t, x, z, o)
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

    return rhs


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

    def terms(y, Js, modes):
        o = y[m2 + m:]
        dirs = {}
        for i_fn, mu, G, g1, ci in coulomb:
            F_n = y[i_fn]
            if F_n > 0.0:
                if g1 is None:
                    dirs[ci] = d = slip_direction(s, o[o_vt[ci]], modes[ci])
                    y -= (mu * F_n) * d.dot(G)
                else:
                    y -= (mu * F_n) * g1
        for robot_rows, body_rows, a0, ci, mu, T, consts, j in dyn_tilt:
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
    if plan.affine_ctl and drives is None:
        return None
    s = plan.system
    nQ, nv = s.nQ, s.nv
    ctl_call = controller_call(plan)
    fast, readable = (drives.fast, drives.readable) if drives is not None else (None, None)
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


def _launch(plan, friction, solve):
    """launch(t, x, φ, Js, y, b_ctl) -> the modes with every 2-D slide from rest given its direction
    (:func:`~contactdyn.friction.launch_directions`, the readable rule), each trial direction solved
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


def _time_terms(plan):
    """(time_terms(t, out), its default buffer): the reference's and ramps' time terms of e, and the trailing 1;
    ``time_terms.at_times(ts)``: the same at many times, as rows."""
    tv = np.zeros(plan.ne - plan.e_frame[-1] - 6)  # time terms and the trailing 1
    tv[-1] = 1.0
    base = plan.e_frame[-1] + 6
    moves = move_table([m_ for _, m_ in plan.time_moves])
    ramps = ramp_table([ramp for _, ramp, _ in plan.time_ramps])
    move_slots = np.array([slot - base for slot, _ in plan.time_moves], dtype=np.intp)
    ramp_slots = np.array([slot - base for slot, _, _ in plan.time_ramps], dtype=np.intp)
    w = np.zeros(3 * len(moves) + 2 * len(ramps))
    timed = bool(w.size)

    def time_terms(t, out=tv):
        """The time terms of e at t (and the trailing 1), written into ``out``."""
        if timed:
            _write_time_terms(t, moves, move_slots, ramps, ramp_slots, w, out)
        return out

    def at_times(ts):
        """The time terms at each time of ``ts`` [s], as rows (len(ts), len(tv))."""
        out = np.tile(tv, (len(ts), 1))
        for k, t in enumerate(ts):
            time_terms(float(t), out[k])
        return out

    time_terms.at_times = at_times
    return time_terms, tv


@njit(cache=True)
def _write_time_terms(t, moves, move_slots, ramps, ramp_slots, w, out):
    """out[slot], out[slot + 1] = σ, σ'/T of each move; out[slot] = F_d [N] of each ramp, at t [s]
    (trajectory.move_rows, ramp_rows into w)."""
    move_rows(t, moves, w)
    for k in range(move_slots.size):
        out[move_slots[k]] = w[3 * k]
        out[move_slots[k] + 1] = w[3 * k + 1]
    j = 3 * move_slots.size
    ramp_rows(t, ramps, w[j:])
    for k in range(ramp_slots.size):
        out[ramp_slots[k]] = w[j + 2 * k]


def _phi_function(plan, time_terms, tv0):
    """phi(t, x, tv=None) -> (φ, per-frame Jacobians (3, nv)); leaves Pinocchio's data at x.

    φ and the Jacobians are views of one buffer the next call overwrites: a call writes Pinocchio's H, h, g
    (read through views of its data, which keeps its arrays for its lifetime), x and the first frame's terms
    into it by one compiled call (:func:`_write_phi`), each further frame's by one more (:func:`_write_frame`).
    ``tv``: the time terms, else computed into the buffer; ``tv0``: their initial values (the trailing 1).
    """
    s = plan.system
    model, data = s.robot.model, s.robot.data
    nQ, nv = s.nQ, s.nv
    fids = plan.fids
    phi = np.empty(plan.P.shape[1])
    Js = tuple(phi[i:i + 3 * nv].reshape(3, nv) for i in plan.i_J)
    tv_part = phi[plan.i_e + plan.e_frame[-1] + 6:]
    tv_part[:] = tv0
    compute, jacobian, accel = pin.computeAllTerms, pin.getFrameJacobian, pin.getFrameClassicalAcceleration
    lwa = LWA
    H, h = data.M, data.nle  # views of Pinocchio's data
    g = data.g if plan.with_g else np.zeros(0)
    one_dof = nv == 1  # (Pinocchio gives a 1-DOF robot's Jacobian as (6,))
    #: per frame: its id, Pinocchio's translation (getFrameJacobian updates the frame's placement, data.oMf), and
    #: where x's v, its J (3 rows), J̇q̇ (3), p and ṗ go in φ; the first frame's also where h (then g) and x go
    frames = [(fids[f], data.oMf[fids[f]].translation,
               np.array([nQ, plan.i_J[f], plan.i_dr[f], plan.i_e + plan.e_frame[f]]
                        + ([plan.i_h, plan.i_e] if f == 0 else []), dtype=np.intp)) for f in range(len(fids))]
    (fid0, p0, at0), more = frames[0], frames[1:]
    #: a law that reads the tip's orientation: the tip's 6-row Jacobian and J̇q̇ (linear, angular) of the last
    #: call, as Pinocchio gave them (its R: data.oMf[tip].rotation, updated by the call)
    tip6 = plan.tip6 = [None, None]
    tip = fids[plan.tip_frame] if plan.phase.controller.reads_orientation else None

    def frame_terms(fid):
        J6, a6 = jacobian(model, data, fid, lwa), accel(model, data, fid, lwa).vector
        if one_dof:
            J6 = J6.reshape(6, 1)
        if fid == tip:
            tip6[0], tip6[1] = J6, a6
        return J6, a6

    def phi_of(t, x, tv=None):
        compute(model, data, x[:nv], x[nQ:nQ + nv])
        _write_phi(phi, H, h, g, x, *frame_terms(fid0), p0, at0)
        for fid, p, at in more:
            _write_frame(phi, *frame_terms(fid), p, x, at)
        if tv is None:
            time_terms(t, tv_part)
        else:
            tv_part[...] = tv
        return phi, Js

    return phi_of


@njit(cache=True)
def _write_phi(phi, H, h, g, x, J6, a6, p, at):
    """φ's robot terms: H [kg·m²] column by column from 0, h [N·m] (then g, if any) from at[4], x from at[5];
    and the first frame's (:func:`_write_frame`)."""
    nv = h.size
    for j in range(nv):
        for i in range(nv):
            phi[j * nv + i] = H[i, j]
    for i in range(nv):
        phi[at[4] + i] = h[i]
    for i in range(g.size):
        phi[at[4] + nv + i] = g[i]
    for i in range(x.size):
        phi[at[5] + i] = x[i]
    _write_frame(phi, J6, a6, p, x, at)


@njit(cache=True)
def _write_frame(phi, J6, a6, p, x, at):
    """φ's terms of one frame: its J's translation rows (3, nv) from at[1], J̇q̇'s linear part [m/s²] from at[2],
    p [m] and ṗ = J v [m/s] from at[3] (J6, a6: Pinocchio's 6-row Jacobian and classical acceleration; v:
    x[at[0]:at[0] + nv])."""
    nv = J6.shape[1]
    for r in range(3):
        phi[at[2] + r] = a6[r]
        phi[at[3] + r] = p[r]
        pd = 0.0
        for c in range(nv):
            phi[at[1] + r * nv + c] = J6[r, c]
            pd += J6[r, c] * x[at[0] + c]
        phi[at[3] + 3 + r] = pd


def _impulse_rates(plan):
    """rates(ẋ, z, o, modes, dirs): write the impulse states' rates (∫F dt, ∫F_f dt per friction contact) into ẋ
    from the solution z and the affine outputs o; ``dirs``: the 2-D sliding directions this call's friction
    terms already computed (by contact index), or None."""
    off = plan.m * plan.m + plan.m  # impulse_terms index y = [A, b, o]: o's start
    impulses = [(i0, from_z, k_n if from_z else k_n - off, sliding, mu, d0, k_visc - off, stick, ci)
                for i0, from_z, k_n, sliding, mu, d0, k_visc, stick, ci in impulse_terms(plan)]
    s = plan.system
    o_vt = [plan.o_vt[c.name] for c in s.contacts]

    def rates(xd, z, o, modes, dirs):
        for i0, from_z, k_n, sliding, mu, d0, k_visc, stick, ci in impulses:
            F_n = z[k_n] if from_z else o[k_n]
            xd[i0] = F_n
            if stick is not None:
                xd[i0 + 1:i0 + 1 + len(stick)] = z[stick]
            elif sliding:
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
        out.append((2 * nQ + slot, from_z, k_n, sliding, c.friction.mu_k, d0, k_visc, stick, ci))
    return out


def controller_call(plan):
    """The command of a controller without an affine tip-force law: call(t, x, q, v, Js, φ, o, τ_c) -> (τ, ż);
    a tip law read off as a matrix, and the operational_space law, at the plan's own slots
    (:func:`~contactdyn.plan_law.plan_command`, :func:`~contactdyn.plan_law.operational_command`)."""
    make = controller_input(plan)
    command = compiled_law(plan).command
    fast = plan_command(plan) or operational_command(plan)
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
