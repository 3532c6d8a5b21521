"""A compiled plan's output: the Result channels' values at many states at once.

The integrator needs only derivatives; a Result needs, at every output sample, the
forces, torques, gaps, slip velocities and stage deformations. :func:`plan_samples`
computes them for all samples of a segment together: φ per sample (the call's own,
``plan.phi_at``), then the map P φ, the friction terms, the KKT solves and the read-out as
array operations, or, where the plan has a compiled kernel, its call per sample. Through motors, the drives' forces and
voltages come from the plan's drive matrix (:mod:`contactdyn.compiled.plan_drives`; the law itself
at samples where a voltage clips); a plan folding measured forces or a carried reference
into its solve takes each sample through that fold. :class:`Samples` holds the result (and
is filled from :class:`~contactdyn.model.dynamics.Evaluation` objects where a mode runs on
``System.evaluate``).
"""

from __future__ import annotations

import numpy as np

from ..model.friction import launching
from ..model.phases import reference_positions
from ..numerics.linalg import solve_vector
from .plan_fold import contact_torque_of

__all__ = ["Samples", "plan_samples", "plan_derivatives", "evaluated_samples", "slip_directions"]

#: rows per matrix product in the output pass, small enough to keep OpenBLAS on one thread: with 128,
#: a 4-contact B1's (2001×48)·(48×232) took a median 231 ms on the busy machine (min 0.9 ms), with 16 1.2 ms
ROW_CHUNK = 16


def _rows_times(X: np.ndarray, B: np.ndarray) -> np.ndarray:
    """X @ B in chunks of rows: a multi-threaded BLAS product of this size costs more than it saves
    (and much more on a busy machine)."""
    out = np.empty((X.shape[0], B.shape[1]))
    for i in range(0, X.shape[0], ROW_CHUNK):
        np.matmul(X[i:i + ROW_CHUNK], B, out=out[i:i + ROW_CHUNK])
    return out


class Samples:
    """Per-sample diagnostics of one segment, as arrays (what Result channels are made of)."""

    def __init__(self, n: int, system):
        nv, nb = system.nv, len(system.body_names)
        self.tau = np.zeros((n, nv))  #: the drives' applied joint torques [N·m or N]
        self.tau_cmd = np.zeros((n, nv))  #: the controller's command [N·m or N; V for voltage controllers]
        self.u = np.full((n, len(system.drives.specs)), np.nan)  #: voltage per drive [V], NaN for ideal drives
        self.limit_torque = np.zeros((n, nv))  #: per joint [N·m or N], 0 unless pressing on a limit
        self.joint_friction = np.zeros((n, nv))  #: per joint: damping and dry friction [N·m or N]
        self.tip = np.zeros((n, 3))
        self.x_d = np.full((n, 3), np.nan)
        self.has_x_d = False
        self.body_force = np.zeros((n, nb))
        self.F_n = {c.name: np.zeros(n) for c in system.contacts}
        self.gap = {c.name: np.zeros(n) for c in system.contacts}
        self.F_d = {key: np.full(n, np.nan) for key in system.force_directions}  #: per set-point key
        self.has_F_d = {key: False for key in system.force_directions}
        self.F_f = {c.name: np.zeros((n, len(c.tangents))) for c in system.contacts}
        self.v_slip = {c.name: np.zeros((n, len(c.tangents))) for c in system.contacts}
        self.iface = {f"{c.name}.{dc.label}": np.zeros(n) for c in system.contacts for dc in c.tangent_chains}
        self.stages = {label: np.zeros((n, 3)) for label in system.stage_labels}

    @classmethod
    def concatenate(cls, parts: list[Samples], system) -> Samples:
        if len(parts) == 1:
            return parts[0]
        out = cls(0, system)
        for name in ("tau", "tau_cmd", "u", "limit_torque", "joint_friction", "tip", "x_d", "body_force"):
            setattr(out, name, np.concatenate([getattr(p, name) for p in parts]))
        out.has_x_d = any(p.has_x_d for p in parts)
        out.has_F_d = {key: any(p.has_F_d[key] for p in parts) for key in out.has_F_d}
        for name in ("F_n", "gap", "F_d", "F_f", "v_slip", "iface", "stages"):
            d = getattr(out, name)
            for key in d:
                d[key] = np.concatenate([getattr(p, name)[key] for p in parts])
        return out

    def fill(self, k: int, ev) -> None:
        """Row k from a full :class:`~contactdyn.model.dynamics.Evaluation`."""
        self.tau[k] = ev.tau
        self.tau_cmd[k] = ev.tau_cmd
        self.u[k] = ev.u
        for i, value in ev.limit_torque.items():
            self.limit_torque[k, i] = value
        if ev.joint_friction is not None:
            self.joint_friction[k] = ev.joint_friction
        self.tip[k] = ev.p_tip
        if ev.x_d is not None and len(ev.x_d) == 3:
            self.x_d[k] = ev.x_d
            self.has_x_d = True
        self.body_force[k] = ev.body_force
        for key, value in ev.force_d.items():
            self.F_d[key][k] = value
            self.has_F_d[key] = True
        for name in self.F_n:
            self.F_n[name][k] = ev.normal_force[name]
            self.gap[name][k] = ev.gap[name]
            if name in ev.friction:
                self.F_f[name][k] = ev.friction[name]
            if name in ev.slip:
                self.v_slip[name][k] = ev.slip[name]
        for key in self.iface:
            self.iface[key][k] = ev.interface.get(key, 0.0)
        for label in self.stages:
            self.stages[label][k] = ev.stages.get(label, (0.0, 0.0, 0.0))


