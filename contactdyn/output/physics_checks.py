"""Every run checks its own physics: the gaps that contact-simulation benchmarks measure.

A run that breaks Coulomb's or Signorini's law can look right. So each run measures, over
its output samples and at the start of every integration segment (the instants where modes
were just decided), per contact:

=======================  =====  ===============================================================
``cone_excess``          N      largest |F_f| − μ_s F_n while stuck (Coulomb's cone)
``slide_deviation``      N      largest | |F_f + c v_t| − μ_k F_n | while sliding (the kinetic law)
``dissipation_gap``      W      largest F_f·v_t + |F_f + c v_t| |v_t| + c |v_t|² while sliding: 0
                                when the friction opposes the slip (maximum dissipation)
``pull``                 N      most negative normal force of a unilateral contact, as a positive
                                number (Signorini: a contact pushes, it never pulls)
``penetration``          m      deepest −gap of a rigid (bonded-at-touch) contact
``complementarity``      N·m    largest |gap · F_n| of a rigid contact while touching
``drift``                m      largest |gap| of a rigid contact while touching (its bond's drift)
``stick_speed``          m/s    largest |v_t| while stuck (a stick must not creep)
``impulse_excess``       N·s    largest |F_fΔt| − μ_s FΔt of the contact's impacts (the cone of impulses)
=======================  =====  ===============================================================

and, with ``solver.record_energy``, the run's ``energy_residual`` [J]: the largest
|E(t) − E(0) − (work − dissipated) + impact losses| at the output samples (:func:`energy_residual`).

Each has a tolerance from the solver's settings (:func:`tolerances`): a quantity that is
algebraic in the state (the forces of a stick, of a slide) is exact up to the solve's
round-off and the states' error, rtol relative; one that drifts (a bond's gap, a stick's
speed) is held by the integration to its atol. A check above its tolerance is a violation:
one sentence, naming the contact, the check, the value, the tolerance and the time.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from ..model.friction import FORCE_ABS_TOL

if TYPE_CHECKING:
    from ..model.system import System

__all__ = ["CHECKS", "UNITS", "StartAudit", "tolerances", "run_checks", "violations", "PhysicsWarning"]

#: check -> (unit, meaning)
CHECKS = {
    "cone_excess": ("N", "|F_f| − μ_s F_n while stuck"),
    "slide_deviation": ("N", "| |F_f + c v_t| − μ_k F_n | while sliding"),
    "dissipation_gap": ("W", "friction not opposing the slip while sliding"),
    "pull": ("N", "pulling normal force of a unilateral contact"),
    "penetration": ("m", "depth of a rigid contact"),
    "complementarity": ("N·m", "|gap · F_n| of a rigid contact while touching"),
    "drift": ("m", "|gap| of a rigid contact while touching"),
    "stick_speed": ("m/s", "slip speed while stuck"),
    "impulse_excess": ("N·s", "|F_fΔt| − μ_s FΔt of an impact"),
    "energy_residual": ("J", "energy balance residual"),
}
UNITS = {name: unit for name, (unit, _) in CHECKS.items()}
#: [-] relative slack of the force checks per unit of rtol (the forces follow the states, whose relative
#: error is about rtol; a slip or separation is located where the interpolant crosses, within its error)
FORCE_PER_RTOL = 1e3
FORCE_FLOOR = 1e-9  #: [-] relative slack of the force checks at any rtol (the solves' round-off)
SPEED_FLOOR = 1e-3  #: [m/s] the slip speed that scales the dissipation check at least
DRIFT_PER_ATOL = 1e3  #: [-] slack of the drift checks (gap [m], stick speed [m/s]) per unit of atol


class PhysicsWarning(UserWarning):
    """A run whose result breaks a law it simulates (a stick outside the cone, a pulling contact...)."""


@dataclass
class Worst:
    """The largest value seen of one check, and when [s]."""

    value: float = -math.inf
    t: float = math.nan

    def see(self, values: np.ndarray, times: np.ndarray) -> None:
        if not values.size or np.isnan(self.value):
            return
        if np.isnan(values).any():  # a check that cannot be evaluated is a violation, at its first instant
            k = int(np.flatnonzero(np.isnan(values))[0])
            self.value, self.t = math.nan, float(times[k])
            return
        k = int(np.argmax(values))
        if values[k] > self.value:
            self.value, self.t = float(values[k]), float(times[k])


@dataclass
class StartAudit:
    """The forces at the start of each segment (where the loop just decided the modes), by contact and check.

    The hybrid loop hands it each segment's event functions at its first state: a stuck contact's ``slip``
    function is μ_s F_n − |F_f|, a touching unilateral contact's ``separate`` function is F_n."""

    worst: dict[tuple[str, str], Worst] = field(default_factory=dict)

    def record(self, t: float, x: np.ndarray, events: list) -> None:
        for e in events:
            if e.kind == "slip":
                self._see(e.contact, "cone_excess", -float(e.value(t, x)), t)
            elif e.kind == "separate":
                self._see(e.contact, "pull", -float(e(t, x)), t)

    def _see(self, contact: str, check: str, value: float, t: float) -> None:
        self.worst.setdefault((contact, check), Worst()).see(np.array([value]), np.array([t]))


