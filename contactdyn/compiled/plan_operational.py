"""A plan's call after Pinocchio, compiled: a task-space law that is not affine, sliding in 2-D on a normal row.

For a mode whose controller is the operational_space law (:mod:`contactdyn.laws.controllers.operational`:
Λ depends on q, so it is not a matrix the plan can read off), a task PD law that is not affine (its tool-axis
or full-orientation moment, its normal damping: :mod:`contactdyn.laws.controllers.pd`) or a user's controller
whose ``command`` numba compiles (called by its address, its inputs in one buffer:
:mod:`contactdyn.laws.controllers.abi`; without measured forces or states), and that has no drives,
everything a call does after φ is small dense algebra:

    y = P φ = [A, b, o]                          the KKT system and the affine outputs
    per 2-D slide on a normal row r:  d = v_t/|v_t| while v_t·r_mode > v_ε, else the mode's r
        A[:nv, nQ + r] += μ J_fᵀ Tᵀ d;   A[nv:nQ, nQ + r] = A0 + μ constsᵀ d      (the column tilt)
    τ = operational_law.torque(...), task_pd_law.torque(...) or the controller's;   b[:nv] += τ;   z = A⁻¹ b
    ẋ = [Q̇, Q̈, ẏ]

:func:`call` runs it in one compiled function (numba), the same arithmetic as the readable
path's (:mod:`contactdyn.compiled.plan_rhs`: ``_friction_terms``, ``_command_and_solve``;
:func:`contactdyn.model.friction.slip_direction`'s rule; the laws' own compiled functions). The reference, the force
set-points and the tip's rotation, 6-row Jacobian and J̇q̇ (φ's, plan_phi.frame_motion: the robot's terms of
contactdyn.robot.rigid_body) are computed in :func:`call_at`, or passed in from Python where the tip is not the plan's
first frame. A call goes the plan's readable way (returns status 1) where the operational task is singular (the
law's guard raises there), the solve is singular or not finite, or a 2-D slide from rest is still inside the
stick band (its direction is solved by :func:`contactdyn.model.friction.launch_directions`).
"""

from __future__ import annotations

import numpy as np

from ..laws.controllers import operational_law as law
from ..laws.controllers import task_pd_law
from ..laws.controllers.abi import (
    FIELD,
    LAYOUT_HEAD,
    call_controller,
    controller_address,
    layout_of,
    params_of,
    put_field,
)
from ..laws.controllers.operational import OperationalSpace
from ..laws.controllers.operational_law import SINGULAR
from ..laws.controllers.pd import TaskPD
from ..laws.trajectory import ramp_rows, ramp_table
from ..model.friction import launching
from ..numerics.compile_cache import njit
from ..numerics.linalg import lu_solve, mtv
from .plan_kernel import DECLINED, OK, calls, csr_of, kkt_of, matrix_of, pack_with_phi, vector_of, write_out
from .plan_law import NO_REFERENCE, reference_of, reference_rows, reference_tables
from .plan_phi import work_terms, write_phi

__all__ = ["call", "call_at", "operational_kernel_of", "law_in_call", "OPERATIONAL", "OPERATIONAL_LAW",
           "TASK_PD_LAW", "CONTROLLER_LAW"]

OPERATIONAL = 0  #: this module's call among the compiled calls a step takes (plan_steps)
#: the call's law (INTS' LAW): a user's controller compiled by address (contactdyn.laws.controllers.abi)
OPERATIONAL_LAW, TASK_PD_LAW, CONTROLLER_LAW = 0, 1, 2

