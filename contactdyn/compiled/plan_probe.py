"""Reading the model off by unit probes: the affine part of a mode's right-hand side.

Within one smooth phase (modes fixed) almost everything except the robot's own terms
(H, h, J, J̇q̇) is *affine* in a short vector

    e = [x, p_f, ṗ_f (per robot frame f used), time terms, 1]

chain stage forces and junction rates, slip velocities, gaps, servo forces, viscous
friction and the plain task-space PD law. :meth:`ProbedModel._measure` reads that map
``o = W e`` off the readable model's own functions — :func:`~contactdyn.model.chain_forces.chain_forces`,
the friction rows, the servo law, the controller's :class:`~contactdyn.laws.controllers.base.TipForceLaw` —
by evaluating them at unit vectors e_k (:func:`affine_map`), and checks it at random e:
a law that is not affine (Hunt–Crossley) is refused there. The constraint rows are
``a·J_f + const`` with γ = a·J̇q̇ + Baumgarte terms, read off the same way (:meth:`ProbedModel._rows`);
a joint pressing on its position limit is one more row, e_i with its Baumgarte γ, written by
:meth:`~contactdyn.model.limits.JointLimits.add_rows` as in the readable model; a joint stuck by dry friction
too (:meth:`~contactdyn.model.joint_friction.JointFriction.add_rows`), and the joints' damping and sliding
friction are an output (``f_joint``) of :meth:`~contactdyn.model.joint_friction.JointFriction.torques`.

So a stage law, a servo or a tip-force law is written once, in the readable model, and
the compiled plan (:mod:`contactdyn.compiled.rhsplan`) gets it by construction.
"""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np

from ..laws.controllers.sampled import SampledController
from ..model.chain_forces import chain_forces
from ..model.constraints import Rows
from ..model.contact import Kinematics
from ..model.paths import UNDECLARED

__all__ = ["affine_map", "ProbedModel"]


def affine_map(f, n: int, columns: bool = False) -> np.ndarray:
    """Matrix A with f(e) = A e for an affine f of e = [e₁ … e₍ₙ₋₁₎, 1], read off by unit probes.

    ``columns``: f takes the probes at once, as the columns of a matrix, and returns one column each."""
    if columns:
        E = np.eye(n)
        E[-1] = 1.0  # column k: e_k + the trailing 1; the last: the trailing 1 alone
        F = np.asarray(f(E))
        A = F - F[:, -1:]
        A[:, -1] = F[:, -1]
        return A
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


