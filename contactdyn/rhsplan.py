"""The right-hand side compiled for one (modes, phase): the integrator's fast path.

:meth:`System.evaluate` assembles everything per call (dicts, row lists, diagnostics).
Within one smooth phase the modes are fixed, and then almost everything except the
robot's own terms (H, h, J, J̇q̇) is *affine* in a short vector

    e = [x, p_f, ṗ_f (per robot frame used), time terms, 1]

chain stage forces and junction rates, slip velocities, gaps, servo forces, viscous
friction and the plain task-space PD law. A :class:`ModePlan` measures that affine map
``o = W e`` once, by probing the system's own code (:meth:`System._chain` & co.) at unit
vectors, so it is the same model by construction; the constraint rows are ``a·J`` plus
constants, collected once. A call then costs Pinocchio's terms, one product ``W e``,
one product for the rows and one small linear solve. What is not affine stays explicit:
Coulomb friction ``−μ max(F_n, 0) d``, 2-D slip directions, other controllers.

A plan checks itself against :meth:`System.evaluate` when it is built (two states) and
declines (``plan.ok`` false, ``plan.reason`` says why) where it cannot represent the
system — the energy audit, non-linear stage laws, parts it does not know — and the
caller falls back to :meth:`System.evaluate`.
"""

from __future__ import annotations

import math
import pickle
import weakref
from types import SimpleNamespace

import numpy as np
import pinocchio as pin

from .contact import ContactMode, Kinematics
from .controllers import ControlInput
from .samples import Samples, plan_samples, slip_directions
from .trajectory import profile

__all__ = ["ModePlan", "Samples", "cached_plan"]  # Samples: re-exported from contactdyn.samples

_LWA = pin.ReferenceFrame.LOCAL_WORLD_ALIGNED
try:  # numpy's gufunc without the Python wrapper (see system.solve_linear)
    from numpy.linalg import _umath_linalg

    _solve1 = _umath_linalg.solve1
except (ImportError, AttributeError):  # pragma: no cover
    _solve1 = np.linalg.solve

CHECK_RTOL = 1e-9  #: agreement a plan must show with System.evaluate when it is built


_PLANS: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()  #: system -> {key: ModePlan}


def affine_map(f, n: int) -> np.ndarray:
    """Matrix A with f(e) = A e for an affine f of e = [e₁ … e₍ₙ₋₁₎, 1], read off by unit probes."""
    e0 = np.zeros(n)
    e0[-1] = 1.0
    f0 = np.asarray(f(e0))
    A = np.empty((len(f0), n))
    A[:, -1] = f0
    for k in range(n - 1):
        e = e0.copy()
        e[k] = 1.0
        A[:, k] = np.asarray(f(e)) - f0
    return A


def cached_plan(system, modes: list[ContactMode], phase) -> ModePlan:
    """The plan of (modes, phase), compiled once per system: a repeated run of the same system
    (benchmarks, sweeps) reuses it. The key is the modes and the phase's content (index, start,
    reference, set-points), not the Phase object, which every run makes anew."""
    content = pickle.dumps((phase.index, phase.t_start, phase.spec.name, phase.reference, phase.forces,
                            getattr(phase, "carrier", None), getattr(phase, "limits", ())))
    key = (tuple(modes), content)
    plans = _PLANS.setdefault(system, {})
    plan = plans.get(key)
    if plan is None:
        plan = plans[key] = ModePlan(system, modes, phase)
    return plan


class _Outputs:
    """Named slots of the affine output vector o."""

    def __init__(self):
        self.names: list[str] = []
        self.index: dict[str, int] = {}

    def add(self, name: str, size: int = 1) -> slice:
        start = len(self.names)
        for i in range(size):
            key = name if size == 1 else f"{name}[{i}]"
            self.index[key] = len(self.names)
            self.names.append(key)
        return slice(start, start + size)


