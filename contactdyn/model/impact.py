"""The impact map: plastic impacts at touch, sliding or jamming, and velocity projection.

When a contact whose touching makes a constraint row (rigid, or a chain whose surface
nodes are both solid) touches, velocities jump. Over Δt → 0 the momentum law
(eqs 27–31, 35–38) gives

    M (Q̇⁺ − Q̇⁻) = Cᵀ Λ,   G Q̇⁺ = 0

with every bond, stick and the new contact held at velocity level (Λ the impulses
[N·s], M and the rows as in :mod:`contactdyn.model.constraints`). With friction:

- sliding impact (eqs 27–29): the tip slides in its pre-impact slip direction d, the
  friction impulse is −μ_k FΔt d, folded into the normal column as at acceleration level;
- jamming (eqs 30–31): if the tangential velocity after the impact points against d the
  sliding assumption is wrong: zero tangential velocity, F_fΔt an unknown; if holding it
  needs more than μ_s FΔt (eqs 35–38) the tip slides where that impulse pushes.

The impact is unilateral: every other touching contact with a normal row (rigid, or a bonded chain's) holds
only while its normal impulse pushes, Λ_n ≥ 0; one that would pull lets go (``Impact.separated``: its gap opens
from the impact on), and one let go whose normal velocity after it would approach is held again, one at a time
(an active set: the plastic impact of several unilateral contacts, Λ_n ≥ 0, v_n⁺ ≥ 0, Λ_n v_n⁺ = 0). At a joint's
limit the impact's own contact is one of them too (it is not arriving: a tray that stops under a part lets it fly).

Every other touching contact with friction takes its friction impulse by the same law:

- one sliding into the impact (its slip beyond the stick band) slides in its own pre-impact slip
  direction d, its normal column tilted by −μ_k d (μ_k at that slip speed); if its tangential
  velocity after the impact points against d it jams instead (``Impact.jammed_too``): held by
  stick rows from then on, cone-checked as below;
- a stuck one holds through its stick rows only while its impulse stays in its own cone,
  |F_fΔt| ≤ μ_s FΔt (FΔt: its normal row's impulse; zero for a compliant normal, which carries
  no impulse): one that would leave it slides from the impact on, where its impulse pushed
  (``Impact.released``), its column tilted by −μ_k(0) d, and the impact is solved again.

A box landing flat while it slides thus loses μ_k v_n of its sliding speed at once, its four corners'
friction impulses −μ_k FΔt d each (``Impact.slid``).

A joint reaching its position limit is the same map with the limit's row among the rows
(:func:`limit_impact`), friction impulses at a sliding contact included. A joint stuck by dry friction
holds no impulse (its torque is bounded): it is not a row here (:mod:`contactdyn.model.joint_friction`).

The energy lost [J] is ½ Q̇⁻ᵀ M Q̇⁻ − ½ Q̇⁺ᵀ M Q̇⁺ ≥ 0. :func:`project_velocity` is the same
law without a new contact: the smallest kinetic-energy-norm change that keeps every
active constraint (used when a slide stops inside the stick band). Removing a residual slip
≤ v_ε costs at most ½ m v_ε², m the stick row's effective mass; :func:`singular_stick` tells a
projection that costs far more: a stick row (nearly) out of rank, where a tiny slip says nothing of rest.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..errors import SimulationError
from ..laws.failures import kinetic_coefficient
from .constraints import contact_row, impulse_solve, velocity_rows
from .contact import Contact, ContactMode
from .friction import direction_of, in_cone, slip_velocity

__all__ = ["Impact", "impact", "limit_impact", "project_velocity", "singular_stick", "SINGULAR_STICK"]


@dataclass
class Impact:
    """A plastic impact at touch: impulses [N·s] and velocities before and after."""

    t: float
    contact: str
    normal_impulse: float  #: FΔt
    friction_impulse: np.ndarray  #: F_fΔt per tangent
    jammed: bool
    energy_loss: float  #: [J]
    v_before: np.ndarray  #: Q̇⁻
    v_after: np.ndarray  #: Q̇⁺
    slip_before: np.ndarray = field(default_factory=lambda: np.zeros(0))  #: tangential velocity [m/s]
    slip_after: np.ndarray = field(default_factory=lambda: np.zeros(0))  #: tangential velocity [m/s]
    direction: np.ndarray = field(default_factory=lambda: np.zeros(0))  #: sliding direction d (0: none)
    row_impulses: dict = field(default_factory=dict)  #: (owner, kind, index) -> Λ of every held row [N·s or N·m·s]
    #: other contacts that were stuck and slide from the impact on (their stick impulse left the cone): name -> d
    released: dict = field(default_factory=dict)
    #: other contacts that let go at the impact (holding them would have pulled: Λ_n < 0), by name
    separated: tuple = ()
    #: other contacts that slid into the impact and jammed (their slip after it would have reversed), by name
    jammed_too: tuple = ()
    #: other contacts that slid through the impact: name -> their friction impulse −μ_k FΔt d per tangent [N·s]
    slid: dict = field(default_factory=dict)

#: [-] a normal impulse below −IMPULSE_TOL (1 + Σ|Λ|) pulls; a let-go contact's normal velocity below
#: −IMPULSE_TOL (1 + max|Q̇⁺|) approaches (rounding of the momentum law's solve)
IMPULSE_TOL = 1e-12


def impact(system, t: float, x: np.ndarray, modes: list[ContactMode], contact: Contact | None,
           limits: tuple = (), arriving: bool = True) -> tuple[np.ndarray, Impact]:
    """Velocity jump when ``contact`` touches (its mode already says touching), or when a joint
    reaches its position limit (its row the last of ``limits``; ``contact``: the sliding contact
    whose friction takes part, :func:`limit_impact`, or None).

    Momentum law over Δt → 0 (eqs 27–31, 35–38): M(Q̇⁺ − Q̇⁻) = Cᵀ Λ with every bond,
    stick, limit and the new contact holding at velocity level, G Q̇⁺ = 0 (``arriving``: ``contact`` is the one
    whose touch the impact is, never let go; False at a limit's impact, :func:`limit_impact`, whose contact lets go
    where holding it would pull). With friction the tip first slides in its pre-impact slip direction d
    (friction impulse −μ_k FΔt d, the normal column tilted as in eq. 27). If the tangential velocity after the
    impact points against d the assumption is wrong and the impact jams (eqs 30–31):
    zero tangential velocity, friction impulse F_fΔt an unknown. A tip that arrives
    without slip (|v_t| within the stick band) is tried jammed first; if holding it
    needs more than μ_s FΔt it slides where that impulse pushes.
    """
    nQ, nv = system.nQ, system.nv
    q, v = x[:nv], x[nQ:nQ + nv]
    system.robot.update(q, v)
    system.update_bodies(x)
    qd_minus = x[nQ:2 * nQ].copy()
    M = system.mass_matrix()
    name = contact.name if contact is not None else ""
    k = len(contact.tangents) if contact is not None else 0
    kin = system.kinematics(contact, x) if contact is not None else None
    #: the touching contacts' kinematics at x (fixed through the impact: only Q̇⁺ changes between its passes)
    kins = {j: system.kinematics(c, x) for j, (c, m) in enumerate(zip(system.contacts, modes, strict=True))
            if m.touching}
    vt_minus = slip_velocity(system, contact, kin, qd_minus) if k else np.zeros(0)
    held = list(modes)  #: the modes the impact holds: a stick its impulse would push out of the cone slides
    own = system.contacts.index(contact) if contact is not None else -1
    if k and modes[own].stuck:  # the impact's own stick: tried jammed, like a contact at rest
        held[own] = modes[own].with_(stuck=False)
    others = _sliding_into(system, kins, modes, contact, qd_minus, t)  #: index -> (d, μ_k) of the others sliding
    impulses: dict = {}

    def solve(slide=None, jam=False):  # slide: (d, μ) of the impact's own contact
        slides = {system.contacts[j].name: s for j, s in others.items() if held[j].touching and not held[j].stuck}
        if slide is not None:
            slides[name] = slide
        rows = velocity_rows(system, x, held, slides=slides, jam=contact if jam else None, limits=limits)
        z, _ = impulse_solve(system, M, rows, qd_minus)
        impulses.clear()
        impulses.update({m: float(z[nQ + j]) for j, m in enumerate(rows.meta)})
        P_n = impulses.get((name, "n", 0), 0.0)
        P_t = np.array([impulses.get((name, "t", i), 0.0) for i in range(k)])
        return z[:nQ], P_n, P_t

    released: dict[str, tuple[float, ...]] = {}
    touched = contact if arriving else None  #: the contact whose touch the impact is: never let go
    for _ in range(4 * len(system.contacts) + 4):
        own_held = contact is not None and held[own].touching  # (at a limit it may be let go: then no own branch)
        qd_plus, P_n, P_t, d, jammed = _own_contact(system, contact if own_held else None, kin, vt_minus, solve, t)
        j = _unilateral_change(system, kins, modes, held, touched, impulses, qd_plus)
        if j is not None:  # let go a pulling contact, or hold again one let go that would approach
            held[j] = modes[j] if not held[j].touching else held[j].separated()
            continue
        j = _reversed_slide(system, kins, held, others, released, qd_plus)
        if j is not None:  # its slide would reverse: it jams (held by its sticks, cone-checked next)
            held[j] = held[j].with_(stuck=True)
            continue
        outside = _sticks_outside_the_cone(system, held, contact, impulses)
        if not outside:
            break
        for j, push in outside:  # slide from rest where the impulse pushed, with the kinetic friction at rest
            c = system.contacts[j]
            held[j] = held[j].with_(stuck=False, slip=direction_of(push), from_rest=True)
            others[j] = (np.array(held[j].slip), kinetic_coefficient(c.friction, c.name, 0.0, t))
            released[c.name] = held[j].slip
    else:
        raise SimulationError(f"impact at t = {t:.9g} s: no set of the touching contacts holds with pushing "
                              "impulses only (the active set cycles)")
    separated, jammed_too, slid = _outcome(system, modes, held, others, impulses)
    x_new = x.copy()
    x_new[nQ:2 * nQ] = qd_plus
    energy_loss = 0.5 * float(qd_minus @ M @ qd_minus - qd_plus @ M @ qd_plus)
    vt_plus = slip_velocity(system, contact, kin, qd_plus) if k else np.zeros(0)
    return x_new, Impact(t, name, P_n, P_t, jammed, energy_loss, qd_minus, qd_plus, vt_minus, vt_plus, d,
                         dict(impulses), released, separated, jammed_too, slid)


def _outcome(system, modes, held, others, impulses) -> tuple[tuple, tuple, dict]:
    """(separated, jammed_too, slid) of a solved impact (``held``: its modes; ``others``: index -> (d, μ_k) of the
    contacts sliding into it besides its own): the contacts it let go, the others that jammed, and the friction
    impulses −μ_k FΔt d [N·s] of the others that slid through it, by name."""
    separated = tuple(c.name for c, m, h in zip(system.contacts, modes, held, strict=True)
                      if m.touching and not h.touching)
    jammed_too = tuple(system.contacts[j].name for j in others if held[j].stuck and not modes[j].stuck)
    slid = {system.contacts[j].name: (-mu * impulses.get((system.contacts[j].name, "n", 0), 0.0) * d).tolist()
            for j, (d, mu) in others.items() if held[j].touching and not held[j].stuck}
    return separated, jammed_too, slid


def _sliding_into(system, kins, modes, contact, qd_minus, t: float) -> dict[int, tuple[np.ndarray, float]]:
    """Index -> (d, μ_k) of every touching contact other than ``contact`` that slides into the impact with a normal
    row and friction: d its slip direction before it (tangent coordinates), μ_k at that slip speed; one within the
    stick band slides on untilted (its direction is not defined). A law's μ < 0 is its LawError at t [s]."""
    out = {}
    for j, (c, m) in enumerate(zip(system.contacts, modes, strict=True)):
        if (c is contact or not m.touching or m.stuck or c.friction is None or not len(c.tangents)
                or not c.normal.chain.bonded_when_touching):
            continue
        vt = slip_velocity(system, c, kins[j], qd_minus)
        speed = float(np.linalg.norm(vt))
        if speed > system.slip_band:
            out[j] = (vt / speed, kinetic_coefficient(c.friction, c.name, speed, t))
    return out


