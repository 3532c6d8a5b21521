"""The pipeline's drives: each drive's law by its kind's address, the voltage clip, the rotors reflected on M.

One row per drive (joints, then bodies; :class:`contactdyn.laws.drives.Drives`' order) in ``ints`` (DI_* below)
and a block of ``reals`` per drive: its command gain (``DriveKind.command_gain``), its voltage limit [V] and its
kind's values (``drive_abi.spec_values``: the declared parameters, then the transmission figures).
:func:`drive_table` lays them out (Python, once per mode); :func:`apply_drives` runs them per call (with a
fold, the clips decided at the full command: :func:`.force_fold.solve_through_drives`;
:func:`fold_on_targets` folds through the unclipped drives' gains): a kind with a voltage inverts the command to
a voltage (its ``voltage``, eq. 51 inverted), or takes the controller's voltage as it is; the voltage is clipped
to ±u_max; the kind's ``force`` gives the force on the coordinate and the torque on its motor coordinate (an
elastic drive's θ, whose rate then comes out of the solve with the motor's inertia from ``M_rest``). An ideal
source adds its command. Each drive's applied force [N·m or N], voltage [V] (NaN: none) and clip flag (1.0
clipped), then the drives' power and dissipation [W], are written into ``work`` (DW_* below).

The rotors' inertias reflected through rigid gears go on M's robot block (:func:`inertias`: the true system's
``System._D``) and on the controller's H (the rigid model's ``System._D_ctl``, what a law reads as ``inp.H``).
A kind is called by address (:mod:`contactdyn.laws.drive_abi`), so a user's registered kind costs what a built-in
one costs; one numba cannot compile runs as a declared Python stage, named (:func:`python_drives`).
"""

from __future__ import annotations

import math

import numpy as np

from ...laws.drive_abi import (
    call_drive_force,
    call_drive_voltage,
    drive_addresses,
    python_drive_addresses,
    spec_values,
)
from ...numerics.compile_cache import njit

__all__ = ["drive_table", "python_drives", "apply_drives", "command_voltages", "fold_on_targets", "inertias",
           "drive_values", "DI_W", "DW_W"]

#: a drive's ints: coordinate, motor coordinate (-1: none), its command is a voltage (the controller's), it takes
#: a voltage, its kind's voltage and force addresses (force 0: an ideal source), the count and start of its values
#: (relative to the drives' reals: [command gain, u_max, values...] per drive; the gain: the force on its target
#: coordinate per unit force command below the clip, ``DriveKind.command_gain``, where a fold lands)
DI_COORD, DI_MOTOR, DI_BY_VOLTAGE, DI_HAS_VOLTAGE, DI_VOLTAGE, DI_FORCE, DI_N_P, DI_P, DI_W = range(9)
#: a drive's output in ``work``: applied force [N·m or N], voltage [V] (NaN: none), clipped (1.0) — then, after the
#: drives, the power delivered and dissipated [W]
DW_APPLIED, DW_U, DW_CLIPPED, DW_W = 0, 1, 2, 3


def python_drives(system) -> list[str]:
    """The motorized kinds of ``system``'s drives numba cannot compile, each run in the compiled call as a declared
    Python stage (:func:`contactdyn.laws.drive_abi.python_drive_addresses`), named with numba's reason."""
    drives = system.drives
    return [f"drive kind {spec.law.name!r} of {name} is a Python stage ({spec.law.compiled_reason})"
            for name, spec in zip(drives.names, drives.specs, strict=True)
            if spec.law.motorized and not drive_addresses(spec.law)[1]]


def drive_table(system, phase) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(rows (n, DI_W) int64, the drives' reals, the rotors reflected on the joints: the true system's (nv) then the
    controller's rigid model's (nv) [kg·m²]) of ``system``'s drives in ``phase``."""
    drives = system.drives
    by_voltage = drives.has_voltage & (np.arange(len(drives.specs)) < system.nv) \
        if phase.controller.outputs == "voltage" else np.zeros(len(drives.specs), bool)
    rows, reals = [], []
    for i, spec in enumerate(drives.specs):
        kind = spec.law
        v_addr, f_addr = drive_addresses(kind) if kind.motorized else (0, 0)
        if kind.motorized and not f_addr:  # numba cannot compile it: its declared Python stage
            v_addr, f_addr = python_drive_addresses(spec)
        values = spec_values(spec) if kind.motorized else []
        rows.append((drives.coords[i], drives.motor_coords[i], by_voltage[i], kind.has_voltage, v_addr, f_addr,
                     len(values), len(reals) + 2))
        reals += [float(drives.gains[i]), float(drives.u_max[i]), *values]
    reflected = [*system.rotor_inertias, *system.drives.model_reflected[:system.nv]]
    return np.array(rows, dtype=np.int64).reshape((-1, DI_W)), np.array(reals), np.array(reflected, dtype=float)


@njit(cache=True)
def inertias(H, any_motor, reflected, nv):
    """(M's rigid-body block, the controller's H) [kg·m²]: H with the rotors reflected on the robot's nv joints'
    diagonal (rigid gears), the true system's and the rigid model's; H itself for both without motors."""
    if not any_motor:
        return H, H
    M, Hc = H.copy(), H.copy()
    for i in range(nv):
        M[i, i] += reflected[i]
        Hc[i, i] += reflected[nv + i]
    return M, Hc