def evaluated_samples(system, ts: np.ndarray, X: np.ndarray, modes, phase) -> Samples:
    """Samples at the states X[k] (times ts[k]), each sample by :meth:`System.evaluate`."""
    S = Samples(len(ts), system)
    for k, (t, x) in enumerate(zip(ts, X, strict=True)):
        S.fill(k, system.evaluate(t, x, modes, phase, full=True))
    return S


def plan_samples(plan, ts: np.ndarray, X: np.ndarray) -> Samples:
    """Diagnostics at the states X[k] (times ts[k]) of this mode: φ per sample, then the assembly, solve and
    read-out for all samples at once (or the compiled kernel's call per sample)."""
    N = len(ts)
    if plan.drives_per_call and plan.launch is not None:  # a slide from rest under motors: the readable model
        return evaluated_samples(plan.system, ts, X, plan.modes, plan.phase)
    S = Samples(N, plan.system)
    if N == 0:
        return S
    solved = _kernel_samples(plan, ts, X) if plan.kernel is not None else None
    if solved is None:
        folds = getattr(plan, "folded_detail", None) is not None  # the call folds the command into its solve
        solved = (_solve_folded_samples if folds else _solve_samples)(plan, ts, X)
    _read_out(plan, S, ts, X, *solved)
    return S


def _kernel_samples(plan, ts: np.ndarray, X: np.ndarray):
    """As :func:`_solve_samples`, by the plan's compiled call per sample (:mod:`contactdyn.compiled.plan_kernel`,
    :mod:`contactdyn.compiled.plan_operational`); None where a sample's call declines (a clipping voltage, a slide from
    rest inside the stick band: the batched paths then, with the readable law there)."""
    got = plan.kernel.samples(ts, X)
    if got is None:
        return None
    Phi, O, Z, tau = got
    nv = plan.system.nv
    J_all = [Phi[:, i:i + 3 * nv].reshape(len(ts), 3, nv) for i in plan.i_J]
    drives = plan.compiled_drives
    return Phi, O, Z, J_all, tau, {}, None if drives is None else _drive_samples(drives, X, tau)


