"""Built-in controllers compiled into the pipeline as kinds: operational space, the dynamic laws, joint PD, task force.

``operational_space`` (:mod:`contactdyn.laws.controllers.operational`) reads its own config (its position axes come
from the phase's force directions at bind time, variable-size tables, not declared float parameters), so it is a
kind of the call, as ``task_pd`` is: its constants (``OperationalSpace.constants``) packed in ``reals``, its
arithmetic :func:`contactdyn.laws.controllers.operational_law.torque`, the very function its readable ``command``
calls. A task singular at the state (the Hadamard ratio below ``SINGULAR``, or NaN) gives τ = NaN: the KKT solve
then fails its residual test (status 0) and the readable model answers, where ``OperationalSpace._guard`` raises
its error.

Its packed constants (from ``R_CTL``, written by ``pack``): axes (k × 3), force directions (nf × 3),
kp (k) [N/m], kd (k) [N·s/m], tool axis (3), tool target (3), ko [1/s²], do [1/s], k_null [1/s], kd_normal [N·s/m];
k = ``N_AXES``, nf = ``N_FORCES`` (the phase's set-points, in the order of ``OperationalSpace.force_keys``), a tool
axis iff ``HAS_TOOL``.

The task-space dynamic laws (A7, A10, hybrid: :mod:`contactdyn.laws.controllers.dynamic`) are called as a user's
controller of the same shape is, on the controller ABI's buffer (:func:`dynamic_command`, their states' rates its
second output), so :mod:`.force_fold` folds them the same way; their tip targets are
:mod:`contactdyn.laws.controllers.dynamic_law`'s and τ :func:`~contactdyn.laws.controllers.computed_torque.torque`,
the functions their readable ``command`` calls. Their constants: ``pack``'s ``D_*``.

``joint_pd`` (:func:`~contactdyn.laws.controllers.pd.joint_pd_torque`; constants K_p, K_d per joint) and
``task_force`` (:func:`~contactdyn.laws.controllers.force.task_force_torque`; constants force (3) [N], rate (3)
[N/s], start [s], ramp_time [s], amplitude (3) [N], frequency [Hz], phase (3) [rad], oscillates) read their own
config too: kinds, their readable ``command`` the same compiled function; feedforward by ``FEEDFORWARD``.
"""

from __future__ import annotations

import numpy as np

from ...laws.controllers import computed_torque
from ...laws.controllers.abi import control_arrays
from ...laws.controllers.dynamic_law import force_targets, position_targets
from ...laws.controllers.force import task_force_torque
from ...laws.controllers.operational_law import SINGULAR, torque
from ...laws.controllers.pd import joint_pd_torque
from ...numerics.compile_cache import njit
from ...numerics.linalg import pinv
from .pack import (
    D_ENV,
    D_FORCE_LAW,
    D_KF,
    D_KNULL,
    D_KP,
    D_KV,
    D_P,
    D_PRESSING,
    D_SWAP,
    D_TRACKS,
    FEEDFORWARD,
    FF_BIAS,
    FF_GRAVITY,
    HAS_TOOL,
    N_AXES,
    N_FORCES,
    NQ,
    NV,
    R_CTL,
    W_PINV,
    section,
)

__all__ = ["operational_command", "dynamic_command", "joint_pd_command", "task_force_command"]

@njit(cache=True)
def _pinv_kept(work, at, J):
    """J⁺ (numerics.linalg.pinv), computed again only where J is not the one kept at ``work[at]`` (the fold calls
    the law at one state nr + 1 times)."""
    n = J.size
    flat = J.ravel()
    key, kept = work[at + 1:at + 1 + n], work[at + 1 + n:at + 1 + 2 * n]
    same = work[at] == 1.0
    for i in range(n):
        same = same and key[i] == flat[i]
    if same:
        return kept.reshape((J.shape[1], J.shape[0]))
    Jp = pinv(J)
    key[:] = flat
    kept[:] = Jp.ravel()
    work[at] = 1.0
    return Jp