def _reversed_slide(system, kins, held, others, released, qd_plus) -> int | None:
    """The other contact sliding through the impact (not one it released) whose slip after it points most against
    its direction d (v_t⁺ · d < −v_ε, the stick band: the slide assumption is wrong, it jams), else None; one
    ending within the band slides on, to be decided at rest after the impact."""
    found, most = None, -system.slip_band
    for j, (d, _) in others.items():
        c = system.contacts[j]
        if not held[j].touching or held[j].stuck or c.name in released:
            continue
        along = float(slip_velocity(system, c, kins[j], qd_plus) @ d)
        if along < most:
            found, most = j, along
    return found


def _unilateral_change(system, kins, modes, held, contact, impulses, qd_plus) -> int | None:
    """The contact whose normal the impact must let go or hold again, else None: the most pulling other touching
    contact with a normal row (its impulse Λ_n < 0); else the most approaching one let go (v_n⁺ < 0). A bonded
    contact never lets go."""
    pulling = -IMPULSE_TOL * (1.0 + sum(abs(v) for v in impulses.values()))
    found = None
    for j, (c, m) in enumerate(zip(system.contacts, held, strict=True)):
        if c is contact or not m.touching or c.spec.bonded or not c.normal.chain.bonded_when_touching:
            continue
        P_n = impulses.get((c.name, "n", 0), 0.0)
        if P_n < pulling:
            pulling, found = P_n, j
    if found is not None:
        return found
    approaching = -IMPULSE_TOL * (1.0 + float(np.abs(qd_plus).max()))
    for j, (m, h) in enumerate(zip(modes, held, strict=True)):
        if m.touching and not h.touching:
            c = system.contacts[j]
            kin = kins[j]
            v_n = float(contact_row(system, c, kin.normal, kin) @ qd_plus)
            if v_n < approaching:
                approaching, found = v_n, j
    return found