def _worst(values: np.ndarray, times: np.ndarray) -> Worst:
    """The largest of ``values`` and its time [s]."""
    w = Worst()
    w.see(values, times)
    return w


def tolerances(system: System, channels: dict[str, np.ndarray], impacts: list[dict[str, Any]]
               ) -> dict[str, dict[str, float]]:
    """Each contact's tolerance per check, from the solver's rtol and atol and the contact's force scale
    F = max(1 N, its peak |F_n|): forces F (FORCE_FLOOR + FORCE_PER_RTOL rtol), power that force times
    the peak slip speed, gaps and stick speeds DRIFT_PER_ATOL atol, gap·force their product; impulses as
    forces, on the scale of the contact's largest normal impulse (at least 1e-6 N·s)."""
    solver = system.scene.solver
    out: dict[str, dict[str, float]] = {}
    relative = FORCE_FLOOR + FORCE_PER_RTOL * solver.rtol  # [-] slack of a force per unit of its scale
    for c in system.contacts:
        F = max(1.0, float(np.max(np.abs(channels[f"contact.{c.name}.F_n"]), initial=0.0)))
        force = F * relative
        slip = channels.get(f"contact.{c.name}.v_slip")
        speed = max(SPEED_FLOOR, float(np.max(np.abs(slip), initial=0.0))) if slip is not None else SPEED_FLOOR
        drift = DRIFT_PER_ATOL * solver.atol
        hits = [imp for imp in impacts if imp["contact"] == c.name]
        P = max([1e-6] + [abs(imp["normal_impulse"]) for imp in hits])  # [N·s] the impulse scale
        out[c.name] = {"cone_excess": force, "slide_deviation": force, "dissipation_gap": force * speed,
                       "pull": force, "penetration": drift, "complementarity": drift * F, "drift": drift,
                       "stick_speed": drift,
                       # + the impact's own slack of its cone test (FORCE_ABS_TOL, read in N·s there)
                       "impulse_excess": P * relative + FORCE_ABS_TOL}
    return out


def run_checks(system: System, xs: np.ndarray, channels: dict[str, np.ndarray], starts: StartAudit,
               impacts: list[dict[str, Any]], events: list[dict[str, Any]] = ()) -> dict[str, Any]:
    """The run's checks: ``{"contacts": {name: {check: {"value", "t", "tol"}}}, "energy_residual": ...}``
    (a check that does not apply to a contact is absent; value 0 where it applies but nothing was seen)."""
    tol = tolerances(system, channels, impacts)
    contacts: dict[str, dict[str, dict[str, float]]] = {}
    t = np.asarray(channels["t"], float)
    for c in system.contacts:
        worst = _contact_worst(system, c, channels, t)
        if c.friction is not None and len(c.tangents):
            worst["impulse_excess"] = _impulse_worst(c, impacts)
        for check, w in worst.items():
            start = starts.worst.get((c.name, check))
            if start is not None:
                w.see(np.array([start.value]), np.array([start.t]))
        contacts[c.name] = {check: {"value": w.value if not w.value <= 0.0 else 0.0, "t": _time(w.t),
                                    "tol": tol[c.name][check]} for check, w in worst.items()}
    out: dict[str, Any] = {"contacts": contacts}
    if system.energy_slot >= 0:
        out["energy_residual"] = energy_residual(system, xs, channels, impacts, events)
    return out