@njit(cache=True)
def dynamic_command(ints, reals, work, buf, lay, tau, zdot):
    """A dynamic law on its controller buffer (the ABI's layout): τ = H q̈*(a*) + h − τ_c (+ Jᵀ f_swap) around its
    tip targets, ż; status 1 (the ABI's call, so the fold treats it as a user's law of the same shape)."""
    inp = control_arrays(buf, lay)
    c = reals[ints[R_CTL]:]
    ns = lay[2]
    kp, kv, P = c[D_KP:D_KP + 3], c[D_KV:D_KV + 3], section(c, D_P, 3, 3)
    env = section(c, D_ENV, ns, 3)
    if c[D_FORCE_LAW] != 0.0:
        a, f_swap, rates = force_targets(P, inp.p_tip, inp.v_tip, inp.x_d, inp.v_d, inp.a_d, kp, kv, c[D_KF],
                                         inp.force_dir, inp.touch, inp.surface_p, inp.surface_v, inp.force_set,
                                         inp.force_rate, inp.force_read, inp.z, env, c[D_TRACKS] != 0.0)
        for i in range(rates.size):
            zdot[i] = rates[i]
        if c[D_SWAP] == 0.0:
            f_swap = np.empty(0)
    else:
        a = position_targets(inp.p_tip, inp.v_tip, inp.x_d, inp.v_d, inp.a_d, kp, kv, c[D_PRESSING] != 0.0,
                             inp.force_dir, inp.touch, inp.surface_p, inp.surface_v, inp.force_set, inp.force_rate,
                             np.ascontiguousarray(env[:, 0]))
        f_swap = np.empty(0)
    J = inp.J
    out = computed_torque.torque(inp.H, np.empty(0), inp.h, inp.tau_contact, J, _pinv_kept(work, ints[W_PINV], J),
                                 inp.drift, inp.v, a, f_swap, c[D_KNULL])
    for i in range(out.size):
        tau[i] = out[i]
    return 1


@njit(cache=True)
def operational_command(x, ints, reals, H, h, J6, a6, p_tip, v_tip, Rf, x_d, v_d, a_d, F_d):
    """τ [N·m or N] of the operational-space law at the packed constants (NaN where the task is singular)."""
    nv, nQ, k, nf = ints[NV], ints[NQ], ints[N_AXES], ints[N_FORCES]
    at = ints[R_CTL]
    axes, forced = section(reals, at, k, 3), section(reals, at + 3 * k, nf, 3)
    o = at + 3 * (k + nf)
    kp, kd = reals[o:o + k], reals[o + k:o + 2 * k]
    o += 2 * k
    tool = ints[HAS_TOOL] != 0
    tool_axis, target = reals[o:o + 3 * ints[HAS_TOOL]], reals[o + 3:o + 3 + 3 * ints[HAS_TOOL]]
    ko, do, k_null, kd_normal = reals[o + 6], reals[o + 7], reals[o + 8], reals[o + 9]
    J_tip = J6 if tool else J6[:3]  # [J; J_ω] and [J̇q̇; J̇_ω q̇] with a tool axis, else the linear rows
    drift_tip = a6 if tool else a6[:3]
    R_tip = Rf if tool else np.empty((0, 3))
    tau, ratio = torque(x[nQ:nQ + nv], H, h, np.ascontiguousarray(J_tip), np.ascontiguousarray(drift_tip), p_tip,
                        v_tip, x_d, v_d, a_d, F_d, R_tip, axes, forced, kp, kd, tool_axis, target, ko, do, k_null,
                        kd_normal)
    if not ratio >= SINGULAR:  # (also NaN) the readable law raises its error there
        tau[:] = np.nan
    return tau


@njit(cache=True)
def _feedforward(ints, h, g):
    """The feedforward torque (h, g(q), or none: size 0)."""
    ff = ints[FEEDFORWARD]
    return h if ff == FF_BIAS else g if ff == FF_GRAVITY else np.empty(0)


@njit(cache=True)
def joint_pd_command(x, ints, reals, h, g, q_d, v_d):
    """τ [N·m or N] of the joint PD law at the packed gains (q_d, q̇_d of size 0 without a reference)."""
    nv, nQ = ints[NV], ints[NQ]
    at = ints[R_CTL]
    return joint_pd_torque(x[:nv], x[nQ:nQ + nv], q_d, v_d, reals[at:at + nv], reals[at + nv:at + 2 * nv],
                           _feedforward(ints, h, g))


@njit(cache=True)
def task_force_command(t, ints, reals, h, g, J6):
    """τ [N·m or N] of the open-loop task force at the packed constants."""
    c = reals[ints[R_CTL]:]
    return task_force_torque(t, np.ascontiguousarray(J6[:3]), c[0:3], c[3:6], c[6], c[7], c[8:11], c[11], c[12:15],
                             c[15] != 0.0, _feedforward(ints, h, g))
