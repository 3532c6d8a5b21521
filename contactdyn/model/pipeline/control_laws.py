"""Built-in controllers of the pipeline: operational space and the dynamic laws by address, joint PD and task force
compiled in.

``operational_space`` and the task-space dynamic laws (A7, A10, hybrid) read their own config (tables made at
bind time from the phase, not declared float parameters), so they cannot be compiled from their ``command`` as a
user's law is. They are written here once more as a law of the controller ABI's shape, over its buffer, calling
the very compiled functions their readable ``command`` calls (no copy of their arithmetic):
:func:`contactdyn.laws.controllers.operational_law.torque`; the tip targets of
:mod:`contactdyn.laws.controllers.dynamic_law` and :func:`~contactdyn.laws.controllers.computed_torque.torque`.
Each is a C function of the ABI's signature, compiled at its first use and cached (:func:`kind_address`), its
constants the call's ``params``: the pipeline calls it by address as it calls a user's law, and folds it the same
way (:mod:`.force_fold`); a scene that does not use it does not compile it. A singular operational task (the
Hadamard ratio below ``SINGULAR``, or NaN) returns status 0: its command is not finite and the call raises the law's
own error there (``OperationalSpace.failure``, :meth:`~contactdyn.model.pipeline.pipeline.Pipeline.failed_call`).

Operational space's constants (:data:`O_AXES` …): k, a tool axis (1.0 / 0.0), axes (k × 3), force directions (ns × 3,
the phase's set-points in its order, as the buffer's F_d: pack orders them by key), kp (k) [N/m], kd (k) [N·s/m],
tool axis (3), tool target (3), ko [1/s²], do [1/s], k_null [1/s], kd_normal [N·s/m]. A dynamic law's (``D_*``):
switches (A10 or hybrid, tracks position, swaps F* into τ, presses its reference), K_F [1/s], k_null [1/s], K_p
[1/s²] and K_v [1/s] (3 each), P (9), then per set-point the nominal k [N/m], b [N·s/m], m [kg], then (inertia =
"link") per joint the rotor inertia taken out of H [kg·m²] (none: H as it is). A7 in joint space is a kind of its own
(:data:`JOINT_DYNAMIC`, :func:`joint_dynamic_on_buffer`:
:func:`~contactdyn.laws.controllers.dynamic_law.joint_targets` and
:func:`~contactdyn.laws.controllers.computed_torque.joint_torque`, as its readable ``command``), its buffer's
reference the joints' (the ABI's x_d of nv coordinates).

``joint_pd`` (:func:`~contactdyn.laws.controllers.pd.joint_pd_torque`) and ``task_force``
(:func:`~contactdyn.laws.controllers.force.task_force_torque`) are small: compiled into the call as kinds.
"""

from __future__ import annotations

import numpy as np
from numba import carray

from ...laws.controllers import computed_torque
from ...laws.controllers.abi import CONTROLLER_SIGNATURE, LAYOUT_SIZE, control_arrays
from ...laws.controllers.dynamic_law import force_targets, joint_targets, position_targets
from ...laws.controllers.force import task_force_torque
from ...laws.controllers.operational_law import SINGULAR, torque
from ...laws.controllers.pd import joint_pd_torque
from ...numerics.compile_cache import cfunc, njit
from ...numerics.linalg import pinv
from ...numerics.native_call import handles

__all__ = ["kind_address", "operational_on_buffer", "dynamic_on_buffer", "joint_dynamic_on_buffer", "joint_pd_command",
           "task_force_command", "O_K", "D_FORCE_LAW", "JOINT_DYNAMIC"]

O_K, O_TOOL, O_AXES = 0, 1, 2  #: operational space's constants: k, a tool axis, then the tables from O_AXES
D_FORCE_LAW, D_TRACKS, D_SWAP, D_PRESSING, D_KF, D_KNULL, D_KP, D_KV, D_P, D_ENV = 0, 1, 2, 3, 4, 5, 6, 9, 12, 21
FF_NONE, FF_GRAVITY, FF_BIAS = 0.0, 1.0, 2.0  #: joint PD's and task force's feedforward (their first constant)


