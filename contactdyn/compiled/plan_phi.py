"""φ, the vector a plan's call is linear in: Pinocchio's terms, the state, the time terms.

    φ = [H (column by column), J_f (3 rows), J̇q̇_f per frame f, h, (g), e],
    e = [x, p_f, ṗ_f per frame f, the reference's and force ramps' time terms, 1]

Per call: the robot's terms at (q, q̇), computed in the compiled call :func:`write_phi` itself for a plan of one
frame on a robot of revolute and prismatic joints (:mod:`contactdyn.robot.rigid_body`; into Pinocchio's data from
Python, into a buffer of the plan's from a compiled caller: :func:`work_terms`), else by Pinocchio's
``computeAllTerms``; everything else is written into one buffer by :func:`write_phi`, the first frame's terms
included. A frame's Jacobian, J̇q̇, position and
rotation come from its joint's placement and motion and the joint Jacobians (:func:`frame_motion`, as
Pinocchio's ``getFrameJacobian`` and ``getFrameClassicalAcceleration`` in LOCAL_WORLD_ALIGNED, to rounding;
two binding calls fewer); a further frame's are written by :func:`write_frame` after Pinocchio's call.
A compiled caller (:mod:`contactdyn.compiled.plan_kernel`) runs :func:`write_phi` and its own call in one function.
Units: H [kg·m²], h, g [N·m or N], p [m], ṗ [m/s], J̇q̇ [m/s²].
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin

from ..laws.trajectory import move_rows, move_table, ramp_rows, ramp_table
from ..numerics.compile_cache import njit
from ..robot.rigid_body import NO_TABLE, frame_motion_into, rigid_terms

__all__ = ["phi_function", "write_phi", "write_phi_only", "work_terms", "copy_terms", "write_frame", "frame_motion",
           "joint_terms", "frame_constants", "LWA"]

LWA = pin.ReferenceFrame.LOCAL_WORLD_ALIGNED


def phi_function(plan):
    """phi(t, x) -> (φ, per-frame Jacobians (3, nv)); leaves Pinocchio's data at x (with a rigid table: the eight
    arrays of :func:`joint_terms` and ``computeAllTerms``' M, nle, g that the plans and their readers read).

    φ and the Jacobians are views of one buffer the next call overwrites (``plan.phi_at`` hands out copies).
    Attributes for a compiled caller: ``phi.work``, a buffer of the caller's own for the robot's terms
    (:func:`work_terms`: one argument in place of Pinocchio's eight views), which :func:`write_phi` fills in the
    call where it computes the terms (``phi.load`` None; the caller then leaves Pinocchio's data behind, and
    ``phi.refresh(x)`` brings it to x for the readable way where the call declines), else ``phi.load(x)`` by
    Pinocchio's call first; ``phi.buffer`` and its Jacobians' views
    ``phi.jacobians``, and ``phi.tables`` (:func:`write_phi`'s at, moves, move_slots, ramps, ramp_slots, frame,
    support, rigid). ``plan.tip6`` = [J (6, nv), J̇q̇ (6), R] of the tip at the last call, for a law reading its
    orientation.
    """
    s = plan.system
    model, data = s.robot.model, s.robot.data
    nQ, nv = s.nQ, s.nv
    fids = plan.fids
    phi = np.zeros(plan.P.shape[1])
    phi[-1] = 1.0  # e's trailing 1
    Js = tuple(phi[i:i + 3 * nv].reshape(3, nv) for i in plan.i_J)
    g = data.g if plan.with_g else np.zeros(0)
    terms = (data.M, data.nle, g, *joint_terms(model, data, fids[0]))
    #: the robot's terms computed in write_phi (robot.rigid_body) where it can, for one frame (further frames'
    #: terms are written from Python between Pinocchio's call and the plan's); else Pinocchio's call
    rigid = s.robot.rigid_table if len(fids) == 1 else None
    compute = pin.computeAllTerms if rigid is None else None
    #: per frame: where x's v, its J (3 rows), J̇q̇, p and ṗ go in φ; the first frame's also where h (then g) and x go,
    #: its joint, nv and g's size (:func:`work_terms`)
    ats = [np.array([nQ, plan.i_J[f], plan.i_dr[f], plan.i_e + plan.e_frame[f]]
                    + ([plan.i_h, plan.i_e, model.frames[fids[0]].parentJoint, nv, g.size] if f == 0 else []),
                    dtype=np.intp) for f in range(len(fids))]
    #: the further frames: their joints' views, their constants, where their terms go
    more = [(joint_terms(model, data, fids[f]), frame_constants(model, fids[f]), ats[f]) for f in range(1, len(fids))]
    tables = (ats[0], *_time_tables(plan), *frame_constants(model, fids[0]), NO_TABLE if rigid is None else rigid)
    #: a law that reads the tip's orientation: the tip's 6-row Jacobian, J̇q̇ (linear, angular) and rotation of the
    #: last call
    tip6 = plan.tip6 = [None, None, None]
    tip = plan.tip_frame if plan.phase.controller.reads_orientation else None

    def pinocchio(x):
        compute(model, data, x[:nv], x[nQ:nQ + nv])
        for f, (joint, constants, at) in enumerate(more, start=1):
            J6, a6, p, R_f = frame_motion(*joint, *constants)
            write_frame(phi, J6, a6, p, x, at)
            if f == tip:
                tip6[:] = J6, a6, R_f

    H, h, g, R, pj, vj, aj, Jw = terms
    at, moves, move_slots, ramps, ramp_slots, frame, support, table = tables

    def phi_of(t, x):
        if compute is not None:
            pinocchio(x)
        if tip == 0:
            tip6[:] = write_phi(t, x, H, h, g, R, pj, vj, aj, Jw, phi, at, moves, move_slots, ramps, ramp_slots,
                                frame, support, table)
        else:
            write_phi_only(t, x, H, h, g, R, pj, vj, aj, Jw, phi, at, moves, move_slots, ramps, ramp_slots, frame,
                           support, table)
        return phi, Js

    work = np.zeros(nv * nv + 7 * nv + g.size + 24)

    def load(x):  # Pinocchio's terms at x into a compiled caller's buffer (further frames' written into φ)
        pinocchio(x)
        copy_terms(work, H, h, g, R, pj, vj, aj, Jw)

    phi_of.buffer, phi_of.tables, phi_of.work = phi, tables, work
    phi_of.load = load if rigid is None else None
    phi_of.refresh = lambda x: pin.computeAllTerms(model, data, x[:nv], x[nQ:nQ + nv])
    phi_of.jacobians = Js
    return phi_of


def joint_terms(model, data, fid: int) -> tuple:
    """(R, p_j, v_j, a_j, J_w): views of Pinocchio's data of the joint frame ``fid`` is attached to, which
    ``computeAllTerms`` updates in place: its rotation and position [m] in the world, its velocity and
    acceleration at q̈ = 0 in its own frame ([linear, angular]), and the joint Jacobians (WORLD, 6 × nv)."""
    j = model.frames[fid].parentJoint
    return (data.oMi[j].rotation, data.oMi[j].translation, data.v[j].vector, data.a[j].vector,
            data.J.reshape(6, model.nv))  # (eigenpy gives one column as (6,); the reshape is a view)


def frame_constants(model, fid: int) -> tuple[np.ndarray, np.ndarray]:
    """(frame, support) of :func:`frame_motion`: the frame in its joint's frame, [r (3) [m], its rotation (3 × 3,
    by rows)], and the velocity columns of the joints that move it."""
    frame = model.frames[fid]
    placement = frame.placement
    support = [k for jj in model.supports[frame.parentJoint][1:]
               for k in range(model.joints[jj].idx_v, model.joints[jj].idx_v + model.joints[jj].nv)]
    return (np.concatenate([placement.translation, placement.rotation.ravel()]),
            np.array(support, dtype=np.intp))


def _time_tables(plan) -> tuple:
    """(moves, move_slots, ramps, ramp_slots): the reference's moves whose σ, σ'/T go to φ[slot], φ[slot + 1] and
    the force ramps whose F_d [N] goes to φ[slot] (trajectory.move_table, ramp_table)."""
    i_e = plan.i_e
    return (move_table([m_ for _, m_ in plan.time_moves]),
            np.array([i_e + slot for slot, _ in plan.time_moves], dtype=np.intp),
            ramp_table([ramp for _, ramp, _ in plan.time_ramps]),
            np.array([i_e + slot for slot, _, _ in plan.time_ramps], dtype=np.intp))


@njit(cache=True)
def write_phi(t, x, H, h, g, R, pj, vj, aj, Jw, phi, at, moves, move_slots, ramps, ramp_slots, frame, support, rigid):
    """φ at (t, x): the robot's terms first if ``rigid`` has rows (:func:`~contactdyn.robot.rigid_body.rigid_terms`
    into H, h, g, Jw and the frame's joint at[6]'s R, pj, vj, aj; else Pinocchio's call wrote them), then H column
    by column from 0, h (then g, if any) from at[4], x from at[5], the first frame's terms (:func:`frame_motion`,
    :func:`write_frame`), the time terms at t [s] at their slots (:func:`_time_tables`). Returns the first
    frame's (J (6, nv), J̇q̇ (6), R)."""
    nv = h.size
    if rigid.shape[0]:
        rigid_terms(x[:nv], x[at[0]:at[0] + nv], rigid, at[6], H, h, g, R, pj, vj, aj, Jw)
    for j in range(nv):
        for i in range(nv):
            phi[j * nv + i] = H[i, j]
    for i in range(nv):
        phi[at[4] + i] = h[i]
    for i in range(g.size):
        phi[at[4] + nv + i] = g[i]
    for i in range(x.size):
        phi[at[5] + i] = x[i]
    J6, a6, p, Rf = frame_motion(R, pj, vj, aj, Jw, frame, support)
    write_frame(phi, J6, a6, p, x, at)
    if move_slots.size:
        w = np.empty(3 * move_slots.size)
        move_rows(t, moves, w)
        for k in range(move_slots.size):
            phi[move_slots[k]] = w[3 * k]
            phi[move_slots[k] + 1] = w[3 * k + 1]
    if ramp_slots.size:
        w = np.empty(2 * ramp_slots.size)
        ramp_rows(t, ramps, w)
        for k in range(ramp_slots.size):
            phi[ramp_slots[k]] = w[2 * k]
    return J6, a6, Rf