class ModePlan:
    """The compiled right-hand side of one (modes, phase); see the module docstring."""

    def __init__(self, system, modes: list[ContactMode], phase):
        self.system, self.modes, self.phase = system, list(modes), phase
        self.ok, self.reason = False, ""
        self.ring: list[tuple] = [(None, None, None, None)] * 4  #: the last four calls' (t, x, z, o)
        reason = self._unsupported()
        if reason:
            self.reason = reason
            return
        self._layout()
        self._measure()
        if not self.ok:
            return
        self._rows()
        self._build()
        self._check()

    # ---- what a plan can represent ----------------------------------------------------
    def _unsupported(self) -> str:
        s = self.system
        if s.energy_slot >= 0:
            return "energy audit (solver.record_energy)"
        drives = getattr(s, "drives", None)
        if drives is not None and drives.any_motor:
            return "motors (drive models)"
        expected_nQ = s.nv + len(s.body_names) + len(s.mass_labels)
        if s.nQ != expected_nQ:
            return f"coordinates the plan does not know ({s.nQ - expected_nQ} beyond robot, bodies, masses)"
        if getattr(self.phase.controller, "uses_forces", False):
            return "a controller reading measured forces (folded into the linear solve)"
        if any(getattr(m, "from_rest", False) and len(m.slip) == 2 and not m.stuck for m in self.modes):
            return "a 2-D slip launching from rest (its direction is solved per call)"
        if getattr(self.phase, "carrier", None) is not None:
            return "a reference carried by a body (its acceleration is folded into the linear solve)"
        if getattr(self.phase, "limits", ()):
            return "a joint pressing on its position limit (contactdyn.limits)"
        return ""

    # ---- layout of e and o --------------------------------------------------------------
    def _layout(self) -> None:
        s, phase = self.system, self.phase
        n = s.n
        fids: list[int] = []
        for fid in [c.fid for c in s.contacts] + [s.tip_fid]:
            if fid not in fids:
                fids.append(fid)
        self.fids = fids
        self.frame_of = {fid: i for i, fid in enumerate(fids)}
        self.tip_frame = self.frame_of[s.tip_fid]
        self.e_frame = [n + 6 * i for i in range(len(fids))]  # p at [k, k+3), ṗ at [k+3, k+6)
        ne = n + 6 * len(fids)
        ctl = phase.controller
        law = ctl.tip_force_law() if hasattr(ctl, "tip_force_law") else None
        self.affine_ctl = law is not None
        self.time_moves: list[tuple] = []  # (slot, move)
        self.time_ramps: list[tuple] = []  # (slot, ramp, contact index)
        self.feedforward, self.kd_joint = "none", 0.0
        if self.affine_ctl:
            self.kp, self.kd, self.feedforward, self.kd_joint = law.kp, law.kd, law.feedforward, law.kd_joint
            if phase.reference is not None:
                if len(phase.reference.start) != 3 or any(m.kind == "circle" for m in phase.reference.moves):
                    self.affine_ctl = False
                else:
                    for m in phase.reference.moves:
                        self.time_moves.append((ne, m))
                        ne += 2
            for key, ramp in phase.forces.items():
                self.time_ramps.append((ne, ramp, key))
                ne += 1
        self.ne = ne + 1  # the constant 1 last
        out = _Outputs()
        nQ, nv = s.nQ, s.nv
        self.o_f = out.add("f_rest", nQ - nv)
        self.o_y = out.add("ydot", s.ny)
        self.o_g = out.add("g", 3 * len(fids))
        self.n_rhs = len(out.names)
        self.o_gctl = out.add("g_ctl", 3)
        self.o_Fint = out.add("F_int", len(s.contacts))
        self.o_gap = out.add("gap", len(s.contacts))
        self.o_vt = {c.name: out.add(f"vt.{c.name}", len(c.tangents)) for c in s.contacts}
        self.o_visc = {c.name: out.add(f"visc.{c.name}", len(c.tangents)) for c in s.contacts}
        self.o_iface = {f"{c.name}.{dc.label}": out.add(f"iface.{c.name}.{dc.label}")
                        for c in s.contacts for dc in c.tangent_chains}
        self.o_body = out.add("body_force", len(s.body_names))
        self.o_stage = {label: out.add(f"stage.{label}", 3) for label in s.stage_labels}
        self.no = len(out.names)

    # ---- the affine map, by probing the system's own code --------------------------------
    def _probe(self, e: np.ndarray, drift: np.ndarray | None = None) -> tuple[np.ndarray, list]:
        """Outputs o at e, and the constraint rows [(a, frame, const, γ)] with J = 0 and J̇q̇ = drift."""
        s = self.system
        n, nQ, nv = s.n, s.nQ, s.nv
        x = e[:n]
        o = np.zeros(self.no)
        f = np.zeros(nQ)
        ydot = np.zeros(s.ny)
        g = np.zeros((len(self.fids), 3))
        ev = SimpleNamespace(stages={})
        J0 = np.zeros((3, nv))
        d0 = np.zeros(3) if drift is None else drift
        rows = []
        for ci, (c, mode) in enumerate(zip(s.contacts, self.modes, strict=True)):
            j = self.frame_of[c.fid]
            k = self.e_frame[j]
            p_tip, v_tip = e[k:k + 3], e[k + 3:k + 6]
            if c.body_index >= 0:
                p_env = c.spec.point + c.body_axis * x[c.body_index]
                v_env = c.body_axis * x[nQ + c.body_index]
            else:
                p_env, v_env = c.spec.point, np.zeros(3)
            kin = Kinematics(p_tip, v_tip, J0, d0, p_env, v_env)
            tip_F, row, gamma, F_int, gap = s._chain(c, c.normal, mode.touching, 0.0, kin, x, f, ydot, ev, True)
            g[j] += tip_F * c.normal.u
            o[self.o_Fint.start + ci] = F_int
            o[self.o_gap.start + ci] = gap
            for i, dc in enumerate(c.tangent_chains):
                tF, trow, tgamma, tint, _ = s._chain(c, dc, mode.touching, mode.offsets[i], kin, x, f, ydot, ev, True)
                g[j] += tF * dc.u
                o[self.o_iface[f"{c.name}.{dc.label}"]] = tint
                if trow is not None:
                    rows.append(("chain", ci, i, trow, tgamma))
            if c.friction is not None and len(c.tangents):
                T = c.tangents
                vt = T @ (v_tip - v_env)
                o[self.o_vt[c.name]] = vt
                if mode.touching and mode.stuck:
                    for i in range(len(T)):
                        const = np.zeros(nQ)
                        if c.body_index >= 0:
                            const[c.body_index] -= T[i] @ c.body_axis
                        rows.append(("stick", ci, i, const, float(T[i] @ d0) + s.stabilization * float(vt[i])))
                elif mode.touching:
                    visc = -c.friction.viscous * vt
                    o[self.o_visc[c.name]] = visc
                    g[j] += T.T @ visc
                    if c.body_index >= 0:
                        f[c.body_index] -= float(visc @ (T @ c.body_axis))
            if row is not None:
                rows.append(("normal", ci, 0, row, gamma))
        for idx, v_ref, gain in s.servo:
            F = gain * (v_ref - x[nQ + idx])
            f[idx] += F
            o[self.o_body.start + idx - nv] = F
        if self.affine_ctl:
            k = self.e_frame[self.tip_frame]
            g_ctl = np.zeros(3)
            if self.phase.reference is not None:
                ref = self.phase.reference
                g_ctl += self.kp @ (ref.start - e[k:k + 3]) - self.kd @ e[k + 3:k + 6]
                for slot, m in self.time_moves:
                    g_ctl += (self.kp @ m.delta) * e[slot] + (self.kd @ m.delta) * e[slot + 1]
            for slot, _, key in self.time_ramps:
                g_ctl -= e[slot] * s.force_directions[key]
            g[self.tip_frame] += g_ctl
            o[self.o_gctl] = g_ctl
        o[self.o_f] = f[nv:]
        o[self.o_y] = ydot
        o[self.o_g] = g.ravel()
        for label, sl in self.o_stage.items():
            o[sl] = ev.stages.get(label, (0.0, 0.0, 0.0))
        return o, rows

    def _probe_all(self, e: np.ndarray) -> np.ndarray:
        """o at e followed by the rows' γ (their state-dependent part: Baumgarte terms) with J̇q̇ = 0."""
        o, rows = self._probe(e)
        return np.concatenate([o, [row[4] for row in rows]])

    def _measure(self) -> None:
        ne = self.ne
        W = affine_map(self._probe_all, ne)
        w0 = W[:, -1]
        rng = np.random.default_rng(1)
        for _ in range(2):  # affine? (a Hunt–Crossley stage is not)
            e = np.append(rng.normal(size=ne - 1), 1.0)
            o = self._probe_all(e)
            if not np.allclose(W @ e, o, rtol=1e-9, atol=1e-9 * (1.0 + np.abs(o).max())):
                self.reason = "non-linear stage law (e.g. Hunt–Crossley)"
                return
        self.o_gam = slice(self.no, len(w0))  # γ's state part, one per constraint row
        self.no = len(w0)
        self.W = W
        self.ok = True

    # ---- constraint rows --------------------------------------------------------------
    def _rows(self) -> None:
        """Rows r = a_r·J_f(r) + const_r, γ_r = a_r·J̇q̇; columns tilted by sliding friction."""
        s = self.system
        e0 = np.zeros(self.ne)
        e0[-1] = 1.0
        _, rows0 = self._probe(e0)
        probes = [self._probe(e0, np.eye(3)[k])[1] for k in range(3)]
        self.rows = []
        for r, (kind, ci, i, const, gamma0) in enumerate(rows0):
            a = np.array([probes[k][r][4] - gamma0 for k in range(3)])
            c = s.contacts[ci]
            self.rows.append(SimpleNamespace(kind=kind, contact=ci, index=i, a=a, const=np.array(const, float),
                                             frame=self.frame_of[c.fid], label=c.tangent_chains[i].label
                                             if kind == "chain" else None))
        self.nr = len(self.rows)
        nQ = s.nQ
        self.normal_row = {row.contact: r for r, row in enumerate(self.rows) if row.kind == "normal"}
        self.stick_rows: dict[int, list[int]] = {}
        for r, row in enumerate(self.rows):
            if row.kind == "stick":
                self.stick_rows.setdefault(row.contact, []).append(nQ + r)
        # sliding friction: tilt of the normal row's column, or an explicit force
        self.tilts = []  # (row, contact, 1-D?)
        self.coulomb = []  # (contact index, frame) for sliding without a normal row
        for ci, (c, mode) in enumerate(zip(s.contacts, self.modes, strict=True)):
            if c.friction is None or not len(c.tangents) or not mode.touching or mode.stuck:
                continue
            normal = [r for r, row in enumerate(self.rows) if row.kind == "normal" and row.contact == ci]
            if normal:
                self.tilts.append((normal[0], ci))
            else:
                self.coulomb.append(ci)

    def _tangent_terms(self, c) -> tuple[np.ndarray, np.ndarray]:
        """Per tangent i: its Cartesian direction T_i and its body column (−T_i·axis at the body)."""
        nQ = self.system.nQ
        consts = np.zeros((len(c.tangents), nQ))
        if c.body_index >= 0:
            consts[:, c.body_index] = -(c.tangents @ c.body_axis)
        return c.tangents, consts

    def _direction(self, ci: int, o: np.ndarray) -> np.ndarray:
        """The sliding direction d of contact ci at outputs o (System._slip_direction's rule)."""
        c, mode = self.system.contacts[ci], self.modes[ci]
        return self.system._slip_direction(o[self.o_vt[c.name]], mode)

    # ---- compiled arrays ----------------------------------------------------------------
    def _build(self) -> None:
        """Constant parts of the KKT matrix, then the map P: φ ↦ [A, b, o] (see :meth:`_assemble`)."""
        s = self.system
        nQ, nv, nr, nf = s.nQ, s.nv, self.nr, len(self.fids)
        m = nQ + nr + 3 * nf
        A0 = np.zeros((m, m))
        A0[nv:nQ, nv:nQ] = np.diag(s.M_rest)
        for i in range(3 * nf):  # w = g: the Cartesian force on each frame, an unknown with a trivial row
            A0[nQ + nr + i, nQ + nr + i] = 1.0
        self.dyn_tilt = []  # 2-D sliding: column tilt computed per call
        Qr = np.zeros((nf, nr, 3))  # rows' Cartesian parts, per frame
        Qc = np.zeros((nf, nr, 3))  # columns' Cartesian parts (negated: A holds −Cᵀ)
        for r, row in enumerate(self.rows):
            A0[nQ + r, :nQ] = row.const
            A0[:nQ, nQ + r] = -row.const
            Qr[row.frame, r] = row.a
            Qc[row.frame, r] = -row.a
        for r, ci in self.tilts:
            c = s.contacts[ci]
            T, consts = self._tangent_terms(c)
            mu = c.friction.mu_k
            if len(T) == 1:
                d = np.asarray(self.modes[ci].slip, float)
                Qc[self.frame_of[c.fid], r] += mu * (d @ T)
                A0[:nQ, nQ + r] += mu * (d @ consts)
            else:
                self.dyn_tilt.append((r, ci, mu, T, consts[:, nv:], self.frame_of[c.fid]))
        self.m, self.A0, self.Qr, self.Qc = m, A0, Qr, Qc
        # φ = [H, (J_f), (J̇q̇_f), h, e]; e = [x, (p_f, ṗ_f), time terms, 1]
        self.i_H = 0
        self.i_J = [nv * nv + 3 * nv * f for f in range(nf)]
        self.i_dr = [nv * nv + 3 * nv * nf + 3 * f for f in range(nf)]
        self.i_h = nv * nv + 3 * nv * nf + 3 * nf
        self.with_g = self.feedforward == "gravity"  # then φ carries g(q) after h
        self.i_e = self.i_h + nv * (2 if self.with_g else 1)
        P = affine_map(self._assemble, self.i_e + self.ne)
        self.P = P
        self.PT = np.ascontiguousarray(P.T)
        self.coulomb_terms = []
        for ci in self.coulomb:
            c = s.contacts[ci]
            T, consts = self._tangent_terms(c)
            one_d = len(T) == 1
            dT = np.asarray(self.modes[ci].slip, float) @ T if one_d else None
            dC = np.asarray(self.modes[ci].slip, float) @ consts[:, nv:] if one_d else None
            self.coulomb_terms.append((ci, self.o_Fint.start + ci, c.friction.mu_k, T, consts[:, nv:],
                                       self.frame_of[c.fid], dT, dC))
        self.z_slice = slice(2 * nQ + self.phase.z_slice.start, 2 * nQ + self.phase.z_slice.stop)
        self.rhs = self._make_rhs()

    def _assemble(self, phi: np.ndarray) -> np.ndarray:
        """[A.ravel(), b, o] from φ, written out plainly (P is measured from this).

        Unknowns [Q̈, λ, w_f]: M Q̈ − Cᵀλ − Σ J_fᵀ w_f = [−h, f_rest];  G Q̈ = −γ;  w_f = g_f.
        """
        s = self.system
        nQ, nv, nr, m = s.nQ, s.nv, self.nr, self.m
        H = phi[:nv * nv].reshape(nv, nv)
        e = phi[self.i_e:]
        o = self.W.dot(e)
        A = self.A0.copy()
        b = np.zeros(m)
        A[:nv, :nv] += H
        b[:nv] = -phi[self.i_h:self.i_h + nv] + self._feedforward_torque(phi, e)
        b[nv:nQ] = o[self.o_f]
        b[nQ:nQ + nr] = -o[self.o_gam]
        for f in range(len(self.fids)):
            J = phi[self.i_J[f]:self.i_J[f] + 3 * nv].reshape(3, nv)
            dr = phi[self.i_dr[f]:self.i_dr[f] + 3]
            A[nQ:nQ + nr, :nv] += self.Qr[f] @ J
            A[:nv, nQ:nQ + nr] += (self.Qc[f] @ J).T
            A[:nv, nQ + nr + 3 * f:nQ + nr + 3 * f + 3] -= J.T
            b[nQ:nQ + nr] -= self.Qr[f] @ dr
            b[nQ + nr + 3 * f:nQ + nr + 3 * f + 3] = o[self.o_g.start + 3 * f:self.o_g.start + 3 * f + 3]
        return np.concatenate([A.ravel(), b, o])

    def _feedforward_torque(self, phi: np.ndarray, e: np.ndarray) -> np.ndarray:
        """The task PD law's joint-space terms: feedforward g(q) or h(q, q̇), and −k_dj q̇."""
        nv, nQ = self.system.nv, self.system.nQ
        tau = -self.kd_joint * e[nQ:nQ + nv]
        if self.feedforward == "gravity":
            tau = tau + phi[self.i_h + nv:self.i_h + 2 * nv]
        elif self.feedforward == "bias":
            tau = tau + phi[self.i_h:self.i_h + nv]
        return tau

    # ---- the right-hand side ------------------------------------------------------------
    def _make_rhs(self):
        s = self.system
        model, data = s.robot.model, s.robot.data
        n, nQ, nv, nr, m = s.n, s.nQ, s.nv, self.nr, self.m
        m2 = m * m
        tv = np.zeros(self.ne - self.e_frame[-1] - 6)  # time terms and the trailing 1
        tv[-1] = 1.0
        P = self.P
        o_y = slice(m2 + m + self.o_y.start, m2 + m + self.o_y.stop)
        with_y = n > 2 * nQ
        fids = self.fids
        single = len(fids) == 1
        fid0 = fids[0]
        base = self.e_frame[-1] + 6
        time_moves = [(slot - base, m_.kind, m_.start, m_.duration, m_.accel_fraction) for slot, m_ in self.time_moves]
        time_ramps = [(slot - base, ramp.at) for slot, ramp, _ in self.time_ramps]
        coulomb = [(m2 + m + i_fn, mu, T, consts, j, dT, dC, ci) for ci, i_fn, mu, T, consts, j, dT, dC
                   in self.coulomb_terms]
        dyn_tilt = self.dyn_tilt
        generic_ctl = not self.affine_ctl
        ctl_call = self._controller_call() if generic_ctl else None
        z_slice = self.z_slice
        compute = pin.computeAllTerms
        placement, jacobian, accel = pin.updateFramePlacement, pin.getFrameJacobian, pin.getFrameClassicalAcceleration
        lwa = _LWA
        solve = _solve1
        cat = np.concatenate
        isfinite = math.isfinite
        plan = self
        ring = self.ring
        with_g = self.with_g

        def g_part():
            return (data.g,) if with_g else ()
        impulses = self._impulse_terms()
        A0 = self.A0
        w0 = nQ + nr

        def time_terms(t, out=tv):
            """The time terms of e at t (and the trailing 1), written into ``out``."""
            for slot, kind, start, duration, af in time_moves:
                sg, dsg, _ = profile(kind, (t - start) / duration, af)
                out[slot] = sg
                out[slot + 1] = dsg / duration
            for slot, at in time_ramps:
                out[slot] = at(t)[0]
            return out

        self.time_terms = time_terms

        def phi_at(t, x, tv=None):
            """φ at (t, x) (Pinocchio's data left at x); ``tv``: time terms already computed."""
            q = x[:nv]
            v = x[nQ:nQ + nv]
            compute(model, data, q, v)
            if tv is None:
                tv = time_terms(t)
            if single:
                J = jacobian(model, data, fid0, lwa).reshape(6, nv)[:3]
                if with_g:
                    return cat((data.M.ravel("K"), J.ravel(), accel(model, data, fid0, lwa).linear, data.nle, data.g,
                                x, placement(model, data, fid0).translation, J.dot(v), tv))
                return cat((data.M.ravel("K"), J.ravel(), accel(model, data, fid0, lwa).linear, data.nle, x,
                            placement(model, data, fid0).translation, J.dot(v), tv))
            Js = [jacobian(model, data, fid, lwa).reshape(6, nv)[:3] for fid in fids]
            pv = []
            for fid, J in zip(fids, Js, strict=True):
                pv += [placement(model, data, fid).translation, J.dot(v)]
            return cat([data.M.ravel("K"), *[J.ravel() for J in Js],
                        *[accel(model, data, fid, lwa).linear for fid in fids], data.nle, *g_part(), x, *pv, tv])

        self.phi_at = phi_at

        def rhs(t, x):
            q = x[:nv]
            v = x[nQ:nQ + nv]
            compute(model, data, q, v)
            for slot, kind, start, duration, af in time_moves:
                sg, dsg, _ = profile(kind, (t - start) / duration, af)
                tv[slot] = sg
                tv[slot + 1] = dsg / duration
            for slot, at in time_ramps:
                tv[slot] = at(t)[0]
            if single:
                J = jacobian(model, data, fid0, lwa).reshape(6, nv)[:3]
                Js = (J,)
                if with_g:
                    phi = cat((data.M.ravel("K"), J.ravel(), accel(model, data, fid0, lwa).linear, data.nle, data.g,
                               x, placement(model, data, fid0).translation, J.dot(v), tv))
                else:
                    phi = cat((data.M.ravel("K"), J.ravel(), accel(model, data, fid0, lwa).linear, data.nle, x,
                               placement(model, data, fid0).translation, J.dot(v), tv))
            else:
                Js = [jacobian(model, data, fid, lwa).reshape(6, nv)[:3] for fid in fids]
                pv = []
                for fid, J in zip(fids, Js, strict=True):
                    pv += [placement(model, data, fid).translation, J.dot(v)]
                phi = cat([data.M.ravel("K"), *[J.ravel() for J in Js],
                           *[accel(model, data, fid, lwa).linear for fid in fids], data.nle, *g_part(), x, *pv, tv])
            y = P.dot(phi)
            A = y[:m2].reshape(m, m)
            b = y[m2:m2 + m]
            for i_fn, mu, T, consts, j, dT, dC, ci in coulomb:
                F_n = y[i_fn]
                if F_n > 0.0:
                    if dT is None:
                        d = plan._direction(ci, y[m2 + m:])
                        dT, dC = d.dot(T), d.dot(consts)
                    b[w0 + 3 * j:w0 + 3 * j + 3] -= (mu * F_n) * dT
                    if nQ > nv:
                        b[nv:nQ] -= (mu * F_n) * dC
            for r, ci, mu, T, consts, j in dyn_tilt:
                d = plan._direction(ci, y[m2 + m:])
                A[:nv, nQ + r] += mu * Js[j].T.dot(d.dot(T))
                A[nv:nQ, nQ + r] = A0[nv:nQ, nQ + r] + mu * d.dot(consts)
            zdot = None
            if generic_ctl:
                tau, zdot = ctl_call(t, x, q, v, Js, phi, y[m2 + m:])
                b[:nv] += tau
            z = solve(A, b)
            if not isfinite(z.dot(z)):
                z = plan._singular(A, b)
            if with_y:
                xd = cat((x[nQ:2 * nQ], z[:nQ], y[o_y]))
                if zdot is not None:
                    xd[z_slice] = zdot
                for i0, from_z, k_n, sliding, mu, d0, k_visc, stick, ci in impulses:
                    F_n = z[k_n] if from_z else y[k_n]
                    xd[i0] = F_n
                    if stick is not None:
                        xd[i0 + 1:i0 + 1 + len(stick)] = z[stick]
                    elif sliding:
                        Fp = F_n if F_n > 0.0 else 0.0
                        if d0 is not None:  # 1-D
                            xd[i0 + 1] = -mu * Fp * d0 + y[k_visc]
                        else:
                            d = plan._direction(ci, y[m2 + m:])
                            xd[i0 + 1:i0 + 1 + len(d)] = -mu * Fp * d + y[k_visc:k_visc + len(d)]
            else:
                xd = cat((x[nQ:2 * nQ], z[:nQ]))
            ring[0] = ring[1]
            ring[1] = ring[2]
            ring[2] = ring[3]
            ring[3] = (t, x, z, y[m2 + m:])
            return xd

        return rhs

    def _impulse_terms(self) -> list[tuple]:
        """Where the impulse states' rates (∫F dt, ∫F_f dt per friction contact) come from, per contact."""
        s = self.system
        nQ, m = s.nQ, self.m
        off = m * m + m  # o's start in y
        out = []
        for name, slot in getattr(s, "impulse_slots", {}).items():
            ci = next(i for i, c in enumerate(s.contacts) if c.name == name)
            c, mode = s.contacts[ci], self.modes[ci]
            r = self.normal_row.get(ci)
            from_z, k_n = (True, nQ + r) if r is not None else (False, off + self.o_Fint.start + ci)
            stick = np.array(self.stick_rows[ci]) if mode.touching and mode.stuck else None
            sliding = mode.touching and not mode.stuck
            one_d = len(c.tangents) == 1
            d0 = float(mode.slip[0]) if one_d and sliding else None
            k_visc = off + self.o_visc[name].start
            out.append((2 * nQ + slot, from_z, k_n, sliding, c.friction.mu_k, d0, k_visc, stick, ci))
        return out

    # ---- output samples, all at once (contactdyn.samples) ----------------------------------
    def samples(self, ts: np.ndarray, X: np.ndarray) -> Samples:
        """Diagnostics at the states X[k] (times ts[k]) of this mode, as arrays."""
        return plan_samples(self, ts, X)

    def _directions(self, ci: int, O: np.ndarray) -> np.ndarray:
        return slip_directions(self, ci, O)

    def kkt_condition(self, t: float, x: np.ndarray) -> float:
        """2-norm condition number of the contact system [[M, −Cᵀ], [G, 0]] at (t, x) (no w rows)."""
        y = self.P.dot(self.phi_at(t, x))
        m, k = self.m, self.system.nQ + self.nr
        A = y[:m * m].reshape(m, m)[:k, :k]
        return float(np.linalg.cond(A)) if k else 1.0

    def _singular(self, A: np.ndarray, b: np.ndarray) -> np.ndarray:
        """Least-squares fallback of a singular KKT matrix (a rigid contact at a singular pose)."""
        self.singular += 1
        if not (np.all(np.isfinite(A)) and np.all(np.isfinite(b))):  # a wild trial state: let the solver reject it
            return np.full(len(b), np.nan)
        return np.linalg.lstsq(A, b, rcond=1e-12)[0]

    singular = 0  #: calls that needed the least-squares fallback

    @property
    def last(self) -> tuple:
        """(t, x, z, o) of the latest call."""
        return self.ring[3]

    def _controller_call(self):
        """Per-call ControlInput for a controller without an affine tip-force law."""
        s, phase = self.system, self.phase
        robot = s.robot
        ctl = phase.controller
        normals = s.force_directions
        names = [c.name for c in s.contacts]
        i_fint = self.o_Fint.start
        ifaces = [(key, sl.start) for key, sl in self.o_iface.items()]
        tf = self.tip_frame
        kt = self.e_frame[tf]
        nQ = s.nQ
        zs = phase.z_slice

        i_e, i_dr = self.i_e, self.i_dr[tf]
        model, data, fid, nv = robot.model, robot.data, self.fids[tf], s.nv

        def call(t, x, q, v, Js, phi, o):
            e = phi[i_e:]
            x_d = v_d = a_d = None
            if phase.reference is not None:
                x_d, v_d, a_d = phase.reference.at(t)
            force_d = {name: ramp.at(t) for name, ramp in phase.forces.items()}
            forces = {name: float(o[i_fint + i]) for i, name in enumerate(names)}
            forces.update({key: float(o[k]) for key, k in ifaces})
            R_tip = pin.updateFramePlacement(model, data, fid).rotation
            J_ang = pin.getFrameJacobian(model, data, fid, _LWA).reshape(6, nv)[3:]
            inp = ControlInput(t, q, v, robot.H, robot.h, robot.gravity_torque(q) if ctl.needs_gravity else None,
                               e[kt:kt + 3].copy(), e[kt + 3:kt + 6].copy(), Js[tf], phi[i_dr:i_dr + 3], x_d, v_d, a_d,
                               forces,
                               force_d, normals, x[2 * nQ + zs.start: 2 * nQ + zs.stop], R_tip=R_tip, J_ang=J_ang)
            return ctl.command(inp)

        return call

    # ---- values the event functions read ----------------------------------------------
    def values(self, t: float, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(z = [Q̈, λ, w], o) at (t, x): the last call's when it was at this very state."""
        for lt, lx, z, o in reversed(self.ring):  # DOP853's dense output calls come after the step's last
            if lx is x and lt == t:
                return z, o
        self.rhs(t, x)
        return self.ring[3][2], self.ring[3][3]

    def gap(self, ci: int, t: float, x: np.ndarray) -> float:
        """Normal gap of contact ci [m]."""
        return float(self.values(t, x)[1][self.o_gap.start + ci])

    def normal_force(self, ci: int, t: float, x: np.ndarray) -> float:
        """Normal force of contact ci [N]: its row's λ when bonded or rigid, else its chain's interface force."""
        z, o = self.values(t, x)
        r = self.normal_row.get(ci)
        return float(z[self.system.nQ + r]) if r is not None else float(o[self.o_Fint.start + ci])

    def slip(self, ci: int, t: float, x: np.ndarray) -> np.ndarray:
        """Slip velocity of contact ci in its tangent coordinates [m/s]."""
        return self.values(t, x)[1][self.o_vt[self.system.contacts[ci].name]]

    def stick_force(self, ci: int, t: float, x: np.ndarray) -> np.ndarray:
        """Friction force of a sticking contact ci in tangent coordinates [N]."""
        z, _ = self.values(t, x)
        return z[self.stick_rows[ci]]

    # ---- self-check ---------------------------------------------------------------------
    def _check(self) -> None:
        """Agree with System.evaluate at the phase's reference states, or decline."""
        s = self.system
        rng = np.random.default_rng(7)
        x0, _ = s.initial_state()
        for x in (x0, x0 + 1e-3 * rng.normal(size=s.n)):
            t = self.phase.t_start + 0.0123
            ref = s.evaluate(t, x, self.modes, self.phase).xdot
            got = self.rhs(t, x.copy())
            scale = 1.0 + float(np.abs(ref).max())
            if not np.all(np.isfinite(got)) or float(np.abs(got - ref).max()) > CHECK_RTOL * scale:
                self.ok = False
                self.reason = f"disagrees with System.evaluate by {float(np.abs(got - ref).max()):.3g}"
                return
        self.ring[:] = [(None, None, None, None)] * 4
        self.singular = 0