#: the constants of a plan's call in :func:`~contactdyn.compiled.plan_kernel.pack`'s two buffers, by these indices
#: (SCALARS: [v_ε, ko, do, k_null (operational_space) or kd_joint (task_pd), kd_normal]; ORIENT: task_pd's R_d)
P_VAL, D_CTL, TILT_F, TILT_T, TILT_BODY, RATES_F, AXES, FORCED, KP, KD, TOOL_AXIS, TARGET, SCALARS, ORIENT = range(14)
#: floats of :func:`call_at`: the reference's tables (plan_law.reference_tables), the force ramps, φ's time tables,
#: its first frame in its joint's and the robot's table (plan_phi.write_phi)
REF_MOVES, REF_R, REF_CIRCLE, REF_TERMS, REF_START, RAMPS, PHI_MOVES, PHI_RAMPS, PHI_FRAME, PHI_RIGID = range(14, 24)
P_COL, P_ROW, INTS, TILT_I, RATES_I = range(24, 29)  # ints (P: CSR columns, row starts)
#: ints: [the reference's kind, −1 none] (:func:`call_at`); [the user controller's address, its layout table]
#: (controllers/abi.layout_of; [0] for the other laws); φ's layout, time slots and the first frame's support
REF_KIND, CTL_AT, PHI_AT, PHI_MSLOTS, PHI_RSLOTS, PHI_SUPPORT = range(29, 35)
#: the controller's input fields in its buffer (contactdyn.laws.controllers.abi.LAYOUT)
F_T, F_Q, F_V, F_H, F_h, F_G, F_P, F_PD, F_J, F_DR, F_XD, F_VD, F_AD, F_Z, F_R, F_JW, F_DW = (
    FIELD[name] for name in ("t", "q", "v", "H", "h", "gravity", "p_tip", "v_tip", "J", "drift", "x_d", "v_d", "a_d",
                             "z", "R_tip", "J_ang", "drift_ang"))


def law_in_call(ctl) -> int:
    """The law :func:`call` computes for a phase's controller: OPERATIONAL_LAW, TASK_PD_LAW (a task PD law that is
    not affine: :meth:`~contactdyn.laws.controllers.pd.TaskPD.tip_force_law` None), CONTROLLER_LAW (a controller
    whose command numba compiles, without measured forces or states, not affine either), or −1 (none of them)."""
    if isinstance(ctl, OperationalSpace):
        return OPERATIONAL_LAW
    if isinstance(ctl, TaskPD) and ctl.tip_force_law() is None:
        return TASK_PD_LAW
    if (ctl is not None and not ctl.uses_forces and not ctl.n_states and ctl.outputs == "torque"
            and not ctl.in_task_space and ctl.tip_force_law() is None and controller_address(type(ctl))):
        return CONTROLLER_LAW
    return -1


#: inline="always" (here and below): a helper compiled into its compiled callers, not as a level of its own
#: (numba compiles each function with all it calls: ~10 s of case1_cart's first run over these helpers)
@njit(cache=True, inline="always")
def _slip_direction(vt, r, band):
    """d of :func:`contactdyn.model.friction.slip_direction` for a 2-D slide: v_t/|v_t| while v_t·r > v_ε (``band``),
    else the mode's r."""
    if vt[0] * r[0] + vt[1] * r[1] > band:  # v_t·r [m/s]
        return vt / np.sqrt(vt[0] * vt[0] + vt[1] * vt[1])
    return r.copy()


@njit(cache=True, inline="always")
def _tilt(A, o, phi, tilt_i, tilt_f, tilt_T, tilt_body, nQ, nv, band):
    """The column tilt of each 2-D slide into A (in place); False where a slide from rest is inside the band.
    tilt_i: [row r, φ's J_f offset, v_t's offset in o, launching]; tilt_f: [μ, r_mode (2)]; tilt_T: T (2, 3) flat;
    tilt_body: [A0's body rows, consts (2, nQ − nv)] flat."""
    for k in range(tilt_i.shape[0]):
        col, i_J, i_vt = nQ + tilt_i[k, 0], tilt_i[k, 1], tilt_i[k, 2]
        mu = tilt_f[k, 0]
        vt, r = o[i_vt:i_vt + 2], tilt_f[k, 1:3]
        if tilt_i[k, 3] and not vt[0] * r[0] + vt[1] * r[1] > band:
            return False
        d = _slip_direction(vt, r, band)
        g = mu * mtv(phi[i_J:i_J + 3 * nv].reshape((3, nv)), mtv(tilt_T[k].reshape((2, 3)), d))  # μ J_fᵀ Tᵀ d
        for i in range(nv):
            A[i, col] += g[i]
        body = tilt_body[k].reshape((3, nQ - nv))
        for i in range(nQ - nv):
            A[nv + i, col] = body[0, i] + mu * (d[0] * body[1, i] + d[1] * body[2, i])
    return True