#: inline="always" (here and below): a helper compiled into its compiled callers, not as a level of its own
#: (numba compiles each function with all it calls: ~10 s of case1_cart's first run over these helpers)
@njit(cache=True, inline="always")
def work_terms(work, nv, ng):
    """(H, h, g, R, pj, vj, aj, Jw) as views of a compiled caller's own buffer (:func:`phi_function`'s
    ``phi.work``), in :func:`write_phi`'s argument order: H (nv, nv) [kg·m²], h, g (nv, ng) [N·m or N], the
    joint's R (3, 3), p (3) [m], v (6) [m/s, rad/s], a at q̈ = 0 (6) [m/s², rad/s²] and the joint Jacobians
    (6, nv). The matrices are stored column by column (views in Fortran order), as Pinocchio's own arrays that a
    Python caller passes: the functions they go to are compiled once, not once per order."""
    o = nv * nv
    H = work[:o].reshape((nv, nv)).T
    h, g = work[o:o + nv], work[o + nv:o + nv + ng]
    o += nv + ng
    R = work[o:o + 9].reshape((3, 3)).T
    return H, h, g, R, work[o + 9:o + 12], work[o + 12:o + 18], work[o + 18:o + 24], work[o + 24:].reshape((nv, 6)).T


@njit(cache=True)
def copy_terms(work, H, h, g, R, pj, vj, aj, Jw):
    """Pinocchio's terms (M, nle, g and :func:`joint_terms`' views) into a compiled caller's buffer
    (:func:`work_terms`)."""
    H_, h_, g_, R_, pj_, vj_, aj_, Jw_ = work_terms(work, h.size, g.size)
    H_[:] = H
    h_[:] = h
    g_[:] = g
    R_[:] = R
    pj_[:] = pj
    vj_[:] = vj
    aj_[:] = aj
    Jw_[:] = Jw


