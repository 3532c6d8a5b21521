"""The right-hand side compiled for one (modes, phase): the integrator's fast path.

:meth:`System.evaluate` assembles everything per call (dicts, row lists, diagnostics).
Within one smooth phase the modes are fixed, and then almost everything except the
robot's own terms (H, h, J, J̇q̇) is *affine* in a short vector

    e = [x, p_f, ṗ_f (per robot frame used), time terms, 1]

chain stage forces and junction rates, slip velocities, gaps, servo forces, viscous
friction and the plain task-space PD law. A :class:`ModePlan` measures that affine map
``o = W e`` once, by probing the system's own code (:func:`~contactdyn.model.chain_forces.chain_forces` & co.) at unit
vectors, so it is the same model by construction; the constraint rows are ``a·J`` plus
constants, collected once. A call then costs Pinocchio's terms, one product ``W e``,
one product for the rows and one small linear solve. What is not affine stays explicit:
Coulomb friction ``−μ max(F_n, 0) d``, 2-D slip directions (a slide launching from rest:
its direction solved per call on the plan's own KKT system), other controllers.
The 2-D reference directions r are data the call reads, not part of the plan
(:func:`structure`, :meth:`ModePlan.use`): every ``turn`` event of a slide reuses its plan.

A plan checks itself against :meth:`System.evaluate` when it is built (two states) and
declines (``plan.ok`` false, ``plan.reason`` says why) where it cannot represent the
system — the energy audit, non-linear stage laws, parts it does not know — and the
caller falls back to :meth:`System.evaluate`.

Where the pieces are: the probes and the layout of e and o in :mod:`contactdyn.compiled.plan_probe`,
the compiled KKT system in :mod:`contactdyn.compiled.plan_kkt`, the per-call function in
:mod:`contactdyn.compiled.plan_rhs`, the output samples in :mod:`contactdyn.compiled.samples`; this module
holds the plan itself, what it declines, the values the events read, and its self-check.
"""

from __future__ import annotations

import math
import pickle
import weakref
from collections import deque

import numpy as np

from ..model.contact import ContactMode, structure
from ..model.paths import UNDECLARED, disagreement, mode_gap
from .plan_kkt import CompiledKKT
from .plan_probe import ProbedModel, affine_map
from .plan_rhs import controller_call, make_rhs
from .samples import Samples, plan_samples

__all__ = ["ModePlan", "Samples", "cached_plan", "structure", "affine_map"]  # Samples: from contactdyn.compiled.samples

_NO_CALL = (None, None, None, None)  #: a ring entry before any call


_PLANS: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()  #: system -> {key: ModePlan}


def cached_plan(system, modes: list[ContactMode], phase) -> ModePlan:
    """The plan of (modes, phase), compiled once per system and set to run with ``modes``: a repeated
    run of the same system (benchmarks, sweeps) and every turn of a 2-D slide reuse it. The key is the
    modes' :func:`structure` and the phase's content (index, start, reference, set-points), not the
    Phase object, which every run makes anew."""
    content = pickle.dumps((phase.index, phase.t_start, phase.spec.name, phase.reference, phase.forces,
                            getattr(phase, "carrier", None), getattr(phase, "limits", ()),
                            getattr(phase, "joint_modes", ())))
    key = (structure(modes), content)
    plans = _PLANS.setdefault(system, {})
    plan = plans.get(key)
    if plan is None:
        plan = plans[key] = ModePlan(system, modes, phase)
    plan.use(modes)
    return plan