@njit(cache=True, inline="always")
def _impulse_rates(xd, z, o, rates_i, rates_f, band):
    """The impulse states' rates (∫F dt, ∫F_f dt per contact) into ẋ, as :func:`.plan_rhs.impulse_terms`
    gives them: rates_i = [ẋ slot, F from z?, F's index in z or o, kind (0 free, 1 stuck, 2 sliding 1-D,
    3 sliding 2-D), the viscous force's index in o, v_t's index in o, stick rows, their z indices (2)];
    rates_f = [μ_k, the 1-D direction, the 2-D mode's r (2)]."""
    for k in range(rates_i.shape[0]):
        i0, kind = rates_i[k, 0], rates_i[k, 3]
        F_n = z[rates_i[k, 2]] if rates_i[k, 1] else o[rates_i[k, 2]]
        xd[i0] = F_n
        if kind == 1:
            for j in range(rates_i[k, 6]):
                xd[i0 + 1 + j] = z[rates_i[k, 7 + j]]
        elif kind >= 2:
            mu_F = rates_f[k, 0] * (F_n if F_n > 0.0 else 0.0)
            k_visc = rates_i[k, 4]
            if kind == 2:
                xd[i0 + 1] = -mu_F * rates_f[k, 1] + o[k_visc]
            else:
                i_vt = rates_i[k, 5]
                d = _slip_direction(o[i_vt:i_vt + 2], rates_f[k, 2:4], band)
                xd[i0 + 1] = -mu_F * d[0] + o[k_visc]
                xd[i0 + 2] = -mu_F * d[1] + o[k_visc + 1]


@njit(cache=True, inline="always")
def _operational(phi, x, fb, ib, ref, set_points, R_tip, J6, drift6, nQ, nv, i_h, i_J, i_dr, i_p):
    """(τ [N·m or N], the task's Hadamard ratio) of the operational_space law (operational_law.torque)."""
    _, ko, do, k_null, kd_normal = vector_of(fb, ib, SCALARS)
    H = phi[:nv * nv].reshape((nv, nv)).T + matrix_of(fb, ib, D_CTL)  # φ holds H column by column
    tool_axis = vector_of(fb, ib, TOOL_AXIS)
    if tool_axis.size:
        J_tip, drift_tip = np.ascontiguousarray(J6), drift6
    else:
        J_tip, drift_tip = np.ascontiguousarray(phi[i_J:i_J + 3 * nv].reshape((3, nv))), phi[i_dr:i_dr + 3]
    return law.torque(x[nQ:nQ + nv], H, phi[i_h:i_h + nv], J_tip, drift_tip, phi[i_p:i_p + 3],
                      phi[i_p + 3:i_p + 6], ref[0:3], ref[3:6], ref[6:9], set_points, np.ascontiguousarray(R_tip),
                      matrix_of(fb, ib, AXES), matrix_of(fb, ib, FORCED), vector_of(fb, ib, KP),
                      vector_of(fb, ib, KD), tool_axis, vector_of(fb, ib, TARGET), ko, do, k_null, kd_normal)


@njit(cache=True, inline="always")
def _task_pd(phi, x, fb, ib, ref, set_points, R_tip, J6, nQ, nv, i_J, i_p, i_ff):
    """τ [N·m or N] of the task PD law (task_pd_law.torque): the tip's J from φ, J_ω and R from the first frame's
    terms (J6, R_tip) where the law holds an orientation; the feedforward φ[i_ff:i_ff + nv] (h or g; −1: none)."""
    _, ko, do, kd_joint, kd_normal = vector_of(fb, ib, SCALARS)
    tool_axis, R_d = vector_of(fb, ib, TOOL_AXIS), matrix_of(fb, ib, ORIENT)
    orient = tool_axis.size > 0 or R_d.shape[0] > 0
    J_ang = np.ascontiguousarray(J6[3:]) if orient else np.empty((0, nv))
    R = np.ascontiguousarray(R_tip) if orient else np.empty((0, 3))
    tau_ff = phi[i_ff:i_ff + nv] if i_ff >= 0 else phi[0:0]
    return task_pd_law.torque(x[nQ:nQ + nv], np.ascontiguousarray(phi[i_J:i_J + 3 * nv].reshape((3, nv))), J_ang,
                              phi[i_p:i_p + 3], phi[i_p + 3:i_p + 6], ref[0:3], ref[3:6], set_points, R,
                              matrix_of(fb, ib, AXES), matrix_of(fb, ib, FORCED), vector_of(fb, ib, KP),
                              vector_of(fb, ib, KD), tool_axis, vector_of(fb, ib, TARGET), R_d, ko, do, kd_joint,
                              kd_normal, tau_ff)


