"""Coulomb friction: slip direction, stick/slip decisions, the cone, the stick band, 2-D launches.

The paper's friction (Part II, eqs 21–24; 1-D, eqs 43–44) at a touching contact with
tangent directions T (one or two unit vectors) and slip velocity v_t = T (v_tip − v_env)
[m/s]:

- sliding: F_f = −μ_k F d − c v_t [N], F the normal force [N] (never pulling: max(F, 0)),
  d the sliding direction, c the viscous coefficient [N·s/m] (the call's:
  :mod:`contactdyn.model.pipeline.contacts`).
  When F is an unknown of the constraint solve (a rigid or bonded contact), the friction
  force is folded into the normal row's force column, C = G_n − μ_k d·G_T (eq. 27's tilt);
- sticking: zero tangential slip is a constraint row per tangent whose force F_f is an
  unknown of the call's KKT solve, held while it stays in the cone
  |F_f| ≤ μ_s F (:func:`in_cone`, with a relative slack ``CONE_TOL`` for round-off).

Coulomb's sgn is never smoothed. Mode switches are located events
(:mod:`contactdyn.hybrid.events`) decided in :mod:`contactdyn.hybrid.transitions`. The stick band v_ε
(``solver.stick_velocity`` [m/s]) separates "at rest" from "sliding": a slide keeps its
reference direction r until v_t·r > v_ε and stops when it falls back to v_ε.

A 2-D slip from rest starts where it accelerates: d with a_t(d) = λ d, λ ≥ 0, found by Newton on the angle in
the call (:mod:`contactdyn.model.pipeline.launch`; :func:`launching` says which contacts launch).
"""

from __future__ import annotations

import numpy as np

from .contact import Contact, ContactMode, Kinematics

__all__ = ["CONE_TOL", "FORCE_ABS_TOL", "SLIP_ALARM", "in_cone", "cone_slack", "direction_of", "initial_slip",
           "slip_velocity", "slip_acceleration", "launching"]

CONE_TOL = 1e-10  #: relative slack of the friction-cone tests |F_f| ≤ μ_s F (round-off of the solves)
FORCE_ABS_TOL = 1e-12  #: [N] absolute slack of the same tests
#: [-] a located slip of a hold is real if the hold is within this of its limit there, else a false alarm: a stuck
#: contact's |F_f| ≥ (1 − this) μ_s F (hybrid.transitions), a stuck joint's |λ| ≥ (1 − this) τ_s
#: (model.joint_friction). A hold is a difference of the call's largest forces: through stiff springs it moves in steps
#: of ~1e-9 of its limit (case 3's axis at 0.05 N: 3e-9), so a tighter band takes the crossing's own located instant
#: for a false alarm, again and again at one instant.
SLIP_ALARM = 1e-6


def in_cone(F_f: np.ndarray, F_n: float, mu_s: float, strictly: bool = False) -> bool:
    """|F_f| ≤ μ_s F within round-off (a pulling contact holds nothing); ``strictly``: inside by that slack,
    |F_f| ≤ μ_s F (1 − CONE_TOL) − FORCE_ABS_TOL, the test a slide at rest must pass to stick. The band between the
    two is hysteresis: a stick at the cone's very edge whose load leaves the cone (a grip opening with μ_s = μ_k) is
    released by the lenient test and not stuck again by the strict one at the same instant (they would chatter)."""
    if strictly:
        return float(np.linalg.norm(F_f)) <= mu_s * max(F_n, 0.0) * (1.0 - CONE_TOL) - FORCE_ABS_TOL
    return float(np.linalg.norm(F_f)) <= mu_s * max(F_n, 0.0) * (1.0 + CONE_TOL) + FORCE_ABS_TOL


def cone_slack(F_n: float, mu_s: float) -> float:
    """[N] The round-off slack of :func:`in_cone` at normal force F_n [N]: μ_s F CONE_TOL + FORCE_ABS_TOL."""
    return mu_s * max(F_n, 0.0) * CONE_TOL + FORCE_ABS_TOL


def direction_of(vec: np.ndarray) -> tuple[float, ...]:
    """A mode's sliding direction along ``vec`` in tangent coordinates (1-D: ±1; 2-D: unit, (1, 0) for zero)."""
    if len(vec) == 1:
        return (1.0 if vec[0] >= 0.0 else -1.0,)
    norm = float(np.linalg.norm(vec))
    return tuple(vec / norm) if norm > 0 else (1.0, 0.0)


def launching(mode: ContactMode) -> bool:
    """A touching 2-D slide started from rest whose direction is still to be solved (:mod:`.pipeline.launch`)."""
    return mode.from_rest and len(mode.slip) == 2 and mode.touching and not mode.stuck


def slip_velocity(system, c: Contact, kin: Kinematics, qd: np.ndarray | None = None) -> np.ndarray:
    """Tangential tip–environment velocity [m/s] in tangent coordinates (at Q̇ = qd if given): along the state's
    tangents, relative to the surface's material point (:class:`~contactdyn.model.contact.Kinematics`)."""
    if qd is None:
        return kin.tangents @ (kin.v_tip - kin.v_env)
    v_touch, v_env = c.rates(qd)
    v_tip = kin.J @ qd[: system.nv] + kin.column_rates(qd)
    return kin.tangents @ ((v_tip if v_touch is None else v_tip + v_touch) - v_env)


def slip_acceleration(system, c: Contact, kin: Kinematics, qdd: np.ndarray) -> np.ndarray:
    """Rate of the slip velocity [m/s²] in tangent coordinates at Q̈ = qdd: T(J Q̈ + J̇q̇) with the bodies' parts,
    what a stick row holds at 0 (its G_t Q̈ + γ_t). Where the slip goes once it leaves a stop: a slide through a pose
    where its tangent row vanishes (an arm through full stretch) reverses by its kinematics (J̇q̇), not its friction."""
    return slip_velocity(system, c, kin, qdd) + kin.tangents @ kin.drift


def initial_slip(c: Contact, kin: Kinematics) -> tuple[float, ...]:
    """Reference sliding direction of a contact at the start: its slip velocity's (1-D: its sign)."""
    if c.friction is None:
        return ()
    vt = kin.tangents @ (kin.v_tip - kin.v_env)
    norm = float(np.linalg.norm(vt))
    if norm == 0.0:
        return tuple(np.eye(len(vt))[0]) if len(vt) else ()
    return tuple(np.sign(vt)) if len(vt) == 1 else tuple(vt / norm)