def plan_derivatives(plan):
    """f(ts, X) -> Ẋ (N, n): the plan's right-hand side at many states at once (φ, the solves and the
    read-out as in :func:`plan_samples`), for the extra stages of the dense output's interpolants
    (:meth:`~contactdyn.numerics.dop853.DenseSolution.__call__`), bitwise the call's: the compiled call itself where the
    plan has one, else P φ made per state as the call
    makes it (``exact``), the rest elementwise or the same LAPACK solve. None where the
    samples' arithmetic is not the call's: a slide launching from rest, a fold, a controller called per
    call, drives (a clipping sample takes the readable law, equal only to 1e-10), 2-D sliding (its
    directions and tilt are computed over samples in another order)."""
    compiled = getattr(plan.rhs, "derivatives", None)  # the plan's compiled call itself (compiled.plan_steps)
    if compiled is not None:
        return compiled
    two_d = plan.dyn_tilt or any(dT is None for *_, dT, _ in plan.coulomb_terms)
    if plan.launch is not None or getattr(plan, "folded_detail", None) is not None or not plan.affine_ctl \
            or plan.compiled_drives is not None or two_d:
        return None
    s = plan.system
    nQ, n = s.nQ, s.n
    rates, modes = plan.impulse_rates, plan.modes

    def derivatives(ts: np.ndarray, X: np.ndarray) -> np.ndarray:
        _, O, Z, _, _, _, _ = _solve_samples(plan, ts, X, exact=True)
        Xd = np.empty((len(ts), n))
        Xd[:, :nQ] = X[:, nQ:2 * nQ]
        Xd[:, nQ:2 * nQ] = Z[:, :nQ]
        if n > 2 * nQ:
            Xd[:, 2 * nQ:] = O[:, plan.o_y]
            for xd, z, o in zip(Xd, Z, O, strict=True):
                rates(xd, z, o, modes, None)
        return Xd

    return derivatives


def _jacobians(plan, phi: np.ndarray) -> list[np.ndarray]:
    """The plan's frame Jacobians J_f (3, nv) as views of one sample's φ."""
    nv = plan.system.nv
    return [phi[i:i + 3 * nv].reshape(3, nv) for i in plan.i_J]


def _solve_folded_samples(plan, ts: np.ndarray, X: np.ndarray):
    """As :func:`_solve_samples` for a plan folding measured forces or a carried reference into its solve: each
    sample's command and its parts per unit row force from the plan's fold (compiled.plan_fold.folded_solve),
    then the fold through the drives and the solve for all those samples at once (:func:`_fold_all`); a sample
    whose command reads a carried body or a ControlInput, or whose solved command clips a voltage, through the
    plan's own fold. The drives' forces and voltages at the solved commands over all samples at once."""
    s = plan.system
    N, nv, m = len(ts), s.nv, plan.m
    m2 = m * m
    Phi = np.empty((N, plan.P.shape[1]))
    Y = np.empty((N, plan.P.shape[0]))
    Z = np.empty((N, m))
    tau = np.empty((N, nv))
    B = np.empty((N, nv, plan.nr))
    tau_b = np.zeros((N, nv))  # per unit acceleration of the body carrying the reference [N·m or N per m/s²]
    carries = np.zeros(N, bool)
    friction, parts, detail = plan.friction_terms, plan.folded_parts, plan.folded_detail
    contact_torque = contact_torque_of(plan)
    T_c = np.empty((N, nv))  # the contacts' torque [N·m or N]
    batched = np.zeros(N, bool)
    parts_all = getattr(plan, "folded_parts_all", None)  # the law's command over all samples at once

    def one(k):  # the sample's parts (Pinocchio's data at its φ)
        t, x, phi, y = ts[k], X[k], Phi[k], Y[k]
        Js = _jacobians(plan, phi)
        A, b, o = y[:m2].reshape(m, m), y[m2:m2 + m], y[m2 + m:]
        tau[k], _, B[k], _, carried, readable = parts(t, x, Js, phi, o, A, T_c[k])
        batched[k] = readable is None
        if carried is not None:
            carries[k], tau_b[k] = True, carried[1]
        if not batched[k]:
            Z[k], _, tau[k] = detail(t, x, Js, phi, o, A, b)

    for k in range(N):
        Phi[k] = plan.phi_at(ts[k], X[k])
        phi, y = Phi[k], Y[k]  # (views: the sample's rows)
        Js = _jacobians(plan, phi)
        np.dot(plan.P, phi, out=y)
        if friction is not None:
            friction(y, Js, plan.modes)
        T_c[k] = contact_torque(y[m2:m2 + m], Js)
        if parts_all is None:
            one(k)
    if parts_all is not None:
        got = parts_all(ts, X, Phi, Y[:, m2 + m:], Y[:, :m2].reshape(N, m, m), T_c)
        if got is not None:
            tau[:], B[:] = got
            batched[:] = True
        else:  # the law's matrix not read yet: per sample, Pinocchio's data at each
            for k in range(N):
                plan.phi_at(ts[k], X[k])
                one(k)
    K = np.flatnonzero(batched)
    if len(K):
        A_all, b_all = Y[K, :m2].reshape(-1, m, m), Y[K, m2:m2 + m]
        Z[K], tau[K], clipped = _fold_all(plan, X[K], A_all, b_all, tau[K], B[K], tau_b[K], carries[K])
        for k in K[clipped]:  # the readable model, from the sample's unfolded system (and Pinocchio's data at it)
            phi = plan.phi_at(ts[k], X[k])
            Js = _jacobians(plan, phi)
            A, b = Y[k, :m2].reshape(m, m), Y[k, m2:m2 + m]
            Z[k], _, tau[k] = detail(ts[k], X[k], Js, phi, Y[k, m2 + m:], A, b)
    J_all = [Phi[:, i:i + 3 * nv].reshape(N, 3, nv) for i in plan.i_J]
    return Phi, Y[:, m2 + m:], Z, J_all, tau, {}, _drive_samples(plan.compiled_drives, X, tau)