@njit(cache=True)
def _controller(t, phi, x, fb, ib, ref, R_tip, J6, drift6, nQ, nv, i_h, i_J, i_dr, i_p, i_g):
    """(τ [N·m or N], status: 1 computed) of a user's controller by its address (contactdyn.laws.controllers.abi):
    its buffer filled from φ (H, h, g when the law needs it at φ[i_g:], the tip's p, ṗ, J, J̇q̇), x (q, q̇), the
    reference [x_d, ẋ_d, ẍ_d] and the tip's R, J_ω, J̇_ω q̇ (where the layout has them)."""
    at = vector_of(ib, ib, CTL_AT)
    layout = at[1:].copy()
    buf = np.empty(layout[-1])
    buf[layout[LAYOUT_HEAD + 2 * F_T]] = t
    put_field(buf, layout, F_Q, x[:nv])
    put_field(buf, layout, F_V, x[nQ:nQ + nv])
    H = (phi[:nv * nv].reshape((nv, nv)).T + matrix_of(fb, ib, D_CTL)).copy()  # φ holds H column by column
    put_field(buf, layout, F_H, H.ravel())
    put_field(buf, layout, F_h, phi[i_h:i_h + nv])
    if i_g >= 0:
        put_field(buf, layout, F_G, phi[i_g:i_g + nv])
    put_field(buf, layout, F_P, phi[i_p:i_p + 3])
    put_field(buf, layout, F_PD, phi[i_p + 3:i_p + 6])
    put_field(buf, layout, F_J, phi[i_J:i_J + 3 * nv])
    put_field(buf, layout, F_DR, phi[i_dr:i_dr + 3])
    if ref.size:
        put_field(buf, layout, F_XD, ref[0:3])
        put_field(buf, layout, F_VD, ref[3:6])
        put_field(buf, layout, F_AD, ref[6:9])
    if R_tip.size:
        put_field(buf, layout, F_R, np.ascontiguousarray(R_tip).ravel())
        put_field(buf, layout, F_JW, np.ascontiguousarray(J6[3:]).ravel())
        put_field(buf, layout, F_DW, drift6[3:6])
    tau = np.empty(nv)
    return tau, call_controller(at[0], buf, layout, vector_of(fb, ib, KP).copy(), tau, np.empty(0))


