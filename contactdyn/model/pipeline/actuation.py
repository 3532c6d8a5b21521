"""The pipeline's actuation stage over the packed arrays: the phase's reference and set-points, the controller, the
drives.

The reference x_d, v_d, a_d at t [s] (the start plus each move's profile, ``laws.trajectory.move_rows``, as
``Reference.at``), the force set-points F_d [N] (``ramp_rows``); then the controller by its kind: the task PD law
compiled in (``laws.controllers.task_pd_law.torque``, as ``TaskPD.command`` calls it), a sampled law's held
command (the state's slots, ``SampledController.command``), a controller of the controller ABI called by its
address (:mod:`contactdyn.laws.controllers.abi`: its inputs written into one buffer by the layout table packed with
the mode), or constant voltages (``ConstantVoltage``: the drive table takes them). The drives turn the command, the
joints' τ and the servo forces of the bodies, into generalized forces: ideal torque sources add it as it is,
motors by their kinds' laws (:mod:`.drives`).

Under ``NUMBA_DISABLE_JIT=1`` a controller's "address" is a handle of its class (:data:`.pack.PYTHON_CONTROLLERS`)
and :func:`command_by_address` runs its Python ``command`` on the same buffer: the same source, interpreted.
"""

from __future__ import annotations

from collections import namedtuple

import numpy as np
from numba.extending import overload

from ...laws.controllers.abi import (
    FIELD,
    LAYOUT_HEAD,
    LAYOUT_SIZE,
    call_controller,
    command_arrays,
    control_arrays,
    put_field,
)
from ...laws.controllers.task_pd_law import torque
from ...laws.trajectory import CIRCLE_W, add_circle, move_rows, ramp_rows
from ...numerics.compile_cache import njit
from ...numerics.linalg import put
from .control_laws import PYTHON_KINDS, joint_pd_command, task_force_command
from .drives import DI_W, DW_APPLIED, DW_W, apply_drives, command_voltages
from .pack import (
    ANY_MOTOR,
    CARRIER,
    CTL_ADDRESS,
    CTL_CONSTANT,
    CTL_HELD,
    CTL_KIND,
    FEEDFORWARD,
    FF_BIAS,
    FF_GRAVITY,
    HAS_RD,
    HAS_TOOL,
    I_DRIVES,
    I_LAYOUT,
    I_SERVOS,
    N_AXES,
    N_CTL_PARAMS,
    N_DRIVES,
    N_FORCES,
    N_MOVES,
    N_SERVOS,
    N_Z,
    NQ,
    NV,
    PYTHON_CONTROLLERS,
    R_CARRIER,
    R_CIRCLES,
    R_CTL,
    R_DRIVES,
    R_RAMPS,
    R_REF,
    R_SERVOS,
    READS_ORIENTATION,
    REF_DIMS,
    TIP_FRAME,
    W_DRIVES,
    X_HELD,
    Z_AT,
    section,
)

__all__ = ["reference", "set_points", "task_pd_terms", "joint_pd_terms", "task_force_terms", "open_loop_terms",
           "drive_command", "drives", "held_voltages", "command_by_address", "abi_buffer",
           "abi_call"]

#: the controller ABI's fields (its LAYOUT's order)
(F_T, F_Q, F_V, F_H, F_HB, F_GRAVITY, F_P, F_PD, F_J, F_DRIFT, F_XD, F_VD, F_AD, F_Z, F_R, F_JANG, F_DRIFT_ANG) = (
    FIELD[k] for k in ("t", "q", "v", "H", "h", "gravity", "p_tip", "v_tip", "J", "drift", "x_d", "v_d", "a_d", "z",
                       "R_tip", "J_ang", "drift_ang"))