def _own_contact(system, contact, kin, vt_minus, solve, t: float):
    """The impact's own contact: (Q̇⁺, P_n, P_t, d, jammed) by the sliding or jamming branch (see impact); a law's μ < 0
    is its LawError at t [s]."""
    fr, k = (contact.friction, len(contact.tangents)) if contact is not None else (None, 0)
    d = np.zeros(k)
    if fr is None or not k:
        qd_plus, P_n, P_t = solve()
        return qd_plus, P_n, P_t, d, False
    speed = float(np.linalg.norm(vt_minus))
    jammed = True
    if speed > system.slip_band:
        d = vt_minus / speed
        mu = kinetic_coefficient(fr, contact.name, speed, t)  # the kinetic coefficient at the slip speed before
        qd_plus, P_n, _ = solve(slide=(d, mu))
        P_t = -mu * P_n * d
        jammed = float(slip_velocity(system, contact, kin, qd_plus) @ d) < 0.0
    if jammed:
        qd_plus, P_n, P_t = solve(jam=True)
        if not in_cone(P_t, P_n, fr.mu_s):  # holding needs more than the cone gives: slide where the impulse pushes
            d = -P_t / float(np.linalg.norm(P_t))
            mu = kinetic_coefficient(fr, contact.name, 0.0, t)  # sliding from rest
            qd_plus, P_n, _ = solve(slide=(d, mu))
            P_t = -mu * P_n * d
            jammed = False
    return qd_plus, P_n, P_t, d, jammed