@njit(cache=True, inline="always")
def call(t, phi, x, fb, ib, ref, set_points, R_tip, J6, drift6, out):
    """The status of the module docstring's call, its [ẋ, z, o, τ] written into ``out`` (ẋ with the impulse states'
    rates, τ the law's command [N·m or N], as plan_kernel.call's ``out``). fb, ib: the plan's constants
    (:func:`.plan_kernel.pack`, indices above); INTS: sizes and φ's offsets of h and the tip's J, J̇q̇,
    p (ṗ after it), ẏ's rows in y; J6, drift6, R_tip: the tip's 6 Jacobian rows, J̇q̇ and its rotation (none
    without a tool axis); ref = [x_d, ẋ_d, ẍ_d] [m, m/s, m/s²] the reference (none without), F_d [N] the set-points;
    t [s] the time (a user's controller reads it)."""
    m, nQ, nv, i_h, i_J, i_dr, i_p, o_y0, o_y1, kind, i_ff = vector_of(ib, ib, INTS)
    band = vector_of(fb, ib, SCALARS)[0]  # v_ε [m/s]
    y, A, b, o = kkt_of(phi, fb, ib, P_VAL, P_COL, P_ROW, m)
    if not _tilt(A, o, phi, matrix_of(ib, ib, TILT_I), matrix_of(fb, ib, TILT_F), matrix_of(fb, ib, TILT_T),
                 matrix_of(fb, ib, TILT_BODY), nQ, nv, band):
        return DECLINED
    if kind == OPERATIONAL_LAW:
        tau, ratio = _operational(phi, x, fb, ib, ref, set_points, R_tip, J6, drift6, nQ, nv, i_h, i_J, i_dr, i_p)
        if not ratio >= SINGULAR:  # the readable law raises its error
            return DECLINED
    elif kind == TASK_PD_LAW:
        tau = _task_pd(phi, x, fb, ib, ref, set_points, R_tip, J6, nQ, nv, i_J, i_p, i_ff)
    else:
        tau, status = _controller(t, phi, x, fb, ib, ref, R_tip, J6, drift6, nQ, nv, i_h, i_J, i_dr, i_p, i_ff)
        if status != 1:  # the law raised (its readable command raises its error) or gave no nv torques
            return DECLINED
    b[:nv] += tau
    z = lu_solve(A, b)
    if not np.isfinite(z.dot(z)):
        return DECLINED
    xd = write_out(out, x, z, y, o, tau, nQ, o_y0, o_y1)
    _impulse_rates(xd, z, o, matrix_of(ib, ib, RATES_I), matrix_of(fb, ib, RATES_F), band)
    return OK


@njit(cache=True)
def call_at(t, x, work, phi, fb, ib, out):
    """:func:`call` at (t, x) with φ written from the robot's terms computed here (plan_phi.write_phi, into ``work``:
    plan_phi.work_terms; the tip the plan's first frame) and the reference and the force set-points at t computed
    here from their packed tables: one compiled call per right-hand side."""
    at = vector_of(ib, ib, PHI_AT)
    J6, a6, R_tip = write_phi(t, x, *work_terms(work, at[7], at[8]), phi, at,
                              matrix_of(fb, ib, PHI_MOVES), vector_of(ib, ib, PHI_MSLOTS),
                              matrix_of(fb, ib, PHI_RAMPS), vector_of(ib, ib, PHI_RSLOTS),
                              vector_of(fb, ib, PHI_FRAME), vector_of(ib, ib, PHI_SUPPORT),
                              matrix_of(fb, ib, PHI_RIGID))
    kind = vector_of(ib, ib, REF_KIND)[0]
    ref = np.empty(0) if kind < 0 else reference_of(t, kind, matrix_of(fb, ib, REF_MOVES), matrix_of(fb, ib, REF_R),
                                                     vector_of(fb, ib, REF_CIRCLE), matrix_of(fb, ib, REF_TERMS),
                                                     vector_of(fb, ib, REF_START))
    ramps = matrix_of(fb, ib, RAMPS)
    w = np.empty(2 * ramps.shape[0])
    ramp_rows(t, ramps, w)
    return call(t, phi, x, fb, ib, ref, w[::2].copy(), R_tip, J6, a6, out)