def _fold_all(plan, X: np.ndarray, A: np.ndarray, b: np.ndarray, tau: np.ndarray, B: np.ndarray,
              tau_b: np.ndarray, carries: np.ndarray):
    """(z, the solved joint commands τ [N·m or N; V], the samples whose solved command clips a voltage) of the
    fold (:func:`~contactdyn.compiled.plan_fold._matrix_fold`) over samples: the λ-free commands τ through the drives
    into b, their parts per unit row force B (N, nv, nr) through L_τ into A's columns of λ, and where a sample
    ``carries`` a reference, its part per unit acceleration of the carrying body τ_b through L_τ into that
    body's column, one stacked solve."""
    drives = plan.compiled_drives
    nQ, nr = plan.system.nQ, plan.nr
    lam_cols = slice(nQ, nQ + nr)
    y0 = _rows_times(np.hstack((tau, X, np.ones((len(X), 1)))), drives.L.T)  # L [τ, x, 1]
    YB = np.matmul(drives.L_tau, B)  # the drives' forces (and limited voltages) per unit row force
    A2, b2 = A.copy(), b.copy()  # (the clipped samples' readable model needs A and b as they are)
    A2[:, :nQ, lam_cols] -= YB[:, :nQ]
    b2[:, :nQ] += y0[:, :nQ]
    if carries.any():
        i_b = plan.phase.carrier[0]
        Y_b = _rows_times(tau_b, drives.L_tau.T)
        A2[carries, :nQ, i_b] -= Y_b[carries, :nQ]
    with np.errstate(all="ignore"):
        Z = solve_vector(A2, b2)
    for k in np.flatnonzero(~np.all(np.isfinite(Z), axis=1)):
        Z[k] = plan._singular(A2[k], b2[k])
    lam = Z[:, lam_cols]
    clipped = np.zeros(len(X), bool)
    if drives.limited:  # the voltages at the solved commands
        u = y0[:, nQ:] + np.einsum("kir,kr->ki", YB[:, nQ:], lam)
        if carries.any():
            u[carries] += Y_b[carries, nQ:] * Z[carries, i_b, None]
        clipped = np.abs(u).max(axis=1) > 1.0
    tau = tau + np.einsum("kvr,kr->kv", B, lam)
    if carries.any():
        tau[carries] += tau_b[carries] * Z[carries, i_b, None]
    return Z, tau, clipped