def _sticks_outside_the_cone(system, held, contact, impulses) -> list[tuple[int, np.ndarray]]:
    """The other stuck contacts whose stick impulse |P_t| exceeds μ_s P_n (P_n: their normal row's impulse, 0
    for a compliant normal, which carries no impulse), with the direction the impulse pushes (−P_t)."""
    out = []
    for j, (c, m) in enumerate(zip(system.contacts, held, strict=True)):
        if c is contact or not m.touching or not m.stuck:
            continue
        P_t = np.array([impulses.get((c.name, "t", i), 0.0) for i in range(len(c.tangents))])
        if not in_cone(P_t, impulses.get((c.name, "n", 0), 0.0), c.friction.mu_s):
            out.append((j, -P_t))
    return out


def limit_impact(system, t: float, x: np.ndarray, modes: list[ContactMode], limits: tuple
                 ) -> tuple[np.ndarray, Impact, float]:
    """A joint reaching its position limit, its row (i, side) the last of ``limits``: (x⁺, the impact,
    the limit's impulse Λ [N·m·s or N·s]).

    The same momentum law as at a touch (:func:`impact`) with the limit row among the rows. The
    impact's contact is the first touching one with a normal row (rigid or bonded: its normal
    impulse is finite), a sliding one with friction first: it takes its friction impulse by the
    same sliding/jamming branch (the other sliding contacts too, see :func:`impact`); a sticking one
    holds through its stick rows. It lets go where holding it would pull, as the others do (``Impact.separated``
    names it). Without one, the contact is "".
    """
    rowed = [(c, m) for c, m in zip(system.contacts, modes, strict=True)
             if m.touching and c.normal.chain.bonded_when_touching]
    sliding = [c for c, m in rowed if not m.stuck and c.friction is not None and len(c.tangents)]
    contact = sliding[0] if sliding else rowed[0][0] if rowed else None
    x_new, imp = impact(system, t, x, modes, contact, limits, arriving=False)
    i = limits[-1][0]
    return x_new, imp, imp.row_impulses[(system.limits.by_index[i].name, "limit", i)]