def operational_kernel_of(plan, impulses: list[tuple]):
    """kernel(t, x, φ) -> (ẋ, z, o), or None for a call that goes the readable way (see the module);
    ``kernel.samples(ts, X)`` -> (Φ, O, Z, τ) of the output's samples, or None where one declines. None where
    the plan's mode is not one :func:`call` covers: the operational_space law or a task PD law that is not affine
    (:func:`law_in_call`), no drives, no Coulomb force with a known normal force, no carried reference (2-D slides
    on normal rows and slides from rest are covered).
    ``impulses``: the plan's :func:`~contactdyn.compiled.plan_rhs.impulse_terms`, whose rates the kernel writes into ẋ
    (``kernel.rates`` is True)."""
    s, phase = plan.system, plan.phase
    ctl = phase.controller
    law_kind = law_in_call(ctl)
    if not (law_kind >= 0 and plan.compiled_drives is None and not plan.coulomb_terms and phase.carrier is None) \
            or any(mu is None for _, _, mu, *_ in plan.dyn_tilt) or any(term[4] is None for term in impulses):
        return None  # (a speed-dependent friction law's μ(|v_t|) is Python: the plan's NumPy call takes it)
    nQ, nv, m = s.nQ, s.nv, plan.m
    tf = plan.tip_frame
    off = m * m + m  # o's start in y
    force_keys, law_floats, i_ff = _law_constants(plan, ctl, law_kind)
    ints = [m, nQ, nv, plan.i_h, plan.i_J[tf], plan.i_dr[tf], plan.i_e + plan.e_frame[tf], off + plan.o_y.start,
            off + plan.o_y.stop, law_kind, i_ff]
    tilt_i, tilt_f, tilt_T, tilt_body = _tilt_constants(plan)
    rates_i, rates_f = _rates_constants(plan, impulses)
    P = csr_of(plan)
    ramps = ramp_table([phase.forces[key] for key in force_keys])
    referenced, orient = phase.reference is not None, ctl.reads_orientation
    tables = reference_tables(phase.reference) if referenced else None  # (no carrier: the reference's own)
    kind, *ref_floats = tables or NO_REFERENCE
    fb, ib = pack_with_phi(plan, [P.data, s._D_ctl, tilt_f, tilt_T, tilt_body, rates_f, *law_floats, *ref_floats,
                                  ramps], [P.indices, P.indptr, ints, tilt_i, rates_i, [kind],
                                           _controller_at(plan, ctl, law_kind)])
    none, no_rotation, no_rows = np.empty(0), np.empty((0, 3)), np.empty((0, nv))
    tip6 = plan.tip6  # this make_rhs's tip terms (a later ModePlan.use makes new ones; this kernel keeps its own)
    ramp_values = np.empty(2 * len(ramps))  # F_d [N], Ḟ_d [N/s] per ramp, rewritten per call
    set_points = np.empty(len(ramps))  # F_d [N]
    reference = reference_rows(phase.reference) if referenced else None

    def inputs(t):
        """The call's per-call inputs at t: the reference, F_d [N], the tip's R, J (6 rows), J̇q̇ (6)."""
        ref = reference(t) if referenced else none
        if ramp_values.size:
            ramp_rows(t, ramps, ramp_values)
            set_points[:] = ramp_values[::2]
        if not orient:
            return ref, set_points, no_rotation, no_rows, none
        J6, a6, rotation = tip6  # this call's φ's (plan_phi.phi_function)
        return ref, set_points, rotation, J6, a6

    def one(t, x, phi, out):
        return call(t, phi, x, fb, ib, *inputs(t), out)

    work, phi_buffer, refresh, load = plan.phi.work, plan.phi.buffer, plan.phi.refresh, plan.phi.load

    def one_at(t, x, out):  # one, with the robot's terms, φ, the reference and the set-points in one compiled call
        if load is not None:
            load(x)  # the robot's terms by Pinocchio (a robot contactdyn.robot.rigid_body does not compute)
        if call_at(t, x, work, phi_buffer, fb, ib, out):
            if load is None:
                refresh(x)  # Pinocchio's data at x for the readable way
            return DECLINED
        return OK

    fused = tf == 0 and (tables is not None or not referenced)  # the tip's J, J̇q̇, R are the first frame's
    kernel = calls(plan, one, one_at if fused else None, rates=True)
    no_u = np.zeros(0)  # a step in one compiled call (plan_steps), where the call computes the terms
    kernel.step_inputs = (lambda: (work, phi_buffer, no_u, fb, ib)) if fused and load is None else None
    kernel.kind = OPERATIONAL
    return kernel