class ProbedModel:
    """Mixin of :class:`~contactdyn.compiled.rhsplan.ModePlan`: the layout of e and o, the probes, the rows."""

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
        # motors, a force-reading law, a carried reference: the command runs through the drives per call
        self.drives_per_call = s.drives.any_motor or ctl.uses_forces or phase.carrier is not None
        reads = ctl.uses_forces or phase.carrier is not None or ctl.outputs == "voltage"
        law = ctl.tip_force_law() if hasattr(ctl, "tip_force_law") and not reads else None
        self.affine_ctl = law is not None
        #: a sampled law's held command (contactdyn.laws.controllers.sampled): the state's slots (x's), read as a
        #: term of the feedforward (plan_kkt._feedforward_torque), affine in e; None for a continuous law
        hold = ctl.held if isinstance(ctl, SampledController) else None
        self.held = None if hold is None else slice(2 * s.nQ + phase.z_slice.start + hold.start,
                                                    2 * s.nQ + phase.z_slice.start + hold.stop)
        #: an affine task law (or a held command) whose τ = J_tipᵀ g_ctl + feedforward goes through motors
        #: (plan_drives), not onto w
        self.law_via_drives = (self.affine_ctl or self.held is not None) and self.drives_per_call
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
        self.o_gctl = out.add("g_ctl", 3)
        self.o_Fint = out.add("F_int", len(s.contacts))
        self.o_gap = out.add("gap", len(s.contacts))
        self.o_vt = {c.name: out.add(f"vt.{c.name}", len(c.tangents)) for c in s.contacts}
        self.vt_slices = [self.o_vt[c.name] for c in s.contacts]  #: the same, by contact index
        self.o_visc = {c.name: out.add(f"visc.{c.name}", len(c.tangents)) for c in s.contacts}
        self.o_iface = {f"{c.name}.{dc.label}": out.add(f"iface.{c.name}.{dc.label}")
                        for c in s.contacts for dc in c.tangent_chains}
        self.o_body = out.add("body_force", len(s.body_names))
        self.o_stage = {label: out.add(f"stage.{label}", 3) for label in s.stage_labels}
        #: the joints' damping and sliding friction [N·m or N] (contactdyn.model.joint_friction), None without any
        self.o_fjoint = out.add("f_joint", nv) if s.joint_friction.any else None
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
            p_env, v_env = c.surface(x, nQ)
            kin = Kinematics(p_tip, v_tip, J0, d0, p_env, v_env)
            tip_F, row, gamma, F_int, gap = chain_forces(s, c, c.normal, mode.touching, 0.0, kin, x, f, ydot, ev, True,
                                                         mode.relaxing)
            g[j] += tip_F * c.normal.u
            o[self.o_Fint.start + ci] = F_int
            o[self.o_gap.start + ci] = gap
            for i, dc in enumerate(c.tangent_chains):
                tF, trow, tgamma, tint, _ = chain_forces(s, c, dc, mode.touching, mode.offsets[i], kin, x, f, ydot,
                                                         ev, True, mode.relaxing)
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
        limit_rows = Rows()  # joints pressing on a position limit: the readable model's own rows (model.limits)
        s.limits.add_rows(self.phase.limits, x, nQ, limit_rows, s.stabilization)
        for row, gamma, (_, _, i) in zip(limit_rows.rows, limit_rows.gammas, limit_rows.meta, strict=True):
            rows.append(("limit", -1, i, row, gamma))
        if self.o_fjoint is not None:
            self._joint_terms(x, o, rows)
        for idx, v_ref, gain in s.servo:
            F = gain * (v_ref - x[nQ + idx])
            if not self.drives_per_call:  # else the servo is a drive command (plan_drives)
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
            if not self.law_via_drives:
                g[self.tip_frame] += g_ctl
            o[self.o_gctl] = g_ctl
        o[self.o_f] = f[nv:]
        o[self.o_y] = ydot
        o[self.o_g] = g.ravel()
        for label, sl in self.o_stage.items():
            o[sl] = ev.stages.get(label, (0.0, 0.0, 0.0))
        return o, rows

    def _joint_terms(self, x: np.ndarray, o: np.ndarray, rows: list) -> None:
        """Stuck joints' rows into ``rows``, the damping and sliding friction into o: the readable model's own
        (:mod:`contactdyn.model.joint_friction`)."""
        s, phase = self.system, self.phase
        jf, joint_rows = s.joint_friction, Rows()
        jf.add_rows(phase.joint_modes, phase.limits, x, s.nQ, joint_rows, s.stabilization)
        for row, gamma, (_, _, i) in zip(joint_rows.rows, joint_rows.gammas, joint_rows.meta, strict=True):
            rows.append(("joint", -1, i, row, gamma))
        o[self.o_fjoint] = jf.torques(phase.joint_modes, x, s.nQ, s.nv)

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
                self.reason = f"{UNDECLARED}a part that is not affine (its declared fast_path_gap is empty)"
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
            if kind in ("limit", "joint"):  # joint coordinate i on its limit or stuck: no Cartesian part (a = 0)
                self.rows.append(SimpleNamespace(kind=kind, contact=-1, index=i, a=a, const=np.array(const, float),
                                                 frame=0, label=None, owner=s.robot.joint_names[i]))
                continue
            c = s.contacts[ci]
            self.rows.append(SimpleNamespace(kind=kind, contact=ci, index=i, a=a, const=np.array(const, float),
                                             frame=self.frame_of[c.fid], label=c.tangent_chains[i].label
                                             if kind == "chain" else None, owner=c.name))
        self.nr = len(self.rows)
        nQ = s.nQ
        self.normal_row = {row.contact: r for r, row in enumerate(self.rows) if row.kind == "normal"}
        self.stick_rows: dict[int, list[int]] = {}
        for r, row in enumerate(self.rows):
            if row.kind == "stick":
                self.stick_rows.setdefault(row.contact, []).append(nQ + r)
        #: joint coordinate -> index in z of its limit torque [N·m or N] (joints pressing on a limit)
        self.limit_rows = {row.index: nQ + r for r, row in enumerate(self.rows) if row.kind == "limit"}
        #: joint coordinate -> index in z of its holding torque [N·m or N] (joints stuck by dry friction)
        self.joint_rows = {row.index: nQ + r for r, row in enumerate(self.rows) if row.kind == "joint"}
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