@njit(cache=True)
def reference(t, ints, reals):
    """(x_d, v_d, a_d) at t [s]: the start plus Σ_k (σ_k, σ'_k/T_k, σ''_k/T_k²) Δ_k, a circle's rows its own
    (``laws.trajectory.add_circle``); empty without a reference."""
    dims, n_moves, at = ints[REF_DIMS], ints[N_MOVES], ints[R_REF]
    x_d, v_d, a_d = reals[at:at + dims].copy(), np.zeros(dims), np.zeros(dims)
    if n_moves:
        moves = section(reals, at + dims, n_moves, 4)
        deltas = section(reals, at + dims + 4 * n_moves, n_moves, dims)
        w = np.empty(3 * n_moves)
        move_rows(t, moves, w)
        circles = section(reals, ints[R_CIRCLES], n_moves, CIRCLE_W)
        for k in range(n_moves):
            if circles[k, 0] != 0.0:
                add_circle(t, moves[k], circles[k], x_d, v_d, a_d)
                continue
            for i in range(dims):
                x_d[i] += w[3 * k] * deltas[k, i]
                v_d[i] += w[3 * k + 1] * deltas[k, i]
                a_d[i] += w[3 * k + 2] * deltas[k, i]
    return x_d, v_d, a_d


@njit(cache=True)
def carry(x, ints, reals, x_d, v_d):
    """A reference carried by a body (``[phase.reference] body``, ``model.phases.reference_at``): x_d += axis · Q_b
    [m], v_d += axis · Q̇_b [m/s] in place. Its acceleration axis · Q̈_b is an unknown of the solve, which the
    pipeline folds for a law of the ABI (:func:`.force_fold.controller_terms`: the law at a_d + axis)."""
    i = ints[CARRIER]
    if i < 0 or x_d.size == 0:
        return
    axis = reals[ints[R_CARRIER]:ints[R_CARRIER] + 3]
    for k in range(3):
        x_d[k] = x_d[k] + axis[k] * x[i]
        v_d[k] = v_d[k] + axis[k] * x[ints[NQ] + i]


@njit(cache=True)
def set_points(t, ints, reals):
    """(F_d [N] per set-point, its direction (n, 3), Ḟ_d [N/s]) at t [s], in the phase's order."""
    n = ints[N_FORCES]
    ramps = section(reals, ints[R_RAMPS], n, 5)
    w = np.empty(2 * n)
    ramp_rows(t, ramps, w)
    F_d, rate = np.empty(n), np.empty(n)
    for j in range(n):
        F_d[j], rate[j] = w[2 * j], w[2 * j + 1]
    return F_d, section(reals, ints[R_RAMPS] + 5 * n, n, 3), rate


@njit(cache=True)
def _task_pd(x, ints, reals, h, g, J6, p_tip, v_tip, Rf, x_d, v_d, F_d, forced):
    """τ of the task PD law (TaskPD.command's arguments from the packed constants)."""
    nv, nQ, k = ints[NV], ints[NQ], ints[N_AXES]
    at = ints[R_CTL]
    axes = section(reals, at, k, 3)
    kp, kd = reals[at + 3 * k:at + 4 * k], reals[at + 4 * k:at + 5 * k]
    o = at + 5 * k
    tool, target = reals[o:o + 3 * ints[HAS_TOOL]], reals[o + 3:o + 3 + 3 * ints[HAS_TOOL]]
    R_d = section(reals, o + 6, 3 * ints[HAS_RD], 3)
    ko, do, kd_joint, kd_normal = reals[o + 15], reals[o + 16], reals[o + 17], reals[o + 18]
    orient = ints[READS_ORIENTATION] != 0
    J_ang = J6[3:] if orient else np.empty((0, nv))  # (views of C arrays: no copies)
    R_tip = Rf if orient else np.empty((0, 3))
    ff = ints[FEEDFORWARD]
    tau_ff = h if ff == FF_BIAS else g if ff == FF_GRAVITY else np.empty(0)
    return torque(x[nQ:nQ + nv], J6[:3], J_ang, p_tip, v_tip, x_d, v_d, F_d, R_tip, axes, forced, kp, kd, tool,
                  target, R_d, ko, do, kd_joint, kd_normal, tau_ff)


