"""A force-reading controller or a carried reference on the compiled path: folded into the solve.

A controller that reads measured forces (A7, A10, the hybrid law) is affine in them,
τ = τ₀ + B λ, and where a force is a row's unknown λ (a bonded or rigid contact, a stick,
a bonded tangential chain) B folds into the constraint matrix; a reference carried by a
body makes the command affine in that body's acceleration, which folds the same way. The
readable model does that in :func:`~contactdyn.constraints.solve_folded` (probing the
controller with a unit force per row, re-checking the drives' clip pattern with the solved
λ); the plan calls the very same function on its own system, read off the compiled KKT
matrix per call:

    f = [b_Q + Σ_f J_fᵀ w_f]   (w_f = g_f: the Cartesian forces the plan carries as unknowns)
    rows G = A[rows, :nQ],   columns C = −A[:nQ, rows]ᵀ (sliding tilt included),   γ = −b[rows]

So the fold, the drives and the clipping are written once. It costs the controller's
command once per row (and once more for a carried reference) and a second small solve.
"""

from __future__ import annotations

import numpy as np

from .constraints import Rows, solve_folded
from .dynamics import command_of

__all__ = ["contact_torque_of", "folded_solve"]


def contact_torque_of(plan):
    """torque(b, Js) -> Σ_f J_fᵀ w_f: the contacts' generalized force on the joints [N·m or N], w_f = b's w rows."""
    w0 = plan.system.nQ + plan.nr

    def torque(b, Js):
        tau = Js[0].T.dot(b[w0:w0 + 3])
        for f in range(1, len(Js)):
            tau = tau + Js[f].T.dot(b[w0 + 3 * f:w0 + 3 * f + 3])
        return tau

    return torque


def folded_solve(plan, make_input):
    """solve(t, x, Js, φ, o, A, b) -> (z = [Q̈, λ, w], ż): the readable fold on the plan's KKT system."""
    s = plan.system
    nQ, nv, nr = s.nQ, s.nv, plan.nr
    phase = plan.phase
    ctl = phase.controller
    vmask = s._joint_motors if ctl.outputs == "voltage" else None
    kinds = {"normal": "n", "stick": "t", "limit": "limit"}
    meta = [(row.owner, kinds.get(row.kind, row.label), row.index) for row in plan.rows]
    torque = contact_torque_of(plan)
    fold_rows = ctl.uses_forces and nr > 0
    w0 = nQ + nr

    def solve(t, x, Js, phi, o, A, b):
        tau_c = torque(b, Js)
        inp = make_input(t, x, x[:nv], x[nQ:nQ + nv], Js, phi, o, tau_c)
        cmd, zdot, carried = command_of(s, inp, phase, x)
        if not fold_rows and carried is None:  # as the readable model: the drives, then the plain solve
            s.drives.apply(cmd, x, nQ, b, voltage=vmask)  # b[:nQ] takes the drives' forces
            z = np.linalg.solve(A, b)
            return (z if np.all(np.isfinite(z)) else plan._singular(A, b)), zdot
        rows = Rows()
        for r in range(nr):
            rows.add(A[nQ + r, :nQ].copy(), -b[nQ + r], meta[r], -A[:nQ, nQ + r])
        f = b[:nQ].copy()
        f[:nv] += tau_c
        _, qdd, lam, regular, _, zdot = solve_folded(s, inp, ctl, cmd, zdot, f, rows, x, vmask, carried)
        if not regular:
            plan.singular += 1
        return np.concatenate((qdd, lam, b[w0:])), zdot

    return solve
