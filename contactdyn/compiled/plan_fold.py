"""A force-reading controller or a carried reference on the compiled path: folded into the solve.

A controller that reads measured forces (A7, A10, the hybrid law) is affine in them,
τ = τ₀ + B λ, and where a force is a row's unknown λ (a bonded or rigid contact, a stick,
a bonded tangential chain) B folds into the constraint matrix; a reference carried by a
body makes the command affine in that body's acceleration, which folds the same way. The
readable model does that in :func:`~contactdyn.model.constraints.solve_folded` (probing the
controller with a unit force per row, re-checking the drives' clip pattern with the solved
λ). The plan gets τ₀ and B from a tip law read off as a matrix (:mod:`contactdyn.compiled.plan_law`:
B = H J⁺ D from the matrix's columns of the measured forces, no ``ControlInput``), else
probes with the same :func:`~contactdyn.model.constraints.force_columns`, and folds through its
compiled drives (L_τ, :mod:`contactdyn.compiled.plan_drives`) into its own KKT matrix: one solve,
then, where a drive has a voltage limit, a check that none clips at the solved command.
Where one does, it calls ``solve_folded`` itself on its system read off the compiled KKT
matrix:

    f = [b_Q + Σ_f J_fᵀ w_f]   (w_f = g_f: the Cartesian forces the plan carries as unknowns)
    rows G = A[rows, :nQ],   columns C = −A[:nQ, rows]ᵀ (sliding tilt included),   γ = −b[rows]

So the probes, the drives' law and the clipping are written once. Probing costs the
controller's command once per row (and once more for a carried reference) besides its own;
the matrix path a few products per call (B from H, J⁺ and the columns read once).
"""

from __future__ import annotations

import math

import numpy as np

from ..model.constraints import Rows, force_columns, solve_folded
from ..model.dynamics import carried_terms, command_of
from ..numerics.linalg import contiguous as _c
from .plan_kernel import fold_solve
from .plan_law import compiled_law, plan_command, plan_commands

__all__ = ["contact_torque_of", "folded_solve", "reaching_rows", "row_meta"]


def contact_torque_of(plan):
    """torque(b, Js) -> Σ_f J_fᵀ w_f: the contacts' generalized force on the joints [N·m or N], w_f = b's w rows."""
    w0 = plan.system.nQ + plan.nr

    def torque(b, Js):
        tau = Js[0].T.dot(b[w0:w0 + 3])
        for f in range(1, len(Js)):
            tau = tau + Js[f].T.dot(b[w0 + 3 * f:w0 + 3 * f + 3])
        return tau

    return torque


def reaching_rows(plan) -> list[int] | None:
    """The rows whose column on the coordinates beyond the robot, A[nv:nQ, nQ + r], is nonzero (their force is
    in the measured joint torque, :func:`~contactdyn.model.constraints.force_columns`), where the plan's map P makes
    those entries constant (no sliding tilt writes them); None where a call must look."""
    s, m, nr = plan.system, plan.m, plan.nr
    nv, nQ = s.nv, s.nQ
    P = plan.P[:m * m].reshape(m, m, -1)[nv:nQ, nQ:nQ + nr]  # φ's last entry is the constant 1
    if plan.dyn_tilt or np.any(P[..., :-1]):
        return None
    return [int(j) for j in np.flatnonzero(np.any(P[..., -1] != 0.0, axis=0))]