@njit(cache=True, inline="always")
def operational_on_buffer(buf, lay, c, tau, zdot):
    """Operational space's τ [N·m or N] from the ABI's buffer at constants ``c``; status 0: the task is singular."""
    inp = control_arrays(buf, lay)
    nv, k, ns = lay[0], int(c[O_K]), lay[2]
    tool = c[O_TOOL] != 0.0
    axes, forced = c[O_AXES:O_AXES + 3 * k].reshape((k, 3)), c[O_AXES + 3 * k:O_AXES + 3 * (k + ns)].reshape((ns, 3))
    o = O_AXES + 3 * (k + ns)
    kp, kd = c[o:o + k], c[o + k:o + 2 * k]
    o += 2 * k
    n_tool = 3 if tool else 0
    tool_axis, target = c[o:o + n_tool], c[o + 3:o + 3 + n_tool]
    J_tip, drift_tip = np.empty((3 + n_tool, nv)), np.empty(3 + n_tool)  # [J; J_ω], [J̇q̇; J̇_ω q̇] with a tool
    for r in range(3):  # (element by element: a slice assignment compiles numba's broadcast and its checks)
        drift_tip[r] = inp.drift[r]
        for j in range(nv):
            J_tip[r, j] = inp.J[r, j]
    for r in range(n_tool):
        drift_tip[3 + r] = inp.drift_ang[r]
        for j in range(nv):
            J_tip[3 + r, j] = inp.J_ang[r, j]
    R_tip = inp.R_tip if tool else np.empty((0, 3))
    out, ratio = torque(inp.v, inp.H, inp.h, J_tip, drift_tip, inp.p_tip, inp.v_tip, inp.x_d, inp.v_d, inp.a_d,
                        inp.force_set, R_tip, axes, forced, kp, kd, tool_axis, target, c[o + 6], c[o + 7], c[o + 8],
                        c[o + 9])
    if not ratio >= SINGULAR:  # (also NaN) the call raises the law's error there (Pipeline.failed_call)
        return 0
    for i in range(nv):
        tau[i] = out[i]
    return 1


@njit(cache=True, inline="always")
def dynamic_on_buffer(buf, lay, c, tau, zdot):
    """A dynamic law's τ = H q̈*(a*) + h − τ_c (+ Jᵀ f_swap) [N·m or N] around its tip targets, and ż, from the ABI's
    buffer at constants ``c`` (D_*); status 1."""
    inp = control_arrays(buf, lay)
    ns = lay[2]
    kp, kv, P = c[D_KP:D_KP + 3], c[D_KV:D_KV + 3], c[D_P:D_P + 9].reshape((3, 3))
    env = c[D_ENV:D_ENV + 3 * ns].reshape((ns, 3))
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
    rotor = np.ascontiguousarray(c[D_ENV + 3 * ns:])  # the rotors taken out of H [kg·m²] (inertia = "link") or none
    out = computed_torque.torque(inp.H, rotor, inp.h, inp.tau_contact, J, pinv(J), inp.drift, inp.v, a,
                                 f_swap, c[D_KNULL])
    for i in range(out.size):
        tau[i] = out[i]
    return 1


@njit(cache=True, inline="always")
def joint_dynamic_on_buffer(buf, lay, c, tau, zdot):
    """A7 in joint space, τ = H q̈* − r ∘ q̈* + h − τ_c [N·m or N], from the ABI's buffer (its x_d, v_d, a_d the
    joint reference's, nv each, or empty) at constants c = [K_p (nv) [1/s²], K_v (nv) [1/s], the rotors taken out of
    H (nv, inertia = "link"; none: H as it is) [kg·m²]]; status 1."""
    inp = control_arrays(buf, lay)
    nv = lay[0]
    qdd = joint_targets(inp.q, inp.v, inp.x_d, inp.v_d, inp.a_d, c[:nv], c[nv:2 * nv])
    out = computed_torque.joint_torque(inp.H, np.ascontiguousarray(c[2 * nv:]), inp.h, inp.tau_contact, qdd)
    for i in range(nv):
        tau[i] = out[i]
    return 1