@njit(cache=True)
def write_phi_only(t, x, H, h, g, R, pj, vj, aj, Jw, phi, at, moves, move_slots, ramps, ramp_slots, frame, support,
                   rigid):
    """:func:`write_phi` for a Python caller that needs no frame terms back (an array handed back costs ~0.1 µs)."""
    write_phi(t, x, H, h, g, R, pj, vj, aj, Jw, phi, at, moves, move_slots, ramps, ramp_slots, frame, support, rigid)


@njit(cache=True)
def frame_motion(R, pj, vj, aj, Jw, frame, support):
    """(J, J̇q̇, p, R_f) of a frame in LOCAL_WORLD_ALIGNED, as Pinocchio's getFrameJacobian (6 × nv, rows linear then
    angular), getFrameClassicalAcceleration at q̈ = 0 [m/s², rad/s²] and its placement (p [m], R_f), from its
    joint's (:func:`joint_terms`: R, pj, vj, aj, Jw) and the frame in the joint's, ``frame`` = [r, rotation by
    rows] (:func:`frame_constants`; ``support``: the joints' columns that move it):
    p = p_j + R r;  J's column c = [v_c + ω_c × p, ω_c] of the joint Jacobians (WORLD, at the origin);
    J̇q̇ = R (a + α × r + ω × (v + ω × r)) and R α, with (v, ω), (a, α) the joint's own [linear, angular]."""
    nv = Jw.shape[1]
    p, Rf, J6, a6 = np.empty(3), np.empty((3, 3)), np.zeros((6, nv)), np.empty(6)
    frame_motion_into(R, pj, vj, aj, Jw, frame, support, J6, a6, p, Rf)
    return J6, a6, p, Rf


@njit(cache=True, inline="always")
def write_frame(phi, J6, a6, p, x, at):
    """φ's terms of one frame: its J's translation rows (3, nv) from at[1], J̇q̇'s linear part [m/s²] from at[2],
    p [m] and ṗ = J v [m/s] from at[3] (J6, a6: the frame's 6-row Jacobian and classical acceleration,
    :func:`frame_motion`; v: x[at[0]:at[0] + nv])."""
    nv = J6.shape[1]
    for r in range(3):
        phi[at[2] + r] = a6[r]
        phi[at[3] + r] = p[r]
        pd = 0.0
        for c in range(nv):
            phi[at[1] + r * nv + c] = J6[r, c]
            pd += J6[r, c] * x[at[0] + c]
        phi[at[3] + 3 + r] = pd
