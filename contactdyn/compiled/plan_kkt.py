"""The compiled KKT system of one mode: constant parts, and the map P: φ ↦ [A, b, o].

Unknowns z = [Q̈, λ, w_f] with w_f the Cartesian force on each robot frame f [N]:

    M Q̈ − Cᵀ λ − Σ_f J_fᵀ w_f = [−h, f_rest]
    G Q̈ = −γ
    w_f = g_f (the affine outputs: stage, friction and task-law forces on frame f)

(:mod:`contactdyn.model.constraints` writes the same system plainly per call.) The rows and
columns are a·J_f + const, so A and b are *linear* in φ = [H, J_f, J̇q̇_f, h, (g), e]:
:meth:`CompiledKKT._build` measures P from :meth:`CompiledKKT._assemble` by unit probes
(:func:`~contactdyn.compiled.plan_probe.affine_map`), and a call costs one product P φ.
"""

from __future__ import annotations

import numpy as np

from ..model.friction import per_call_coefficient
from .plan_operational import CONTROLLER_LAW, TASK_PD_LAW, law_in_call
from .plan_probe import affine_map
from .plan_rhs import make_rhs

__all__ = ["CompiledKKT"]


class CompiledKKT:
    """Mixin of :class:`~contactdyn.compiled.rhsplan.ModePlan`: the KKT matrix's constant part and the map P."""

    # ---- compiled arrays ----------------------------------------------------------------
    def _build(self) -> None:
        """Constant parts of the KKT matrix, then the map P: φ ↦ [A, b, o] (see :meth:`_assemble`)."""
        s = self.system
        nQ, nv, nr, nf = s.nQ, s.nv, self.nr, len(self.fids)
        m = nQ + nr + 3 * nf
        A0 = np.zeros((m, m))
        A0[nv:nQ, nv:nQ] = np.diag(s.M_rest)  # bodies (with rotors through wheels), chain masses, motor shafts
        if s.drives.any_motor:
            A0[:nv, :nv] += np.diag(s._D)  # rotor inertias through rigid gears, n_s n_t J [kg·m²]
        for i in range(3 * nf):  # w = g: the Cartesian force on each frame, an unknown with a trivial row
            A0[nQ + nr + i, nQ + nr + i] = 1.0
        self.dyn_tilt = []  # 2-D sliding, or a speed-dependent friction law: column tilt computed per call
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
            mu = per_call_coefficient(c.friction)  # None: μ(|v_t|) per call
            if len(T) == 1 and mu is not None:
                d = np.asarray(self.modes[ci].slip, float)
                Qc[self.frame_of[c.fid], r] += mu * (d @ T)
                A0[:nQ, nQ + r] += mu * (d @ consts)
            else:
                self.dyn_tilt.append((r, ci, mu, T, consts[:, nv:], self.frame_of[c.fid]))
        self.m, self.A0, self.Qr, self.Qc = m, A0, Qr, Qc
        # φ = [H, (J_f), (J̇q̇_f), h, e]; e = [x, (p_f, ṗ_f), time terms, 1]
        self.i_J = [nv * nv + 3 * nv * f for f in range(nf)]
        self.i_dr = [nv * nv + 3 * nv * nf + 3 * f for f in range(nf)]
        self.i_h = nv * nv + 3 * nv * nf + 3 * nf
        #: φ carries g(q) after h: the affine task law's feedforward, or a task PD law's that the call computes
        #: (contactdyn.compiled.plan_operational)
        self.with_g = self.feedforward == "gravity" or (law_in_call(self.phase.controller) in (TASK_PD_LAW,
                                                                                                CONTROLLER_LAW)
                                                         and self.phase.controller.needs_gravity)
        self.i_e = self.i_h + nv * (2 if self.with_g else 1)
        P = affine_map(self._assemble, self.i_e + self.ne, columns=True)
        self.P = P
        self.PT = np.ascontiguousarray(P.T)
        self.coulomb_terms = []
        for ci in self.coulomb:
            c = s.contacts[ci]
            T, consts = self._tangent_terms(c)
            self.coulomb_terms.append((ci, self.o_Fint.start + ci, per_call_coefficient(c.friction), T, consts[:, nv:],
                                       self.frame_of[c.fid]))
        self.z_slice = slice(2 * nQ + self.phase.z_slice.start, 2 * nQ + self.phase.z_slice.stop)
        self.rhs = make_rhs(self)

    def _assemble(self, phi: np.ndarray) -> np.ndarray:
        """[A.ravel(), b, o] from φ, written out plainly (P is measured from this, all unit probes at once: φ may
        be a matrix of φ's as columns, and the result has one column each).

        Unknowns [Q̈, λ, w_f]: M Q̈ − Cᵀλ − Σ J_fᵀ w_f = [−h, f_rest];  G Q̈ = −γ;  w_f = g_f.
        """
        s = self.system
        nQ, nv, nr, m = s.nQ, s.nv, self.nr, self.m
        k = phi.shape[1:]  # () for one φ, (K,) for K of them
        H = phi[:nv * nv].reshape((nv, nv) + k)
        e = phi[self.i_e:]
        o = self.W.dot(e)
        A = np.zeros((m, m) + k)
        A += self.A0.reshape((m, m) + (1,) * len(k))
        b = np.zeros((m,) + k)
        A[:nv, :nv] += H
        b[:nv] = -phi[self.i_h:self.i_h + nv]
        if not self.law_via_drives:  # else the law's τ goes through the drives per call (plan_rhs)
            b[:nv] += self._feedforward_torque(phi, e)
        b[nv:nQ] = o[self.o_f]
        if self.o_fjoint is not None:  # the joints' damping and sliding friction (contactdyn.model.joint_friction)
            b[:nv] += o[self.o_fjoint]
        b[nQ:nQ + nr] = -o[self.o_gam]
        for f in range(len(self.fids)):
            J = phi[self.i_J[f]:self.i_J[f] + 3 * nv].reshape((3, nv) + k)
            dr = phi[self.i_dr[f]:self.i_dr[f] + 3]
            A[nQ:nQ + nr, :nv] += np.tensordot(self.Qr[f], J, 1)  # Q_r J
            A[:nv, nQ:nQ + nr] += np.swapaxes(np.tensordot(self.Qc[f], J, 1), 0, 1)  # (Q_c J)ᵀ
            A[:nv, nQ + nr + 3 * f:nQ + nr + 3 * f + 3] -= np.swapaxes(J, 0, 1)  # −Jᵀ
            b[nQ:nQ + nr] -= np.tensordot(self.Qr[f], dr, 1)
            b[nQ + nr + 3 * f:nQ + nr + 3 * f + 3] = o[self.o_g.start + 3 * f:self.o_g.start + 3 * f + 3]
        return np.concatenate([A.reshape((m * m,) + k), b, o])

    def _feedforward_torque(self, phi: np.ndarray, e: np.ndarray) -> np.ndarray:
        """The task PD law's joint-space terms: feedforward g(q) or h(q, q̇), and −k_dj q̇; a sampled law's held
        command (x's held slots, ``held``: contactdyn.laws.controllers.sampled)."""
        nv, nQ = self.system.nv, self.system.nQ
        tau = -self.kd_joint * e[nQ:nQ + nv]
        if self.feedforward == "gravity":
            tau = tau + phi[self.i_h + nv:self.i_h + 2 * nv]
        elif self.feedforward == "bias":
            tau = tau + phi[self.i_h:self.i_h + nv]
        if self.held is not None:
            tau = tau + e[self.held]
        return tau