@njit(cache=True, inline="always")
def abi_buffer(t, x, ints, reals, H, h, g, J6, a6, p_tip, v_tip, Rf, x_d, v_d, a_d):
    """(buffer, layout) of a controller of the ABI: its inputs written where the packed layout table puts them (the
    set-points' fields, the measured forces and what goes with them are :mod:`.force_fold`'s). (Each field's index
    as np.int64: a literal would compile put_field once per field.)"""
    nv, nQ = ints[NV], ints[NQ]
    lay = ints[ints[I_LAYOUT]:ints[I_LAYOUT] + LAYOUT_SIZE]
    buf = np.zeros(lay[lay.size - 1])
    buf[lay[LAYOUT_HEAD + 2 * F_T]] = t
    put_field(buf, lay, np.int64(F_Q), x[:nv])
    put_field(buf, lay, np.int64(F_V), x[nQ:nQ + nv])
    put_field(buf, lay, np.int64(F_H), H.ravel())
    put_field(buf, lay, np.int64(F_HB), h)
    put_field(buf, lay, np.int64(F_GRAVITY), g)
    put_field(buf, lay, np.int64(F_P), p_tip)
    put_field(buf, lay, np.int64(F_PD), v_tip)
    put_field(buf, lay, np.int64(F_J), J6[:3].ravel())
    put_field(buf, lay, np.int64(F_DRIFT), a6[:3])
    put_field(buf, lay, np.int64(F_XD), x_d)
    put_field(buf, lay, np.int64(F_VD), v_d)
    put_field(buf, lay, np.int64(F_AD), a_d)
    put_field(buf, lay, np.int64(F_Z), x[2 * nQ + ints[Z_AT]:2 * nQ + ints[Z_AT] + ints[N_Z]])
    put_field(buf, lay, np.int64(F_R), Rf.ravel())
    put_field(buf, lay, np.int64(F_JANG), J6[3:].ravel())
    put_field(buf, lay, np.int64(F_DRIFT_ANG), a6[3:])
    return buf, lay


@njit(cache=True, inline="always")
def abi_call(ints, reals, buf, lay, tau, zdot):
    """The ABI's call of the packed controller on ``buf``: τ into ``tau``, ż into ``zdot``; its status (1 written)."""
    params = reals[ints[R_CTL]:ints[R_CTL] + ints[N_CTL_PARAMS]]
    return command_by_address(ints[CTL_ADDRESS], buf, lay, params, tau, zdot)


# ---- the controller's kinds compiled in, each a stage of the call (pipeline.stage_addresses): (τ [N·m or N] or
# voltages [V], ż, B, D, b, d) at (t, x), of force_fold.controller_terms' signature -------------------------------
@njit(cache=True)
def _plain(ints, tau):
    """(τ, ż, B, D, b, d) of a law without states, fold or carried column."""
    nv, nz = ints[NV], ints[N_Z]
    return tau, np.zeros(nz), np.zeros((nv, 0)), np.zeros((nz, 0)), np.zeros(nv), np.zeros(nz)


@njit(cache=True)
def task_pd_terms(t, x, ints, reals, work, H, h, g, FJ, Fa, Fp, Fv, FR, f, C, events):
    """The task PD law."""
    fi = ints[TIP_FRAME]
    x_d, v_d, _ = reference(t, ints, reals)
    carry(x, ints, reals, x_d, v_d)
    F_d, forced, _ = set_points(t, ints, reals)
    return _plain(ints, _task_pd(x, ints, reals, h, g, FJ[fi], Fp[fi], Fv[fi], FR[fi], x_d, v_d, F_d, forced))


@njit(cache=True)
def joint_pd_terms(t, x, ints, reals, work, H, h, g, FJ, Fa, Fp, Fv, FR, f, C, events):
    """Joint PD."""
    x_d, v_d, _ = reference(t, ints, reals)
    carry(x, ints, reals, x_d, v_d)
    return _plain(ints, joint_pd_command(x, ints[NQ], reals[ints[R_CTL]:], h, g, x_d, v_d))