def _matrix_fold(plan, drives):
    """fold(τ, ż, B, D_z, carried, x, A, b, with_tau) -> (z, ż, τ or None), or None where the solved command
    clips a voltage: the λ-free command τ through the compiled drives into b, its parts per unit row force B
    (and per unit acceleration of a carrying body) through L_τ into A's columns, one solve."""
    nQ, nr = plan.system.nQ, plan.nr
    lam_cols = slice(nQ, nQ + nr)
    lam_index = np.arange(nQ, nQ + nr)
    L, L_tau, limited = _c(drives.L), drives.L_tau, bool(drives.limited)

    def fold(tau, zdot, B, Dz, carried, x, A, b, with_tau):
        cols, B_all = lam_index, B
        if carried is not None:  # the command's part proportional to the carrying body's acceleration: a column
            i_b, tau_b, zdot_b = carried
            cols, B_all = np.append(lam_index, i_b), np.column_stack((B, tau_b))
        if limited:  # copies: a call that clips needs A and b as they are for the readable model
            A, b = A.copy(), b.copy()
        z, y0, Y = fold_solve(A, b, L, L_tau, _c(tau), _c(x), _c(B_all), cols, nQ)  # A, b: folded
        if not math.isfinite(z.dot(z)):
            z = plan._singular(A, b)
        lam = z[lam_cols]
        if limited and not drives.unclipped(y0 + Y.dot(z[cols])):  # the voltages at the solved command
            return None
        if with_tau:
            tau = tau + B.dot(lam)
            if carried is not None:
                tau = tau + tau_b * z[i_b]
        if Dz is not None:
            zdot = zdot + Dz.dot(lam)
            if carried is not None and zdot_b is not None:
                zdot = zdot + zdot_b * z[i_b]
        return z, zdot, (tau if with_tau else None)

    return fold


def row_meta(plan) -> list[tuple]:
    """The plan's rows as a controller's force columns read them: (owner, kind, index), kind "n" | "t" | "limit" |
    "joint" | a chain's label."""
    kinds = {"normal": "n", "stick": "t", "limit": "limit", "joint": "joint"}
    return [(row.owner, kinds.get(row.kind, row.label), row.index) for row in plan.rows]


def _law_parts(plan, ctl, meta: list):
    """parts(t, x, Js, φ, o, A, τ_c) -> (τ, ż, B, D_z, carried, None) of a tip law read off as a matrix, at the
    plan's own slots (:func:`~contactdyn.compiled.plan_law.plan_command`), or None while its matrix is not read; None
    for a controller that is not one. B = H J⁺ D_a (+ Jᵀ D_f) with D, M's columns of the rows' measured forces,
    read once; a row reaching beyond the robot adds its column on the joints (the measured joint torque)."""
    fast = plan_command(plan)
    if fast is None:
        return None
    s, phase, nr = plan.system, plan.phase, plan.nr
    nQ, nv = s.nQ, s.nv
    carrier = phase.carrier if phase.reference is not None else None
    lam_cols = slice(nQ, nQ + nr)
    reach = reaching_rows(plan)
    every_row_reaches = reach == list(range(nr))
    increments = ctl.ctl.increments
    row_columns = None  # (D_a, D_f, D_z) of CompiledLaw.row_columns, once the law's matrix is read

    def row_parts(H, J, A):
        """B for one sample, or per sample of a stack (H, J, A with a leading sample axis; ``reach`` known)."""
        nonlocal row_columns
        if row_columns is None:
            row_columns = ctl.row_columns(meta)
        D_a, D_f, Dz = row_columns
        B = increments(H, J, D_a, D_f)
        if every_row_reaches:
            B += A[..., :nv, lam_cols]
        else:
            for j in (reach if reach is not None else np.flatnonzero(A[nv:nQ, lam_cols].any(axis=0))):
                B[..., j] += A[..., :nv, nQ + j]
        return B, Dz

    def parts(t, x, Js, phi, o, A, tau_c):
        got = fast(t, x, Js, phi, o, tau_c)
        if got is None:
            return None
        tau, zdot, H, J = got
        B, Dz = row_parts(H, J, A)
        carried = None if carrier is None else carried_terms(carrier[0], *ctl.carried_increment(H, J, carrier[1]),
                                                             zdot)
        return tau, zdot, B, Dz, carried, None

    if carrier is None and reach is not None:  # (the output's samples all at once, contactdyn.compiled.samples)
        fast_all = plan_commands(plan)

        def parts_all(ts, X, Phi, O, A, T_c):
            """(τ (N, nv), B (N, nv, nr)) of :func:`parts` over N samples, the same arithmetic per sample; None
            while the law's matrix is not read."""
            got = fast_all(ts, X, Phi, O, T_c)
            if got is None:
                return None
            tau, _, H, J = got
            return tau, row_parts(H, J, A)[0]

        plan.folded_parts_all = parts_all
    return parts