def _time(t: float) -> float | None:
    """[s] when a check's value was seen; None when it saw nothing (the JSON sidecar stays strict JSON)."""
    return t if math.isfinite(t) else None


def _contact_worst(system: System, c, ch: dict[str, np.ndarray], t: np.ndarray) -> dict[str, Worst]:
    """The checks that apply to contact c, at its output samples."""
    p = f"contact.{c.name}"
    F_n = np.asarray(ch[f"{p}.F_n"], float)
    touching = np.asarray(ch[f"{p}.touching"], float) > 0.5
    worst: dict[str, Worst] = {}
    if not c.spec.bonded:
        worst["pull"] = _worst(-F_n[touching], t[touching])
    if c.normal.chain.bonded_when_touching:
        gap = np.asarray(ch[f"{p}.gap"], float)
        worst["penetration"] = _worst(-gap, t)
        worst["complementarity"] = _worst(np.abs(gap * F_n)[touching], t[touching])
        worst["drift"] = _worst(np.abs(gap)[touching], t[touching])
    fr = c.friction
    if fr is None or not len(c.tangents):
        return worst
    F_f = np.asarray(ch[f"{p}.F_f"], float).reshape(len(t), -1)
    v_t = np.asarray(ch[f"{p}.v_slip"], float).reshape(len(t), -1)
    stuck = touching & (np.asarray(ch[f"{p}.stuck"], float) > 0.5)
    sliding = touching & ~stuck
    speed = np.linalg.norm(v_t, axis=1)  # [m/s]
    worst["cone_excess"] = _worst((np.linalg.norm(F_f, axis=1) - fr.mu_s * np.maximum(F_n, 0.0))[stuck], t[stuck])
    worst["stick_speed"] = _worst(speed[stuck], t[stuck])
    coulomb = F_f + fr.viscous * v_t  # the Coulomb part of the friction [N]
    size = np.linalg.norm(coulomb, axis=1)
    mu = fr.mu(speed)  # the law's kinetic coefficient at each sample's slip speed
    worst["slide_deviation"] = _worst(np.abs(size - mu * np.maximum(F_n, 0.0))[sliding], t[sliding])
    moving = sliding & (speed > system.slip_band)  # at rest the direction is the launch's, not the slip's
    power = np.einsum("ij,ij->i", coulomb, v_t) + size * speed  # [W] 0 when the friction opposes the slip
    worst["dissipation_gap"] = _worst(power[moving], t[moving])
    return worst


def stored_energy(system: System, xs: np.ndarray, ch: dict[str, np.ndarray]) -> tuple[np.ndarray | None, str]:
    """[J] per sample: ½ Q̇ᵀ M Q̇ (the robot's H, rotors reflected on the joints, an articulated body's H_b, the other
    coordinates' inertias) + the robot's and the bodies' gravity potential + the stages' and elastic transmissions'
    springs; (None, why) where a stage's law does not state its potential."""
    nQ, nv, robot = system.nQ, system.nv, system.robot
    energy = np.empty(len(xs))
    for k, x in enumerate(xs):
        q, v, rest = x[:nv], x[nQ:nQ + nv], x[nQ + nv:2 * nQ]
        others = 0.5 * float(system.rotor_inertias @ (v * v)) + 0.5 * float(system.M_rest @ (rest * rest)) \
            - float(system.weights @ x[nv:nQ])  # the bodies' weights' potential −W·Q [J]
        for body in system.articulated.values():  # (its coordinates' M_rest and weights are zeros)
            idx = slice(body.first, body.first + body.nb)
            others += body.energy(x[idx], x[nQ:][idx], body.chart_of(x))
        if system.riding:  # a riding mass's ½ m |v|² beyond its ½ m ξ̇² (in M_rest's sum)
            robot.update(q, v)
            system.update_bodies(x)
            others += sum(0.5 * rm.mass * (float(np.sum(rm.velocity(x[nQ + rm.carrier], x[nQ + rm.coord]) ** 2))
                                           - x[nQ + rm.coord] ** 2) for rm in system.riding)
        energy[k] = robot.kinetic_energy(q, v) + robot.potential_energy(q) + others  # others: rotors, bodies, masses
    for c in system.contacts:
        for dc in c.chains:
            for s in dc.chain.stages:
                x_s = ch[f"stage.{c.name}.{dc.label}.{s.label}.x"]
                if s.potential(0.0) is None:
                    return None, f"stage law {s.law!r} states no potential"
                energy += np.array([s.potential(float(xi)) for xi in x_s])
    d = system.drives
    for i, spec in enumerate(d.specs):
        m = d.motor_coords[i]
        if m >= 0:  # a transmission's spring (elastic: ½ c φ², φ = θ/N − Q/r)
            energy += spec.law.potential(spec, xs[:, d.coords[i]], xs[:, m])
    return energy, ""