def project_velocity(system, x: np.ndarray, modes: list[ContactMode], limits: tuple = (), joint_modes: tuple = ()
                     ) -> np.ndarray:
    """x with Q̇ moved onto every active velocity constraint (bonds, rigid contacts, sticks, the joints pressing
    on ``limits``, the joints stuck by dry friction in ``joint_modes``).

    The smallest change in the kinetic-energy norm, M ΔQ̇ = Gᵀ Λ, G Q̇⁺ = 0: an impulse
    that removes what the constraints forbid (used when a slide stops inside the stick
    band, where the residual slip is at most ``solver.stick_velocity``).
    """
    nQ, nv = system.nQ, system.nv
    system.robot.update(x[:nv], x[nQ:nQ + nv])
    rows = velocity_rows(system, x, modes, limits=limits, joint_modes=joint_modes)
    if not rows:
        return x
    system.update_bodies(x)
    M = system.mass_matrix()
    z, _ = impulse_solve(system, M, rows, x[nQ:2 * nQ])
    x_new = x.copy()
    x_new[nQ:2 * nQ] = z[:nQ]
    return x_new


#: [-] a stick's velocity projection that removes more than this many times ½ m v_ε² of kinetic energy (m [kg]: the
#: contact point's lightest effective mass, v_ε the stick band) is at a singular stick row (:func:`singular_stick`)
SINGULAR_STICK = 1e6


def singular_stick(system, c: Contact, x: np.ndarray, x_stuck: np.ndarray, kin) -> bool:
    """Is the projection ``x`` -> ``x_stuck`` (:func:`project_velocity` with contact c stuck, its slip ≤ v_ε at x) at
    a singular stick row: does it remove more than ``SINGULAR_STICK`` × ½ m v_ε² of kinetic energy, m = 1/λ_max(J
    M⁻¹ Jᵀ) [kg] the lightest effective mass of c's relative motion (J: its rows along the three axes)? ``kin``: c's
    kinematics at x, the robot and the bodies updated there (the caller's, which reads them too).

    The projection is M-orthogonal: it removes ½ ΔQ̇ᵀ M ΔQ̇ = ½ m_t v_t², m_t the stick row's effective mass on the
    motion the other rows allow. At a regular pose m_t is of the order of m (a box's mass; an arm's, scaled by its
    leverage) and the loss ~1e-18 J per kg at the default v_ε. Where the row nearly vanishes on that motion (an arm's
    tip through full stretch on a floor: its tangent row J_x ~ 0), m_t ~ 1/σ² and removing a slip of 1e-9 m/s stops
    the whole arm: its slip is small because its row is, not because it came to rest."""
    nQ = system.nQ
    M = system.mass_matrix()
    dqd = x[nQ:2 * nQ] - x_stuck[nQ:2 * nQ]
    removed = 0.5 * float(dqd @ M @ dqd)  # [J] (= ½ Q̇ᵀ M Q̇ − ½ Q̇⁺ᵀ M Q̇⁺, without their cancellation)
    J = np.array([contact_row(system, c, u, kin) for u in np.eye(3)])
    lightest = float(np.linalg.eigvalsh(J @ np.linalg.solve(M, J.T))[-1])  # [1/kg]
    return removed * lightest > SINGULAR_STICK * 0.5 * system.slip_band ** 2