def _generic_command(plan):
    """command(t, x, Js, φ) -> τ [N·m or N; V]: the controller's command at one sample, reading what the plan's
    call gives it (a force-reading law without rows: the contacts' torque after the call's sliding friction)."""
    s = plan.system
    nQ, nv, m = s.nQ, s.nv, plan.m
    m2 = m * m
    ctl_call = plan._controller_call()
    contact_torque = contact_torque_of(plan) if plan.phase.controller.uses_forces else None
    friction = plan.friction_terms

    def command(t, x, Js, phi):
        if contact_torque is None:
            o, tau_c = plan.W.dot(phi[plan.i_e:]), None
        else:
            y = plan.P.dot(phi)
            if friction is not None:
                friction(y, Js, plan.modes)
            o, tau_c = y[m2 + m:], contact_torque(y[m2:m2 + m], Js)
        return ctl_call(t, x, x[:nv], x[nQ:nQ + nv], Js, phi, o, tau_c)[0]

    return command


def _solve_samples(plan, ts: np.ndarray, X: np.ndarray, exact: bool = False):
    """φ, the outputs o and the solution z at every sample, all at once: (Φ, O, Z, Jacobians, τ of a generic law).

    ``exact``: the product the call makes row by row (P φ) made so here too, for values bitwise those of the
    call where the rest is elementwise (:func:`plan_derivatives`; φ is the call's own, ``plan.phi_at``)."""
    s = plan.system
    N = len(ts)
    nQ, nv, nr, m = s.nQ, s.nv, plan.nr, plan.m
    m2 = m * m
    Phi = np.empty((N, plan.P.shape[1]))
    held = plan.held is not None  # a sampled law's held command: in the state, and (without drives) in P φ
    generic = not plan.affine_ctl and not held
    tau = X[:, plan.held].copy() if held else np.zeros((N, nv))
    if generic:
        command = _generic_command(plan)
    phi_at = plan.phi_at  # (the call's own φ: as cheap per sample as a batched one)
    for k in range(N):
        Phi[k] = phi = phi_at(ts[k], X[k])
        if generic:  # (Pinocchio's data at this sample: the controller reads it)
            tau[k] = command(ts[k], X[k], _jacobians(plan, phi), phi)
    Y = np.array([plan.P.dot(phi) for phi in Phi]).reshape(N, -1) if exact else _rows_times(Phi, plan.PT)
    A = Y[:, :m2].reshape(N, m, m)
    B = Y[:, m2:m2 + m]
    O = Y[:, m2 + m:]
    J_all = [Phi[:, i:i + 3 * nv].reshape(N, 3, nv) for i in plan.i_J]
    w0 = nQ + nr
    refs = _launch_references(plan, ts, X, O) if plan.launch is not None else {}
    for ci, i_fn, _, T, consts, j in plan.coulomb_terms:
        mu = _coefficients(plan, ci, O)
        Fp = np.maximum(O[:, i_fn], 0.0)
        D = slip_directions(plan, ci, O, refs.get(ci))
        B[:, w0 + 3 * j:w0 + 3 * j + 3] -= (mu * Fp)[:, None] * (D @ T)
        if nQ > nv:
            B[:, nv:nQ] -= (mu * Fp)[:, None] * (D @ consts)
    for r, ci, _, T, consts, j in plan.dyn_tilt:
        D = slip_directions(plan, ci, O, refs.get(ci))
        mu = _coefficients(plan, ci, O)[:, None]
        A[:, :nv, nQ + r] += mu * np.einsum("kiv,ki->kv", J_all[j], D @ T)
        A[:, nv:nQ, nQ + r] = plan.A0[nv:nQ, nQ + r] + mu * (D @ consts)
    drives = plan.compiled_drives
    if drives is None:
        if not held:
            B[:, :nv] += tau
        drive_out = None
    else:  # the command through the drives: their matrix, the law itself where a voltage clips
        if plan.affine_ctl:
            tau = _task_torque(plan, Phi, O, J_all, X)
        drive_out = _drive_samples(drives, X, tau)
        B[:, :nQ] += drive_out[0]
    Z = _solve_all(plan, A, B)
    return Phi, O, Z, J_all, tau, refs, drive_out


