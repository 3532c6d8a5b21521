"""A compiled plan's output: the Result channels' values at many states at once.

The integrator needs only derivatives; a Result needs, at every output sample, the
forces, torques, gaps, slip velocities and stage deformations. :func:`plan_samples`
computes them for all samples of a segment together: one Pinocchio pass per sample
(H, J, J̇q̇, h, the tip position), then φ, the map P φ, the friction terms, the KKT
solves and the read-out as array operations. Through motors, the drives' forces and
voltages come from the plan's drive matrix (:mod:`contactdyn.plan_drives`; the law itself
at samples where a voltage clips); a plan folding measured forces or a carried reference
into its solve takes each sample through that fold. :class:`Samples` holds the result (and
is filled from :class:`~contactdyn.dynamics.Evaluation` objects where a mode runs on
``System.evaluate``).
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin

from .friction import launching
from .phases import reference_at
from .plan_fold import contact_torque_of

__all__ = ["Samples", "plan_samples", "evaluated_samples", "slip_directions"]

_LWA = pin.ReferenceFrame.LOCAL_WORLD_ALIGNED
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
        out = cls(0, system)
        for name in ("tau", "tau_cmd", "u", "limit_torque", "tip", "x_d", "body_force"):
            setattr(out, name, np.concatenate([getattr(p, name) for p in parts]))
        out.has_x_d = any(p.has_x_d for p in parts)
        out.has_F_d = {key: any(p.has_F_d[key] for p in parts) for key in out.has_F_d}
        for name in ("F_n", "gap", "F_d", "F_f", "v_slip", "iface", "stages"):
            d = getattr(out, name)
            for key in d:
                d[key] = np.concatenate([getattr(p, name)[key] for p in parts])
        return out

    def fill(self, k: int, ev) -> None:
        """Row k from a full :class:`~contactdyn.dynamics.Evaluation`."""
        self.tau[k] = ev.tau
        self.tau_cmd[k] = ev.tau_cmd
        self.u[k] = ev.u
        for i, value in ev.limit_torque.items():
            self.limit_torque[k, i] = value
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
    """Diagnostics at the states X[k] (times ts[k]) of this mode: one Pinocchio pass per
    sample, then the assembly, solve and read-out for all samples at once."""
    N = len(ts)
    if plan.drives_per_call and plan.launch is not None:  # a slide from rest under motors: the readable model
        return evaluated_samples(plan.system, ts, X, plan.modes, plan.phase)
    S = Samples(N, plan.system)
    if N == 0:
        return S
    folds = getattr(plan, "folded_detail", None) is not None  # the call folds the command into its solve
    _read_out(plan, S, ts, X, *(_solve_folded_samples if folds else _solve_samples)(plan, ts, X))
    return S


def _solve_folded_samples(plan, ts: np.ndarray, X: np.ndarray):
    """As :func:`_solve_samples` for a plan folding measured forces or a carried reference into its solve:
    each sample through the plan's own fold (:func:`~contactdyn.plan_fold.folded_solve`), which gives the
    solved command; the drives' forces and voltages at those commands over all samples at once."""
    s = plan.system
    N, nv, m = len(ts), s.nv, plan.m
    m2 = m * m
    Phi = np.empty((N, plan.P.shape[1]))
    Y = np.empty((N, plan.P.shape[0]))
    Z = np.empty((N, m))
    tau = np.empty((N, nv))
    friction, detail = plan.friction_terms, plan.folded_detail
    for k in range(N):
        t, x = ts[k], X[k]
        Phi[k] = phi = plan.phi_at(t, x)
        Js = [phi[i:i + 3 * nv].reshape(3, nv) for i in plan.i_J]
        Y[k] = y = plan.P.dot(phi)
        if friction is not None:
            friction(y, Js, plan.modes)
        Z[k], _, tau[k] = detail(t, x, Js, phi, y[m2 + m:], y[:m2].reshape(m, m), y[m2:m2 + m])
    J_all = [Phi[:, i:i + 3 * nv].reshape(N, 3, nv) for i in plan.i_J]
    return Phi, Y[:, m2 + m:], Z, J_all, tau, {}, _drive_samples(plan.compiled_drives, X, tau)


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


