"""Built-in controllers compiled into the pipeline as kinds: the operational-space law.

``operational_space`` (:mod:`contactdyn.laws.controllers.operational`) reads its own config (its position axes come
from the phase's force directions at bind time, variable-size tables, not declared float parameters), so it is a
kind of the call, as ``task_pd`` is: its constants (``OperationalSpace.constants``) packed in ``reals``, its
arithmetic :func:`contactdyn.laws.controllers.operational_law.torque`, the very function its readable ``command``
calls. A task singular at the state (the Hadamard ratio below ``SINGULAR``, or NaN) gives τ = NaN: the KKT solve
then fails its residual test (status 0) and the readable model answers, where ``OperationalSpace._guard`` raises
its error.

Packed constants (from ``R_CTL``): axes (k × 3), force directions (nf × 3), kp (k) [N/m], kd (k) [N·s/m], tool axis
(3), tool target (3), ko [1/s²], do [1/s], k_null [1/s], kd_normal [N·s/m]; k = ``N_AXES``, nf = ``N_FORCES`` (the
phase's set-points, in the order of ``OperationalSpace.force_keys``), a tool axis iff ``HAS_TOOL``.
"""

from __future__ import annotations

import numpy as np

from ...laws.controllers.operational_law import SINGULAR, torque
from ...numerics.compile_cache import njit
from .pack import HAS_TOOL, N_AXES, N_FORCES, NQ, NV, R_CTL, section

__all__ = ["operational_constants", "operational_command"]


def operational_constants(ctl) -> list[float]:
    """The packed constants of a bound ``OperationalSpace`` (its ``constants``, the tool's as zeros without one)."""
    axes, forced, kp, kd, tool_axis, target, ko, do, k_null, kd_normal = ctl.constants
    tool = (tool_axis, target) if tool_axis.size else (np.zeros(3), np.zeros(3))
    return [*axes.ravel(), *forced.ravel(), *kp, *kd, *tool[0], *tool[1], ko, do, k_null, kd_normal]


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