def folded_solve(plan, make_input, drives):
    """solve(t, x, Js, φ, o, A, b) -> (z = [Q̈, λ, w], ż): the readable fold on the plan's KKT system.

    The fold goes through the compiled drives (:class:`~contactdyn.compiled.plan_drives.CompiledDrives`)
    into the plan's own matrix while no voltage clips: A[:nQ, λ] −= L_τ B (B: the command per
    unit row force, :func:`~contactdyn.model.constraints.force_columns`), A[:nQ, Q_b] −= L_τ ∂τ/∂Q̈_b
    for a reference carried by body coordinate Q_b, b[:nQ] += the drives' forces at the
    λ-free command; a call whose solved command clips a voltage goes through the readable
    :func:`~contactdyn.model.constraints.solve_folded`. A tip law read off as a matrix
    (:mod:`contactdyn.compiled.plan_law`) gives τ, ż, B and D_z from the plan's own slots
    (:func:`~contactdyn.compiled.plan_law.plan_command`), no ControlInput.
    """
    s = plan.system
    nQ, nv, nr = s.nQ, s.nv, plan.nr
    phase = plan.phase
    ctl = compiled_law(plan)  # a force-reading tip law by its matrix (plan_law), else the controller
    vmask = s._joint_motors if ctl.outputs == "voltage" else None
    meta = row_meta(plan)
    torque = contact_torque_of(plan)
    fold_rows = ctl.uses_forces and nr > 0
    w0 = nQ + nr
    matrix_fold = _matrix_fold(plan, drives)
    law_parts = _law_parts(plan, ctl, meta)

    def parts(t, x, Js, phi, o, A, tau_c):
        """(τ, ż, B, D_z, carried, (ControlInput, drive command) or None): the λ-free command and its parts per
        unit row force and body acceleration, by the law's matrix at the plan's slots where it is read, else
        probed."""
        got = law_parts(t, x, Js, phi, o, A, tau_c) if law_parts is not None else None
        if got is not None:
            return got
        inp = make_input(t, x, x[:nv], x[nQ:nQ + nv], Js, phi, o, tau_c)
        cmd, zdot, carried = command_of(s, inp, phase, x, ctl)
        B, Dz = force_columns(inp, ctl, cmd[:nv], zdot, meta, [-A[:nQ, nQ + r] for r in range(nr)], nv)
        return cmd[:nv], zdot, B, Dz, carried, (inp, cmd)

    def detail(t, x, Js, phi, o, A, b, with_tau=True):
        """(z, ż, the solved joint command τ [N·m or N; V]): the output reads what the drives made of τ."""
        tau_c = torque(b, Js)
        tau, zdot, B, Dz, carried, readable = parts(t, x, Js, phi, o, A, tau_c)
        z = matrix_fold(tau, zdot, B, Dz, carried, x, A, b, with_tau)
        if z is not None:
            return z
        if readable is None:  # a voltage clips: the readable model, from a ControlInput
            inp = make_input(t, x, x[:nv], x[nQ:nQ + nv], Js, phi, o, tau_c)
            cmd, zdot, carried = command_of(s, inp, phase, x, ctl)
        else:
            inp, cmd = readable
        if not fold_rows and carried is None:  # as the readable model: the drives, then the plain solve
            s.drives.apply(cmd, x, nQ, b, voltage=vmask)  # b[:nQ] takes the drives' forces
            z = np.linalg.solve(A, b)
            return (z if np.all(np.isfinite(z)) else plan._singular(A, b)), zdot, cmd[:nv]
        rows = Rows()
        for r in range(nr):
            rows.add(A[nQ + r, :nQ].copy(), -b[nQ + r], meta[r], -A[:nQ, nQ + r])
        f = b[:nQ].copy()
        f[:nv] += tau_c
        _, qdd, lam, regular, full, zdot = solve_folded(s, inp, ctl, cmd, zdot, f, rows, x, vmask, carried)
        if not regular:
            plan.singular += 1
        return np.concatenate((qdd, lam, b[w0:])), zdot, full[:nv]

    def solve(t, x, Js, phi, o, A, b):
        return detail(t, x, Js, phi, o, A, b, False)[:2]

    plan.folded_detail = detail
    plan.folded_parts = parts  # (the output folds its samples' parts all at once, contactdyn.compiled.samples)
    return solve