@njit(cache=True)
def task_force_terms(t, x, ints, reals, work, H, h, g, FJ, Fa, Fp, Fv, FR, f, C, events):
    """The open-loop task force."""
    return _plain(ints, task_force_command(t, reals[ints[R_CTL]:], h, g, FJ[ints[TIP_FRAME]]))


@njit(cache=True)
def open_loop_terms(t, x, ints, reals, work, H, h, g, FJ, Fa, Fp, Fv, FR, f, C, events):
    """Constant voltages [V], a sampled law's held command, or none (τ = 0)."""
    if ints[CTL_KIND] == CTL_CONSTANT:
        return _plain(ints, reals[ints[R_CTL]:ints[R_CTL] + ints[NV]].copy())
    if ints[CTL_KIND] == CTL_HELD:
        return _plain(ints, x[ints[X_HELD]:ints[X_HELD] + ints[NV]].copy())
    return _plain(ints, np.zeros(ints[NV]))


@njit(cache=True)
def drive_command(x, ints, reals, tau):
    """The command per drive (joints, then bodies): the joints' τ [N·m or N; V], the bodies' servo forces
    g (v_ref − v) [N]."""
    nQ = ints[NQ]
    cmd = np.zeros(ints[N_DRIVES])
    put(cmd, 0, tau)
    servo = reals[ints[R_SERVOS]:]
    for k in range(ints[N_SERVOS]):
        idx = ints[ints[I_SERVOS] + k]
        cmd[idx] = servo[2 * k + 1] * (servo[2 * k] - x[nQ + idx])
    return cmd


@njit(cache=True)
def held_voltages(x, ints, reals, tau):
    """The voltages [V] a torque command tau [N·m or N] asks of the robot joints' motors at the state x
    (:func:`.drives.command_voltages`): what a sampled torque law holds with ``hold = "voltage"``."""
    rows = section(ints, ints[I_DRIVES], ints[N_DRIVES], DI_W)
    return command_voltages(x, ints[NQ], rows, reals[ints[R_DRIVES]:], tau)


@njit(cache=True)
def drives(x, ints, reals, work, cmd, sat, f):
    """The command per drive (:func:`drive_command`) through the drives into f: added as it is by ideal sources only
    (no motor), else by each drive's law (:func:`.drives.apply_drives`, its outputs into
    ``work``; ``sat`` decides the clips): (ok, the forces applied on the drives' coordinates [N·m or N]); ok False
    where a kind's compiled law failed."""
    n = ints[N_DRIVES]
    if ints[ANY_MOTOR]:
        rows = section(ints, ints[I_DRIVES], n, DI_W)
        out = work[ints[W_DRIVES]:]
        ok = apply_drives(x, ints[NQ], rows, reals[ints[R_DRIVES]:], cmd, sat, f, out)
        applied = np.empty(n)
        for i in range(n):
            applied[i] = out[DW_W * i + DW_APPLIED]
        return ok, applied
    for i in range(n):
        f[i] += cmd[i]
    return True, cmd


def command_by_address(address, buffer, layout, params, tau, zdot) -> int:
    """The controller at ``address`` on its buffer (the ABI's call); interpreted, a handle's Python ``command``."""
    kind = PYTHON_KINDS.get(int(address))
    if kind is not None:  # a built-in law on the buffer (control_laws)
        return kind(buffer, layout, params, tau, zdot)
    cls = PYTHON_CONTROLLERS.get(int(address))
    if cls is None:
        return call_controller(address, buffer, layout, params, tau, zdot)
    config = namedtuple("Config", [p.name for p in cls.params])(*params)
    nv, nz = int(layout[0]), int(layout[1])
    out, rates = command_arrays(cls.name, cls.command(namedtuple("Self", ["config", "nv"])(config, nv),
                                                      control_arrays(buffer, layout)), nv, nz)
    tau[:] = out
    if rates is not None:
        zdot[:] = rates
    return 1


@overload(command_by_address, inline="always")
def _command_by_address_compiled(address, buffer, layout, params, tau, zdot):
    def impl(address, buffer, layout, params, tau, zdot):
        return call_controller(address, buffer, layout, params, tau, zdot)
    return impl