@njit(cache=True)
def apply_drives(x, nQ, rows, dreals, cmd, sat, f, out):
    """Each drive's generalized force at its command (cmd: a force per drive [N·m or N], or a voltage [V] where
    its row says so) added to f (and its motor's torque on its motor coordinate); outputs into ``out`` (DW_*).
    ``sat`` decides which voltages clip (the full command of a fold, while ``cmd`` lacks the folded part;
    ``cmd`` itself otherwise). False where a kind's compiled law failed or returned a force that is not finite (a
    NaN voltage, status 0, a NaN force on the coordinate or on its motor coordinate: the call's status then -1,
    Pipeline.failed_call names the kind)."""
    power = lost = 0.0
    o4 = np.empty(4)
    n = rows.shape[0]
    for i in range(n):
        c, m = rows[i, DI_COORD], rows[i, DI_MOTOR]
        qd = x[nQ + c]
        at = DW_W * i
        out[at + DW_CLIPPED] = 0.0
        if rows[i, DI_FORCE] == 0:  # an ideal source: the command acts as it is
            f[c] += cmd[i]
            out[at + DW_APPLIED], out[at + DW_U] = cmd[i], math.nan
            power += cmd[i] * qd
            continue
        theta, omega = (x[m], x[nQ + m]) if m >= 0 else (math.nan, math.nan)
        p_at, n_p = rows[i, DI_P], rows[i, DI_N_P]
        ui = cmd[i]
        if rows[i, DI_HAS_VOLTAGE]:
            us = ui
            if not rows[i, DI_BY_VOLTAGE]:
                ui = drive_voltage(x, nQ, rows, dreals, i, cmd[i])
                us = ui if sat[i] == cmd[i] else drive_voltage(x, nQ, rows, dreals, i, sat[i])
                if math.isnan(ui) or math.isnan(us):
                    return False
            u_max = dreals[p_at - 1]
            if abs(us) > u_max:
                out[at + DW_CLIPPED] = 1.0
                ui = math.copysign(u_max, us)
        if call_drive_force(rows[i, DI_FORCE], dreals, p_at, n_p, ui, x[c], qd, theta, omega, o4) != 1:
            return False
        if not (math.isfinite(o4[0]) and (m < 0 or math.isfinite(o4[1]))):  # (a kind's NaN [N·m or N]: named)
            return False
        f[c] += o4[0]
        if m >= 0:
            f[m] += o4[1]
        out[at + DW_APPLIED], out[at + DW_U] = o4[0], ui if rows[i, DI_HAS_VOLTAGE] else math.nan
        power += o4[2]
        lost += o4[3]
    out[DW_W * n], out[DW_W * n + 1] = power, lost
    return True


@njit(cache=True, inline="always")
def drive_voltage(x, nQ, rows, dreals, i, command):
    """u [V] that drive i's kind asks for the force ``command`` [N·m or N] at the state x (its voltage law: eq. 51
    inverted at its coordinate's and its motor's speeds); NaN where the law failed."""
    m = rows[i, DI_MOTOR]
    omega = x[nQ + m] if m >= 0 else math.nan
    return call_drive_voltage(rows[i, DI_VOLTAGE], dreals, rows[i, DI_P], rows[i, DI_N_P], command,
                              x[nQ + rows[i, DI_COORD]], omega)


@njit(cache=True)
def command_voltages(x, nQ, rows, dreals, tau):
    """u [V] per robot joint (rows 0..nv−1 are the robot's joints): the voltage its drive asks for the force command
    tau[i] [N·m or N] at the state x (:func:`drive_voltage`, as :func:`apply_drives` turns a torque command into a
    voltage). NaN where a kind's law failed."""
    u = np.empty(tau.size)
    for i in range(tau.size):
        u[i] = drive_voltage(x, nQ, rows, dreals, i, tau[i])
    return u


@njit(cache=True)
def fold_on_targets(rows, dreals, out, B, bq, fold, fold_q):
    """A force-reading law's τ = τ₀ + B λ (+ b Q̈_b, a carried reference) through the joints' drives whose voltage
    did not clip (``out``'s flags): gain_i B_i [and gain_i b_i] added on row i's target coordinate, its motor
    coordinate if it owns one (``fold`` (nQ, rows), ``fold_q`` (nQ): :func:`.kkt.kkt_solve`'s). A clipped
    drive's force does not depend on λ."""
    for i in range(B.shape[0]):
        if out[DW_W * i + DW_CLIPPED] != 0.0:
            continue
        c = rows[i, DI_MOTOR] if rows[i, DI_MOTOR] >= 0 else rows[i, DI_COORD]
        gain = dreals[rows[i, DI_P] - 2]
        for j in range(B.shape[1]):
            fold[c, j] += gain * B[i, j]
        fold_q[c] += gain * bq[i]


def drive_values(out: np.ndarray, n: int) -> dict[str, np.ndarray | float]:
    """The drives' outputs of the last call by name: applied [N·m or N], u [V] (NaN: none), clipped (bool) per
    drive; power and dissipation [W]."""
    table = out[:DW_W * n].reshape((n, DW_W))
    return {"applied": table[:, DW_APPLIED].copy(), "u": table[:, DW_U].copy(), "clipped": table[:, DW_CLIPPED] != 0,
            "power": float(out[DW_W * n]), "dissipation": float(out[DW_W * n + 1])}
