"""φ, the vector a plan's call is linear in: Pinocchio's terms, the state, the time terms.

    φ = [H (column by column), J_f (3 rows), J̇q̇_f per frame f, h, (g), e],
    e = [x, p_f, ṗ_f per frame f, the reference's and force ramps' time terms, 1]

Per call: Pinocchio's ``computeAllTerms`` at (q, q̇), then per frame ``getFrameJacobian`` (which also
updates the frame's placement, ``data.oMf``) and ``getFrameClassicalAcceleration``; everything else is
written into one buffer by one compiled call, :func:`write_phi` (a further frame's terms by
:func:`write_frame` each). A compiled caller (:mod:`contactdyn.plan_kernel`) runs :func:`write_phi` and
its own call in one function. Units: H [kg·m²], h, g [N·m or N], p [m], ṗ [m/s], J̇q̇ [m/s²].
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin
from numba import njit

from .trajectory import move_rows, move_table, ramp_rows, ramp_table

__all__ = ["phi_function", "write_phi", "write_frame", "LWA"]

LWA = pin.ReferenceFrame.LOCAL_WORLD_ALIGNED


def phi_function(plan):
    """phi(t, x) -> (φ, per-frame Jacobians (3, nv)); leaves Pinocchio's data at x.

    φ and the Jacobians are views of one buffer the next call overwrites (``plan.phi_at`` hands out copies).
    Attributes for a compiled caller: ``phi.pinocchio(x)`` -> (J6, a6) of the first frame (Pinocchio's calls;
    further frames already written), ``phi.terms`` = (H, h, g, p) of the first frame (views of Pinocchio's
    data, which keeps its arrays for its lifetime), ``phi.buffer`` and its Jacobians' views ``phi.jacobians``,
    and ``phi.tables`` (:func:`write_phi`'s at, moves, move_slots, ramps, ramp_slots).
    """
    s = plan.system
    model, data = s.robot.model, s.robot.data
    nQ, nv = s.nQ, s.nv
    fids = plan.fids
    phi = np.zeros(plan.P.shape[1])
    phi[-1] = 1.0  # e's trailing 1
    Js = tuple(phi[i:i + 3 * nv].reshape(3, nv) for i in plan.i_J)
    compute, jacobian, accel = pin.computeAllTerms, pin.getFrameJacobian, pin.getFrameClassicalAcceleration
    H, h = data.M, data.nle
    g = data.g if plan.with_g else np.zeros(0)
    one_dof = nv == 1  # (Pinocchio gives a 1-DOF robot's Jacobian as (6,))
    #: per frame: its id, Pinocchio's translation, where x's v, its J (3 rows), J̇q̇, p and ṗ go in φ; the first
    #: frame's also where h (then g) and x go
    frames = [(fids[f], data.oMf[fids[f]].translation,
               np.array([nQ, plan.i_J[f], plan.i_dr[f], plan.i_e + plan.e_frame[f]]
                        + ([plan.i_h, plan.i_e] if f == 0 else []), dtype=np.intp)) for f in range(len(fids))]
    (fid0, p0, at0), more = frames[0], frames[1:]
    tables = (at0, *_time_tables(plan))
    #: a law that reads the tip's orientation: the tip's 6-row Jacobian and J̇q̇ (linear, angular) of the last
    #: call, as Pinocchio gave them (its R: data.oMf[tip].rotation, updated by the call)
    tip6 = plan.tip6 = [None, None]
    tip = fids[plan.tip_frame] if plan.phase.controller.reads_orientation else None

    def frame_terms(fid):
        J6, a6 = jacobian(model, data, fid, LWA), accel(model, data, fid, LWA).vector
        if one_dof:
            J6 = J6.reshape(6, 1)
        if fid == tip:
            tip6[0], tip6[1] = J6, a6
        return J6, a6

    def pinocchio(x):
        compute(model, data, x[:nv], x[nQ:nQ + nv])
        for fid, p, at in more:
            write_frame(phi, *frame_terms(fid), p, x, at)
        return frame_terms(fid0)

    if not more and tip is None and not one_dof:
        def pinocchio(x):  # the same for one frame whose terms are only written (~0.13 µs less a call)
            compute(model, data, x[:nv], x[nQ:nQ + nv])
            return jacobian(model, data, fid0, LWA), accel(model, data, fid0, LWA).vector

    def phi_of(t, x):
        J6, a6 = pinocchio(x)
        write_phi(t, x, H, h, g, J6, a6, p0, phi, *tables)
        return phi, Js

    phi_of.pinocchio, phi_of.terms, phi_of.buffer, phi_of.tables = pinocchio, (H, h, g, p0), phi, tables
    phi_of.jacobians = Js
    return phi_of


def _time_tables(plan) -> tuple:
    """(moves, move_slots, ramps, ramp_slots): the reference's moves whose σ, σ'/T go to φ[slot], φ[slot + 1] and
    the force ramps whose F_d [N] goes to φ[slot] (trajectory.move_table, ramp_table)."""
    i_e = plan.i_e
    return (move_table([m_ for _, m_ in plan.time_moves]),
            np.array([i_e + slot for slot, _ in plan.time_moves], dtype=np.intp),
            ramp_table([ramp for _, ramp, _ in plan.time_ramps]),
            np.array([i_e + slot for slot, _, _ in plan.time_ramps], dtype=np.intp))


@njit(cache=True)
def write_phi(t, x, H, h, g, J6, a6, p, phi, at, moves, move_slots, ramps, ramp_slots):
    """φ at (t, x): H column by column from 0, h (then g, if any) from at[4], x from at[5], the first frame's
    terms (:func:`write_frame`), the time terms at t [s] at their slots (:func:`_time_tables`)."""
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


@njit(cache=True)
def write_frame(phi, J6, a6, p, x, at):
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