class ModePlan(ProbedModel, CompiledKKT):
    """The compiled right-hand side of one (modes, phase); see the module docstring."""

    def __init__(self, system, modes: list[ContactMode], phase):
        self.system, self.modes, self.phase = system, list(modes), phase
        self.ok, self.reason = False, ""
        #: the last four calls' (t, x, z, o), the latest at [3] (a call appends; the oldest drops out)
        self.ring: deque[tuple] = deque([_NO_CALL] * 4, maxlen=4)
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
        """Why this plan declines: a gap its parts declared at load (contactdyn.model.paths), or one they did not."""
        s = self.system
        reason = mode_gap(s, self.modes, self.phase)
        if reason:
            return reason
        expected_nQ = s.nv + len(s.body_names) + len(s.mass_labels) + s.drives.n_motor_coords
        if s.nQ != expected_nQ:
            return (f"{UNDECLARED}coordinates the plan does not know ({s.nQ - expected_nQ} beyond robot, bodies, "
                    "masses, motors)")
        return ""


    def use(self, modes: list[ContactMode]) -> None:
        """Run with these modes from now on: the same :func:`structure`, their own 2-D reference
        directions r. ``self.rhs`` becomes a call bound to them (a few µs to make); the calls made
        for earlier modes keep theirs: a finished segment's dense output calls its own later."""
        if modes == self.modes:
            return
        if structure(modes) != structure(self.modes):
            raise ValueError(f"a plan runs modes of its own structure only; built for {self.modes}, given {modes}")
        self.modes = list(modes)
        if self.ok:  # a declined plan has no call: its modes run on System.evaluate
            self.rhs = make_rhs(self)
            self.ring.extend([_NO_CALL] * 4)

    # ---- output samples, all at once (contactdyn.compiled.samples) ----------------------------------
    def samples(self, ts: np.ndarray, X: np.ndarray, modes: list[ContactMode] | None = None) -> Samples:
        """Diagnostics at the states X[k] (times ts[k]) of this mode (run with ``modes`` if given), as arrays."""
        if modes is not None:
            self.use(modes)
        return plan_samples(self, ts, X)

    def _controller_call(self):
        """Per-call ControlInput for a controller without an affine tip-force law (:func:`plan_rhs.controller_call`)."""
        return controller_call(self)

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
    kernel = None  #: the call's compiled kernel, if it has one (set by plan_rhs.make_rhs)
    python_command = False  #: the controller's command is called in Python per call (plan_rhs.controller_call)

    @property
    def last(self) -> tuple:
        """(t, x, z, o) of the latest call."""
        return self.ring[3]


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
        return self.values(t, x)[1][self.vt_slices[ci]]

    def cone_margin(self, ci: int, mu_s: float, t: float, x: np.ndarray) -> float:
        """μ_s F − |F_f| [N] of a sticking contact ci: the ``slip`` event's function."""
        F_f = self.stick_force(ci, t, x)
        return mu_s * self.normal_force(ci, t, x) - math.sqrt(float(F_f @ F_f))

    def limit_torque(self, t: float, x: np.ndarray) -> dict[int, float]:
        """Torques [N·m or N] of the joints pressing on a limit, by joint coordinate (the ``release`` event's)."""
        z, _ = self.values(t, x)
        return {i: float(z[k]) for i, k in self.limit_rows.items()}

    def joint_hold(self, t: float, x: np.ndarray) -> dict[int, float]:
        """Holding torques [N·m or N] of the joints stuck by dry friction, by joint coordinate (``joint_slip``'s)."""
        z, _ = self.values(t, x)
        return {i: float(z[k]) for i, k in self.joint_rows.items()}

    def stick_force(self, ci: int, t: float, x: np.ndarray) -> np.ndarray:
        """Friction force of a sticking contact ci in tangent coordinates [N]."""
        z, _ = self.values(t, x)
        return z[self.stick_rows[ci]]

    # ---- self-check ---------------------------------------------------------------------
    def _check(self) -> None:
        """Agree with System.evaluate at the run's initial state and a perturbation of it, or decline."""
        x0, _ = self.system.initial_state()
        self.check_at(self.phase.t_start + 0.0123, x0)

    def check_at(self, t: float, x: np.ndarray) -> None:
        """Agree with System.evaluate at (t, x) — where a run starts this mode — and at a perturbation of x, or
        decline (``ok`` false, an undeclared reason): a law changed on one path only cannot pass unseen
        (:func:`~contactdyn.model.paths.disagreement`: to CHECK_RTOL × (1 + each rate's largest magnitude))."""
        if not self.ok:
            return
        reason = disagreement(self.system, self.modes, self.phase, self.rhs, t, x)
        if reason:
            self.ok, self.reason = False, reason
        self.ring.extend([_NO_CALL] * 4)
        self.singular = 0