def _solve_samples(plan, ts: np.ndarray, X: np.ndarray):
    """φ, the outputs o and the solution z at every sample, all at once: (Φ, O, Z, Jacobians, τ of a generic law)."""
    s = plan.system
    N = len(ts)
    nQ, nv, nr, m = s.nQ, s.nv, plan.nr, plan.m
    m2 = m * m
    Phi = np.empty((N, plan.P.shape[1]))
    generic = not plan.affine_ctl
    tau = np.zeros((N, nv))
    if generic:
        command = _generic_command(plan)
    ntv = plan.ne - plan.e_frame[-1] - 6
    TV = np.empty((N, ntv))
    TV[:, -1] = 1.0
    for k in range(N):
        plan.time_terms(ts[k], TV[k])
    if generic or len(plan.fids) > 1:
        phi_at = plan.phi_at
        for k in range(N):
            Phi[k] = phi = phi_at(ts[k], X[k], TV[k])
            if generic:  # (Pinocchio's data at this sample: the controller reads it)
                tau[k] = command(ts[k], X[k], [phi[i:i + 3 * nv].reshape(3, nv) for i in plan.i_J], phi)
    else:
        _phi_batch(plan, X, TV, Phi)
    Y = _rows_times(Phi, plan.PT)
    A = Y[:, :m2].reshape(N, m, m)
    B = Y[:, m2:m2 + m]
    O = Y[:, m2 + m:]
    J_all = [Phi[:, i:i + 3 * nv].reshape(N, 3, nv) for i in plan.i_J]
    w0 = nQ + nr
    refs = _launch_references(plan, ts, X, O) if plan.launch is not None else {}
    for ci, i_fn, mu, T, consts, j in plan.coulomb_terms:
        Fp = np.maximum(O[:, i_fn], 0.0)
        D = slip_directions(plan, ci, O, refs.get(ci))
        B[:, w0 + 3 * j:w0 + 3 * j + 3] -= (mu * Fp)[:, None] * (D @ T)
        if nQ > nv:
            B[:, nv:nQ] -= (mu * Fp)[:, None] * (D @ consts)
    for r, ci, mu, T, consts, j in plan.dyn_tilt:
        D = slip_directions(plan, ci, O, refs.get(ci))
        A[:, :nv, nQ + r] += mu * np.einsum("kiv,ki->kv", J_all[j], D @ T)
        A[:, nv:nQ, nQ + r] = plan.A0[nv:nQ, nQ + r] + mu * (D @ consts)
    drives = plan.compiled_drives
    if drives is None:
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
    motorized = drives.system.drives.motorized
    U = np.full((len(X), len(motorized)), np.nan)
    U[:, motorized] = _rows_times(E, drives.V.T)
    clipped = np.flatnonzero(np.abs(Y[:, nQ:]).max(axis=1) > 1.0) if drives.limited else ()
    for k in clipped:
        F[k], out = drives.output(X[k], tau[k])
        U[k] = out.u
    return F, U


def _launch_references(plan, ts: np.ndarray, X: np.ndarray, O: np.ndarray) -> dict[int, np.ndarray]:
    """Per launching contact, the reference r of each sample (O: the samples' outputs): the direction its
    slide from rest takes (the plan's own per-call launch, :func:`~contactdyn.plan_rhs.make_rhs`) where the
    slip is still inside the stick band, the mode's r where it has left it (there the slip's own direction
    rules anyway)."""
    s = plan.system
    nv = s.nv
    out = {}
    inside = np.zeros(len(ts), bool)
    for ci, mode in enumerate(plan.modes):
        if launching(mode):
            r = np.asarray(mode.slip, float)
            out[ci] = np.tile(r, (len(ts), 1))
            inside |= O[:, plan.o_vt[s.contacts[ci].name]] @ r <= s.slip_band
    for k in np.flatnonzero(inside):
        phi = plan.phi_at(ts[k], X[k])  # Pinocchio at this sample: the controller reads it
        Js = [phi[i:i + 3 * nv].reshape(3, nv) for i in plan.i_J]
        resolved = plan.launch(ts[k], X[k], phi, Js, plan.P.dot(phi), [])
        for ci in out:
            out[ci][k] = resolved[ci].slip
    return out