def _drive_samples(drives, X: np.ndarray, tau: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(the drives' generalized forces (N, nQ) [N·m or N], the voltages per drive (N, n_drives) [V]) at the
    commands τ: [f; u/u_max] = L [τ, x, 1] and u = V [τ, x, 1], the readable law at the samples where one clips."""
    nQ = drives.nQ
    E = np.hstack((tau, X, np.ones((len(X), 1))))
    Y = _rows_times(E, drives.L.T)
    F = Y[:, :nQ]
    with_voltage = drives.system.drives.has_voltage
    U = np.full((len(X), len(with_voltage)), np.nan)
    U[:, with_voltage] = _rows_times(E, drives.V.T)
    clipped = np.flatnonzero(np.abs(Y[:, nQ:]).max(axis=1) > 1.0) if drives.limited else ()
    for k in clipped:
        F[k], out = drives.output(X[k], tau[k])
        U[k] = out.u
    return F, U


def _launch_references(plan, ts: np.ndarray, X: np.ndarray, O: np.ndarray) -> dict[int, np.ndarray]:
    """Per launching contact, the reference r of each sample (O: the samples' outputs): the direction its
    slide from rest takes (the plan's own per-call launch, :func:`~contactdyn.compiled.plan_rhs.make_rhs`) where the
    slip is still inside the stick band, the mode's r where it has left it (there the slip's own direction
    rules anyway)."""
    s = plan.system
    out = {}
    inside = np.zeros(len(ts), bool)
    for ci, mode in enumerate(plan.modes):
        if launching(mode):
            r = np.asarray(mode.slip, float)
            out[ci] = np.tile(r, (len(ts), 1))
            inside |= O[:, plan.o_vt[s.contacts[ci].name]] @ r <= s.slip_band
    for k in np.flatnonzero(inside):
        phi = plan.phi_at(ts[k], X[k])  # Pinocchio at this sample: the controller reads it
        Js = _jacobians(plan, phi)
        resolved = plan.launch(ts[k], X[k], phi, Js, plan.P.dot(phi), [])
        for ci in out:
            out[ci][k] = resolved[ci].slip
    return out


def _task_torque(plan, Phi: np.ndarray, O: np.ndarray, J_all: list, X: np.ndarray) -> np.ndarray:
    """The affine task law's joint command at every sample [N·m or N]: J_tipᵀ g_ctl + the feedforward − k_dj q̇
    (:meth:`~contactdyn.compiled.plan_kkt.CompiledKKT._feedforward_torque`, over samples)."""
    nQ, nv = plan.system.nQ, plan.system.nv
    tau = np.einsum("kiv,ki->kv", J_all[plan.tip_frame], O[:, plan.o_gctl])
    if plan.feedforward == "gravity":
        tau += Phi[:, plan.i_h + nv:plan.i_h + 2 * nv]
    elif plan.feedforward == "bias":
        tau += Phi[:, plan.i_h:plan.i_h + nv]
    if plan.kd_joint:
        tau -= plan.kd_joint * X[:, nQ:nQ + nv]
    return tau


def _read_out(plan, S: Samples, ts: np.ndarray, X: np.ndarray, Phi: np.ndarray, O: np.ndarray, Z: np.ndarray,
              J_all: list, tau: np.ndarray, refs: dict, drive_out: tuple | None) -> None:
    """Fill S with the same quantities System.evaluate reports, from the solved samples."""
    s, phase = plan.system, plan.phase
    nQ, nv = s.nQ, s.nv
    kt = plan.i_e + plan.e_frame[plan.tip_frame]
    S.tip[:] = Phi[:, kt:kt + 3]
    S.tau_cmd[:] = _task_torque(plan, Phi, O, J_all, X) if plan.affine_ctl and drive_out is None else tau
    if drive_out is None:
        S.tau[:] = S.tau_cmd
        S.body_force[:] = O[:, plan.o_body]
    else:  # what the drives apply: joints, then bodies
        F, S.u[:] = drive_out
        S.tau[:] = F[:, :nv]
        S.body_force[:] = F[:, nv:nv + S.body_force.shape[1]]
    if phase.reference is not None and plan.affine_ctl:  # x_d = start + Σ δ_m σ_m, σ_m in φ's time terms
        S.x_d[:] = phase.reference.start
        for slot, m_ in plan.time_moves:
            S.x_d += Phi[:, plan.i_e + slot, None] * m_.delta
        S.has_x_d = True
    elif phase.reference is not None:
        x_d = reference_positions(s, phase, ts, X)  # (carried: + the body's origin)
        if x_d.shape[1] == 3:
            S.x_d[:] = x_d
            S.has_x_d = True
    for i, k in plan.limit_rows.items():
        S.limit_torque[:, i] = Z[:, k]
    if plan.o_fjoint is not None:  # damping and sliding friction, a stuck joint's holding torque
        S.joint_friction[:] = O[:, plan.o_fjoint]
        for i, k in plan.joint_rows.items():
            S.joint_friction[:, i] += Z[:, k]
    slots = {key: slot for slot, _, key in plan.time_ramps}
    for key, ramp in phase.forces.items():
        S.F_d[key][:] = Phi[:, plan.i_e + slots[key]] if key in slots else ramp.values(ts)
        S.has_F_d[key] = True
    for ci, (c, mode) in enumerate(zip(s.contacts, plan.modes, strict=True)):
        name = c.name
        r = plan.normal_row.get(ci)
        F_n = Z[:, nQ + r] if r is not None else O[:, plan.o_Fint.start + ci]
        S.F_n[name][:] = F_n
        S.gap[name][:] = O[:, plan.o_gap.start + ci]

        if c.friction is not None and len(c.tangents):
            S.v_slip[name][:] = O[:, plan.o_vt[name]]
            if mode.touching and mode.stuck:
                S.F_f[name][:] = Z[:, plan.stick_rows[ci]]
            elif mode.touching:
                D = slip_directions(plan, ci, O, refs.get(ci))
                mu = _coefficients(plan, ci, O)[:, None]
                S.F_f[name][:] = -mu * np.maximum(F_n, 0.0)[:, None] * D + O[:, plan.o_visc[name]]
        for i, dc in enumerate(c.tangent_chains):
            key = f"{name}.{dc.label}"
            rows = [nQ + r for r, row in enumerate(plan.rows) if row.kind == "chain" and row.contact == ci
                    and row.index == i]
            S.iface[key][:] = Z[:, rows[0]] if rows else O[:, plan.o_iface[key].start]
    for label, sl in plan.o_stage.items():
        S.stages[label][:] = O[:, sl]


def _coefficients(plan, ci: int, O: np.ndarray) -> np.ndarray:
    """The kinetic coefficient (N,) of contact ci at the samples' outputs O: its law's μ(|v_t|)."""
    c = plan.system.contacts[ci]
    return np.broadcast_to(c.friction.mu(np.linalg.norm(O[:, plan.o_vt[c.name]], axis=1)), (len(O),))


def slip_directions(plan, ci: int, O: np.ndarray, refs: np.ndarray | None = None) -> np.ndarray:
    """Sliding directions (N, k) of contact ci at the samples' outputs O (friction.slip_direction's rule:
    v_t/|v_t| while v_t·r exceeds the stick band, else the reference r; 1-D: r). r: the mode's, or per
    sample ``refs`` (N, 2) (a slide launching from rest, :func:`_launch_references`)."""
    c, mode = plan.system.contacts[ci], plan.modes[ci]
    r = np.asarray(mode.slip, float)
    if len(c.tangents) == 1:
        return np.broadcast_to(r, (len(O), 1))
    vt = O[:, plan.o_vt[c.name]]
    out = np.broadcast_to(r, vt.shape).copy() if refs is None else refs.copy()
    ahead = np.einsum("ki,ki->k", vt, out) > plan.system.slip_band
    out[ahead] = vt[ahead] / np.sqrt((vt[ahead] ** 2).sum(axis=1))[:, None]
    return out

def _solve_all(plan, A: np.ndarray, B: np.ndarray) -> np.ndarray:
    with np.errstate(all="ignore"):
        try:
            Z = np.linalg.solve(A, B[..., None])[..., 0]
        except np.linalg.LinAlgError:
            Z = np.full(B.shape, np.nan)
    bad = ~np.all(np.isfinite(Z), axis=1)
    for k in np.flatnonzero(bad):
        Z[k] = plan._singular(A[k], B[k])
    return Z

