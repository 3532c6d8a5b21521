"""Coulomb friction: slip direction, stick/slip decisions, the cone, the stick band, 2-D launches.

The paper's friction (Part II, eqs 21–24; 1-D, eqs 43–44) at a touching contact with
tangent directions T (one or two unit vectors) and slip velocity v_t = T (v_tip − v_env)
[m/s]:

- sliding: F_f = −μ_k F d − c v_t [N], F the normal force [N] (never pulling: max(F, 0)),
  d the sliding direction (:func:`slip_direction`), c the viscous coefficient [N·s/m].
  When F is an unknown of the constraint solve (a rigid or bonded contact), the friction
  force is folded into the normal row's force column, C = G_n − μ_k d·G_T (eq. 27's tilt);
- sticking: zero tangential slip is a constraint row per tangent whose force F_f is an
  unknown (:mod:`contactdyn.model.constraints`), held while it stays in the cone
  |F_f| ≤ μ_s F (:func:`in_cone`, with a relative slack ``CONE_TOL`` for round-off).

Coulomb's sgn is never smoothed. Mode switches are located events
(:mod:`contactdyn.hybrid.events`) decided in :mod:`contactdyn.hybrid.transitions`. The stick band v_ε
(``solver.stick_velocity`` [m/s]) separates "at rest" from "sliding": a slide keeps its
reference direction r until v_t·r > v_ε and stops when it falls back to v_ε.

A 2-D slip from rest starts where it accelerates (:func:`launch_directions`): d with
a_t(d) = λ d, λ ≥ 0, found by Newton on the angle.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np

from .contact import Contact, ContactMode, Kinematics

if TYPE_CHECKING:
    from .constraints import Rows
    from .phases import Phase

__all__ = ["CONE_TOL", "FORCE_ABS_TOL", "in_cone", "cone_slack", "direction_of", "initial_slip", "slip_direction",
           "slip_velocity", "slip_acceleration", "kinetic_coefficient", "launching", "launch_directions",
           "launch_directions_at", "friction_terms"]

CONE_TOL = 1e-10  #: relative slack of the friction-cone tests |F_f| ≤ μ_s F (round-off of the solves)
FORCE_ABS_TOL = 1e-12  #: [N] absolute slack of the same tests


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


def slip_direction(system, vt: np.ndarray, mode: ContactMode) -> np.ndarray:
    """Unit sliding direction d in tangent coordinates (1-D: ±1).

    The slip velocity's own direction v_t/|v_t| (eqs 21–24; 1-D: sgn, eqs 43–44)
    while it points ahead of the mode's reference r (v_t·r > v_ε, the stick band);
    otherwise r itself. The segment ends at a ``stop`` event where v_t·r falls to v_ε,
    and 2-D ``turn`` events keep r within 60° of v_t, so the second branch only serves
    a slip just started from rest (|v_t| ≤ v_ε) and the integrator's trial stages past
    a stop: the force stays continuous across the stop instead of flipping there,
    which would make the step size collapse. Never a smoothed sgn.
    """
    r = mode.slip
    if len(r) == 2:  # 1-D: sgn v_t is r itself whenever v_t·r > v_ε, so r either way
        v = vt.tolist()  # the test in Python floats: ~1 µs less per call than numpy's on a 2-vector
        if v[0] * r[0] + v[1] * r[1] > system.slip_band:  # v_t·r [m/s]
            return vt / math.sqrt(float(vt @ vt))
    return np.array(r)


def kinetic_coefficient(fr, vt: np.ndarray) -> float:
    """μ(|v_t|) [-] of friction ``fr`` (a :class:`~contactdyn.laws.friction_laws.FrictionSpec`) at slip velocity v_t."""
    return fr.mu_k if fr.constant else float(fr.mu(math.sqrt(float(vt @ vt))))


def slip_acceleration(system, c: Contact, x: np.ndarray, xdot: np.ndarray) -> np.ndarray:
    """Tangential tip–environment acceleration [m/s²] in tangent coordinates at (x, ẋ)."""
    nQ, nv = system.nQ, system.nv
    system.robot.update(x[:nv], x[nQ:nQ + nv])
    kin = system.kinematics(c, x)
    qdd = xdot[nQ:2 * nQ]
    a_touch, a_env = c.rates(qdd)
    a_tip = kin.J @ qdd[:nv] + kin.drift + kin.column_rates(qdd)
    return kin.tangents @ ((a_tip if a_touch is None else a_tip + a_touch) - a_env)


def launching(mode: ContactMode) -> bool:
    """A touching 2-D slide started from rest whose direction is still to be solved (:func:`launch_directions`)."""
    return mode.from_rest and len(mode.slip) == 2 and mode.touching and not mode.stuck


def launch_directions(system, modes: list[ContactMode], slip_of, acceleration_of) -> list[ContactMode]:
    """Modes whose 2-D slides from rest, still inside the stick band, slide the consistent way.

    A slip from rest starts where it accelerates: d with a_t(d) = λ d, λ ≥ 0, a_t the
    tangential acceleration when friction is −μ_k F d. With an anisotropic arm (tangential
    mobility differing by direction) this is not the direction of the holding force, and
    a slide that started along that one would swing round at |v_t| ≈ v_ε, where the
    direction dynamics are stiff (rate ∝ 1/|v_t|). Newton on the angle (at most 4
    iterations, two evaluations each); the reference r if it does not converge.

    Written once for both right-hand sides, which give what it reads: ``slip_of(i)`` the
    slip velocity of contact i [m/s], ``acceleration_of(trial, i)`` its tangential
    acceleration [m/s²] in the modes ``trial`` (the readable model: :func:`launch_directions_at`; the one
    pipeline finds the same directions compiled, :mod:`contactdyn.model.pipeline.launch`). A slide already
    past the stick band is launched: its own direction from here on.
    """
    out = list(modes)
    for i, mode in enumerate(modes):
        if not launching(mode):
            continue
        r = np.asarray(mode.slip, float)
        if float(slip_of(i) @ r) > system.slip_band:
            out[i] = mode.with_(from_rest=False)  # launched: the slip's own direction from here on
            continue

        def cross(theta: float, i: int = i, mode: ContactMode = mode) -> tuple[float, np.ndarray, float]:
            """Sliding along d = (cos θ, sin θ): (d × a_t, d, a_t · d) [m/s²]."""
            d = np.array([np.cos(theta), np.sin(theta)])
            trial = list(out)
            trial[i] = mode.with_(slip=tuple(d), from_rest=False)
            a = acceleration_of(trial, i)
            return float(d[0] * a[1] - d[1] * a[0]), d, float(a @ d)

        theta = float(np.arctan2(r[1], r[0]))
        best = r
        for _ in range(4):
            phi, d, ahead = cross(theta)
            if ahead >= 0.0 and abs(phi) <= 1e-9 * (abs(ahead) + abs(phi)):
                best = d
                break
            dphi = (cross(theta + 1e-7)[0] - phi) / 1e-7
            if not dphi < 0.0:  # a stable direction turns the acceleration back onto d
                break
            theta -= float(np.clip(phi / dphi, -0.5, 0.5))
        out[i] = mode.with_(slip=tuple(best), from_rest=False)
    return out


def launch_directions_at(system, t: float, x: np.ndarray, modes: list[ContactMode], phase: Phase, evaluate
                         ) -> list[ContactMode]:
    """:func:`launch_directions` on the readable model: ``evaluate(system, t, x, modes, phase)``
    (``dynamics.evaluate``) per trial direction."""
    nQ, nv = system.nQ, system.nv
    contacts = system.contacts

    def slip_of(i: int) -> np.ndarray:
        system.robot.update(x[:nv], x[nQ:nQ + nv])
        return slip_velocity(system, contacts[i], system.kinematics(contacts[i], x))

    def acceleration_of(trial: list[ContactMode], i: int) -> np.ndarray:
        return slip_acceleration(system, contacts[i], x, evaluate(system, t, x, trial, phase).xdot)

    out = launch_directions(system, modes, slip_of, acceleration_of)
    system.robot.update(x[:nv], x[nQ:nQ + nv])
    return out


def slip_velocity(system, c: Contact, kin: Kinematics, qd: np.ndarray | None = None) -> np.ndarray:
    """Tangential tip–environment velocity [m/s] in tangent coordinates (at Q̇ = qd if given): along the state's
    tangents, relative to the surface's material point (:class:`~contactdyn.model.contact.Kinematics`)."""
    if qd is None:
        return kin.tangents @ (kin.v_tip - kin.v_env)
    v_touch, v_env = c.rates(qd)
    v_tip = kin.J @ qd[: system.nv] + kin.column_rates(qd)
    return kin.tangents @ ((v_tip if v_touch is None else v_tip + v_touch) - v_env)