def _law_constants(plan, ctl, law_kind: int) -> tuple[list, list, int]:
    """(the set-points' keys in F_d's order, the floats AXES … ORIENT, φ's offset of the feedforward torque or −1)
    of the call's law: the operational_space law's or the task PD law's own constants."""
    s = plan.system
    if law_kind == CONTROLLER_LAW:  # its declared parameters in KP; g in φ after h where it needs it
        if ctl.needs_gravity and not plan.with_g:
            raise ValueError("a controller that needs gravity needs φ's g (plan_kkt.with_g)")
        none = np.zeros((0, 3))
        return [], [none, none, params_of(ctl.config), [], [], [], [s.slip_band, 0.0, 0.0, 0.0, 0.0], none], \
            plan.i_h + s.nv if ctl.needs_gravity else -1
    if law_kind == OPERATIONAL_LAW:
        axes, forced, kp, kd, tool_axis, target, ko, do, k_null, kd_normal = ctl.constants
        return ctl.force_keys, [axes, forced, kp, kd, tool_axis, target, [s.slip_band, ko, do, k_null, kd_normal],
                                np.zeros((0, 3))], -1
    axes, kp, kd, tool_axis, target, R_d, ko, do, kd_joint, kd_normal = ctl.constants
    keys = list(plan.phase.forces)
    forced = np.array([s.force_directions[k] for k in keys], dtype=float).reshape(-1, 3)
    feedforward = ctl.config.feedforward
    if feedforward == "gravity" and not plan.with_g:
        raise ValueError("a task PD law with gravity feedforward needs φ's g (plan_kkt.with_g)")
    i_ff = {"none": -1, "bias": plan.i_h, "gravity": plan.i_h + s.nv}[feedforward]  # h, then g, in φ
    return keys, [axes, forced, kp, kd, tool_axis, target, [s.slip_band, ko, do, kd_joint, kd_normal], R_d], i_ff


def _controller_at(plan, ctl, law_kind: int) -> np.ndarray:
    """CTL_AT: [the controller's address, its layout table] for CONTROLLER_LAW (the inputs the call has: no
    reference, no g unless the law needs it, no orientation unless it reads it, empty); [0] for the other laws."""
    if law_kind != CONTROLLER_LAW:
        return np.zeros(1, dtype=np.int64)
    absent = (() if plan.phase.reference is not None else ("x_d", "v_d", "a_d")) + \
        (() if ctl.needs_gravity else ("gravity",)) + \
        (() if ctl.reads_orientation else ("R_tip", "J_ang", "drift_ang")) + \
        ("tau_contact", "surface_p", "surface_v", "touch")  # (no force-reading law here; set-points: ns = 0)
    return np.concatenate(([controller_address(type(ctl))], layout_of(plan.system.nv, 0, absent)))


def _tilt_constants(plan) -> tuple:
    """(tilt_i, tilt_f, tilt_T, tilt_body) of :func:`_tilt` for the plan's 2-D slides on normal rows."""
    s = plan.system
    nQ, nv, nt = s.nQ, s.nv, len(plan.dyn_tilt)
    tilt_i = np.zeros((nt, 4), dtype=np.int64)
    tilt_f = np.zeros((nt, 3))
    tilt_T = np.zeros((nt, 6))
    tilt_body = np.zeros((nt, 3 * (nQ - nv)))
    for k, (r, ci, mu, T, consts, j) in enumerate(plan.dyn_tilt):
        mode = plan.modes[ci]
        tilt_i[k] = r, plan.i_J[j], plan.o_vt[s.contacts[ci].name].start, launching(mode)
        tilt_f[k] = mu, *mode.slip
        tilt_T[k] = T.ravel()
        tilt_body[k] = np.concatenate((plan.A0[nv:nQ, nQ + r], consts.ravel()))
    return tilt_i, tilt_f, tilt_T, tilt_body


def _rates_constants(plan, impulses: list[tuple]) -> tuple:
    """(rates_i, rates_f) of :func:`_impulse_rates` from the plan's impulse terms (indices into y made o's)."""
    off = plan.m * plan.m + plan.m  # o's start in y
    names = [c.name for c in plan.system.contacts]
    rates_i = np.zeros((len(impulses), 9), dtype=np.int64)
    rates_f = np.zeros((len(impulses), 4))
    for k, (i0, from_z, k_n, sliding, mu, d0, k_visc, stick, ci) in enumerate(impulses):
        r = plan.modes[ci].slip
        kind = 1 if stick is not None else 0 if not sliding else 2 if d0 is not None else 3
        rows = [] if stick is None else list(stick)
        i_vt = plan.o_vt[names[ci]].start
        rates_i[k, :7] = i0, from_z, k_n if from_z else k_n - off, kind, k_visc - off, i_vt, len(rows)
        rates_i[k, 7:7 + len(rows)] = rows
        rates_f[k] = mu, d0 or 0.0, *(r if len(r) == 2 else (0.0, 0.0))
    return rates_i, rates_f