# ---- the C functions (closure-free module functions: numba caches them beside this file) -------------------------
def _operational_abi(buffer, layout, params, n_p, tau, zdot):
    lay = carray(layout, (LAYOUT_SIZE,))
    return operational_on_buffer(carray(buffer, (lay[LAYOUT_SIZE - 1],)), lay, carray(params, (n_p,)),
                                 carray(tau, (lay[0],)), carray(zdot, (lay[1],)))


def _dynamic_abi(buffer, layout, params, n_p, tau, zdot):
    lay = carray(layout, (LAYOUT_SIZE,))
    return dynamic_on_buffer(carray(buffer, (lay[LAYOUT_SIZE - 1],)), lay, carray(params, (n_p,)),
                             carray(tau, (lay[0],)), carray(zdot, (lay[1],)))


def _joint_dynamic_abi(buffer, layout, params, n_p, tau, zdot):
    lay = carray(layout, (LAYOUT_SIZE,))
    return joint_dynamic_on_buffer(carray(buffer, (lay[LAYOUT_SIZE - 1],)), lay, carray(params, (n_p,)),
                                   carray(tau, (lay[0],)), carray(zdot, (lay[1],)))


JOINT_DYNAMIC = "position_dynamic_joint"  #: the kind of A7 in joint space (position_dynamic with space = "joint")
_KINDS = {"operational_space": (_operational_abi, operational_on_buffer),
          **{name: (_dynamic_abi, dynamic_on_buffer) for name in ("position_dynamic", "force_dynamic", "hybrid")},
          JOINT_DYNAMIC: (_joint_dynamic_abi, joint_dynamic_on_buffer)}
_compiled: dict[str, tuple[int, object]] = {}  #: kind -> (address, its cfunc, kept alive)
#: handle -> the kind's function on the buffer (interpreted, NUMBA_DISABLE_JIT: the address's twin)
PYTHON_KINDS: dict[int, object] = {}


def kind_address(name: str) -> int:
    """The address of built-in controller ``name``'s C function (compiled at its first use); interpreted, a handle
    of its Python function in :data:`PYTHON_KINDS`."""
    wrapper, on_buffer = _KINDS[name]
    if handles():
        PYTHON_KINDS[id(on_buffer)] = on_buffer
        return id(on_buffer)
    if name not in _compiled:
        fn = cfunc(CONTROLLER_SIGNATURE, cache=True)(wrapper)
        _compiled[name] = (fn.address, fn)
    return _compiled[name][0]


# ---- compiled into the call ---------------------------------------------------------------------------------------
@njit(cache=True)
def _feedforward(code, h, g):
    """The feedforward torque (h, g(q), or none: size 0)."""
    return h if code == FF_BIAS else g if code == FF_GRAVITY else np.empty(0)


@njit(cache=True)
def joint_pd_command(x, nQ, c, h, g, q_d, v_d):
    """τ [N·m or N] of the joint PD law at constants c = [feedforward, K_p (nv), K_d (nv)] (q_d, q̇_d of size 0
    without a reference)."""
    nv = h.size
    return joint_pd_torque(x[:nv], x[nQ:nQ + nv], q_d, v_d, c[1:1 + nv], c[1 + nv:1 + 2 * nv], _feedforward(c[0], h, g))


@njit(cache=True)
def task_force_command(t, c, h, g, J6):
    """τ [N·m or N] of the open-loop task force at constants c = [feedforward, force (3), rate (3), start, ramp_time,
    amplitude (3), frequency, phase (3), oscillates]."""
    return task_force_torque(t, np.ascontiguousarray(J6[:3]), c[1:4], c[4:7], c[7], c[8], c[9:12], c[12], c[13:16],
                             c[16] != 0.0, _feedforward(c[0], h, g))