def _task_torque(plan, Phi: np.ndarray, O: np.ndarray, J_all: list, X: np.ndarray) -> np.ndarray:
    """The affine task law's joint command at every sample [N·m or N]: J_tipᵀ g_ctl + the feedforward − k_dj q̇
    (:meth:`~contactdyn.plan_kkt.CompiledKKT._feedforward_torque`, over samples)."""
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
        x_d = np.array([reference_at(s, phase, t, x)[0] for t, x in zip(ts, X, strict=True)])  # (carried: + body)
        if x_d.shape[1] == 3:
            S.x_d[:] = x_d
            S.has_x_d = True
    for i, k in plan.limit_rows.items():
        S.limit_torque[:, i] = Z[:, k]
    slots = {key: slot for slot, _, key in plan.time_ramps}
    for key, ramp in phase.forces.items():
        S.F_d[key][:] = Phi[:, plan.i_e + slots[key]] if key in slots else [ramp.at(t)[0] for t in ts]
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
                S.F_f[name][:] = -c.friction.mu_k * np.maximum(F_n, 0.0)[:, None] * D + O[:, plan.o_visc[name]]
        for i, dc in enumerate(c.tangent_chains):
            key = f"{name}.{dc.label}"
            rows = [nQ + r for r, row in enumerate(plan.rows) if row.kind == "chain" and row.contact == ci
                    and row.index == i]
            S.iface[key][:] = Z[:, rows[0]] if rows else O[:, plan.o_iface[key].start]
    for label, sl in plan.o_stage.items():
        S.stages[label][:] = O[:, sl]


def _phi_batch(plan, X: np.ndarray, TV: np.ndarray, Phi: np.ndarray) -> None:
    """Φ for one robot frame: Pinocchio per sample (H, J, J̇q̇, h, [g], p), the rest in batch."""
    s = plan.system
    model, data = s.robot.model, s.robot.data
    nv, nQ, n = s.nv, s.nQ, s.n
    fid = plan.fids[0]
    i_e = plan.i_e
    compute, placement = pin.computeAllTerms, pin.updateFramePlacement
    jacobian, accel = pin.getFrameJacobian, pin.getFrameClassicalAcceleration
    cat = np.concatenate
    with_g = plan.with_g
    raw = np.empty((len(X), i_e + 3))
    for k in range(len(X)):
        x = X[k]
        compute(model, data, x[:nv], x[nQ:nQ + nv])
        J = jacobian(model, data, fid, _LWA).reshape(6, nv)[:3]
        if with_g:
            raw[k] = cat((data.M.ravel("K"), J.ravel(), accel(model, data, fid, _LWA).linear, data.nle, data.g,
                          placement(model, data, fid).translation))
        else:
            raw[k] = cat((data.M.ravel("K"), J.ravel(), accel(model, data, fid, _LWA).linear, data.nle,
                          placement(model, data, fid).translation))
    Phi[:, :i_e] = raw[:, :i_e]
    Phi[:, i_e:i_e + n] = X
    Phi[:, i_e + n:i_e + n + 3] = raw[:, i_e:]
    J_all = raw[:, plan.i_J[0]:plan.i_J[0] + 3 * nv].reshape(len(X), 3, nv)
    Phi[:, i_e + n + 3:i_e + n + 6] = np.einsum("kiv,kv->ki", J_all, X[:, nQ:nQ + nv])
    Phi[:, i_e + n + 6:] = TV

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