def initial_slip(c: Contact, kin: Kinematics) -> tuple[float, ...]:
    """Reference sliding direction of a contact at the start: its slip velocity's (1-D: its sign)."""
    if c.friction is None:
        return ()
    vt = kin.tangents @ (kin.v_tip - kin.v_env)
    norm = float(np.linalg.norm(vt))
    if norm == 0.0:
        return tuple(np.eye(len(vt))[0]) if len(vt) else ()
    return tuple(np.sign(vt)) if len(vt) == 1 else tuple(vt / norm)


def friction_terms(system, c: Contact, mode: ContactMode, kin: Kinematics, row: np.ndarray | None, F_n: float,
                   f: np.ndarray, ydot: np.ndarray, ev, rows: Rows, pending: list) -> np.ndarray | None:
    """A friction contact's part of the right-hand side in its mode; returns the normal row's force column.

    Sticking: one constraint row per tangent (force unknown). Sliding: with a normal row
    (its force F unknown) the column tilts by −μ d·G_T and the viscous force goes into
    ``f``; without one (F known from the chain) F_f = −μ max(F, 0) d − c v_t goes into
    ``f`` at once; μ = μ(|v_t|) of the contact's law (:mod:`contactdyn.laws.friction_laws`). ``pending``
    collects (contact, d, μ, viscous force) to finish F_f once
    the solve gives F (:func:`contactdyn.model.dynamics.evaluate`).
    """
    nQ, nv = system.nQ, system.nv
    col = row
    T = kin.tangents
    vt = slip_velocity(system, c, kin)
    ev.slip[c.name] = vt
    if mode.touching:
        R_T = np.zeros((len(T), nQ))  # generalized rows of the tangential slip
        R_T[:, :nv] = T @ kin.J
        c.add_columns(R_T, T)
        kin.add_columns(R_T, T)
    if mode.touching and mode.stuck:
        for i in range(len(T)):
            rows.add(R_T[i], float(T[i] @ kin.drift) + system.stabilization * float(vt[i]), (c.name, "t", i))
    elif mode.touching:
        fr = c.friction
        d = slip_direction(system, vt, mode)
        mu = kinetic_coefficient(fr, vt)
        visc = -fr.viscous * vt if fr.viscous else np.zeros(len(T))
        if row is not None:  # normal force is an unknown: tilt its column by −μ d
            col = row - mu * (d @ R_T)
            pending.append((c, d, mu, visc))
            if fr.viscous:
                f += visc @ R_T
        else:
            ff = -mu * max(F_n, 0.0) * d + visc
            pending.append((c, d, mu, visc))
            ev.friction[c.name] = ff
            f += ff @ R_T
        if system.energy_slot >= 0:
            ydot[system.energy_slot + 1] += float(fr.viscous * vt @ vt)
    else:
        ev.friction[c.name] = np.zeros(len(T))
    return col