def _impulse_worst(c, impacts: list[dict[str, Any]]) -> Worst:
    """The largest |F_fΔt| − μ_s FΔt over the impacts on contact c (the impact's own contact)."""
    hits = [imp for imp in impacts if imp["contact"] == c.name]
    excess = [float(np.linalg.norm(imp["friction_impulse"])) - c.friction.mu_s * max(imp["normal_impulse"], 0.0)
              for imp in hits]  # [N·s]
    return _worst(np.array(excess), np.array([imp["t"] for imp in hits]))


def energy_residual(system: System, xs: np.ndarray, ch: dict[str, np.ndarray],
                    impacts: list[dict[str, Any]], events: list[dict[str, Any]] = ()) -> dict[str, Any]:
    """The energy audit's residual [J]: max |E(t) − E(0) − (work − dissipated) + impact losses until t|, E the
    stored energy (:func:`stored_energy`); its tolerance max(DRIFT_PER_ATOL atol, FORCE_PER_RTOL rtol) × the
    audit's scale (1 + the largest |work| + dissipated). Value None where a part's stored energy is not known
    (``why``)."""
    stored, why = stored_energy(system, xs, ch)
    work, lost = np.asarray(ch["energy.work"], float), np.asarray(ch["energy.dissipated"], float)
    scale = 1.0 + float(np.max(np.abs(work), initial=0.0) + np.max(np.abs(lost), initial=0.0))
    tol = max(DRIFT_PER_ATOL * system.scene.solver.atol, FORCE_PER_RTOL * system.scene.solver.rtol) * scale
    if stored is None:
        return {"value": None, "t": None, "tol": tol, "why": why}
    t = np.asarray(ch["t"], float)
    impact_loss = np.zeros_like(t)
    # every impact's loss once: the contacts' (Result.impacts; a limit's with a contact carries "joint") and the
    # joint limits' without a contact (their "limit" event)
    losses = [imp for imp in impacts if "joint" not in imp] + [e for e in events if e.get("kind") == "limit"]
    for hit in losses:
        impact_loss[t >= hit["t"]] += float(hit.get("energy_loss", 0.0))
    residual = np.abs(stored - stored[0] - (work - lost) + impact_loss)
    k = int(np.argmax(residual))
    return {"value": float(residual[k]), "t": float(t[k]), "tol": tol}


def violations(checks: dict[str, Any]) -> list[str]:
    """One sentence per check above its tolerance."""
    out = []
    for name, by_check in checks.get("contacts", {}).items():
        for check, v in by_check.items():
            if not v["value"] <= v["tol"]:  # NaN: a check that could not be evaluated is a violation
                unit, meaning = CHECKS[check]
                out.append(f"physics check: contact {name!r}: {check} = {v['value']:.3g} {unit} at t = {v['t']:.6g} s "
                           f"({meaning}; tolerance {v['tol']:.2g} {unit})")
    e = checks.get("energy_residual")
    if e is not None and e["value"] is not None and not e["value"] <= e["tol"]:  # (None: unknown, see "why")
        out.append(f"physics check: energy_residual = {e['value']:.3g} J at t = {e['t']:.6g} s "
                   f"(work − dissipation − stored energy; tolerance {e['tol']:.2g} J)")
    return out
