"""Joint damping and Coulomb joint friction with true stick.

Per joint (coordinate i of the robot): viscous damping b [N·m·s/rad or N·s/m] and dry friction
with a static limit τ_s and a kinetic value τ_k ≤ τ_s [N·m or N]. They come from the URDF's
``<dynamics damping="…" friction="…">`` (Pinocchio's ``model.damping``, ``model.friction``: static
= kinetic) unless the scene says otherwise: ``robot.joint_friction = "ignore"`` drops the URDF's
values, and a table ``[robot.joint.<joint>]`` (``damping``, ``friction`` or ``friction_static`` with
``friction_kinetic``) replaces that joint's (keys it does not give: 0). ``Result.meta["joint_friction"]``
lists every joint with damping or friction, its values and their source ("urdf" or "scene").

The joint torque [N·m or N] is −b q̇ᵢ on every joint, always, plus per joint with τ_s > 0 its
dry friction in the joint's friction *mode*, part of the run's
:class:`~contactdyn.model.phases.Phase` (``Phase.joint_modes``: (i, mode) per such joint):

- stuck (mode 0): a constraint row eᵢ Q̈ + ω q̇ᵢ = 0 (ω = ``solver.stabilization``) in the same
  linear system as the contacts' and the limits' rows; its force λᵢ is the holding torque.
  A joint sticks with q̇ᵢ set to exactly 0, so the row keeps it at exactly 0: it cannot creep;
- sliding with sign s = ±1 (mode s): the torque −s τ_k, constant in the mode;

and the events (located by the integrator, logged with the joint's name):

- ``joint_slip``: a stuck joint's holding torque reaches the static limit, |λᵢ| = τ_s; it slides
  from rest where the load pushes, s = −sign(λᵢ);
- ``joint_stick``: a sliding joint's velocity crosses zero (s q̇ᵢ falls through −``STICK_TOL``): it
  sticks (q̇ᵢ := 0) if the torque that holds it there is within τ_s, else it reverses (logged as
  ``joint_reverse``, slides with −s from rest).

Where the modes are decided at an instant (a run's or a phase's start, after any event:
:meth:`~contactdyn.hybrid.transitions.Transitions.settle`), a stuck joint whose holding torque
exceeds τ_s slips, and a stuck joint that moves (an impact gave it a velocity) slides along it. Joints and contacts
at rest together are then checked together, each stick within its limit and each slide from rest accelerating along
it, and searched for a mode that is where one is not (:mod:`contactdyn.hybrid.at_rest`).

Impacts: a dry friction torque is bounded (|τ| ≤ τ_s), so over an impact (Δt → 0) it takes no
impulse: the impact maps (:mod:`contactdyn.model.impact`) hold no stuck joint, and a stuck joint
the impact sets moving slides from it on (above). (A row in the impact map would hold the joint
with an unbounded impulse, as a locked joint.) Unless that slide is below the integration's resolution: where its
friction would stop it within a travel of ``solver.atol`` [rad or m] (:meth:`JointFriction.unresolved_slide`), the
joint holds, its residual speed projected away (:func:`~contactdyn.model.impact.project_velocity`). Why: a light
joint's slide of ~1e-14 rad can pull the contact that just touched off its surface; it sticks 1e-8 s later and the
tip falls back, and the touch, slip, separation and stick repeat every 0.3 µs (the 5-DOF writer with 1.5/0.5 N·m
per joint: 10,000 events by 3.995 s), the chatter whose mean is the held joint on a touching contact.

A joint pressing on a position limit (:mod:`contactdyn.model.limits`) is held by the limit's row alone: its friction
mode is stuck and its row is left out (the two would be one row twice); it comes back when the limit releases, the
joint at rest (its velocity, the limit row's drift, set to 0: :meth:`JointFriction.left_limit`).

Redundant holds: stuck joints and other rows (a stuck contact's, a bond's) can over-constrain the robot (both joints
of a planar arm stuck while its tip sticks: 3 rows on 2 coordinates). The hold is then statically indeterminate: the
solve takes the least-squares (minimum-norm) forces (``Result.stats["singular_solves"]``), and where these leave a
hold outside its limit while splits that move nothing exist, the call takes a split with every hold inside
(:func:`contactdyn.model.pipeline.kkt.coulomb_split`): the hold breaks only where no split is left, as Coulomb's.
Along one direction of splits it is the split nearest the least-norm forces; where they span more (all 7 joints of an
arm stuck while its tool sticks: 10 rows on 7 coordinates) the rule is taken along each direction in turn, for a few
rounds: it finds a split inside where those rounds reach one, not always the nearest.
"""

from __future__ import annotations

from dataclasses import replace
from itertools import groupby
from typing import Any

import numpy as np

from ..errors import SceneError
from ..robot.robot import Robot
from .friction import SLIP_ALARM
from .impact import project_velocity

__all__ = ["JointFriction", "STUCK", "STICK_TOL", "joint_friction_channels", "summary"]

STUCK = 0  #: a joint's friction mode while stuck (sliding: its sign s = ±1)
#: [rad/s or m/s] a sliding joint's ``joint_stick`` fires when s q̇ᵢ falls this far below min(0, its start value)
STICK_TOL = 1e-13


def _event(fn, kind: str, joint: str, index: int):
    fn.terminal, fn.direction = True, -1
    fn.kind, fn.contact, fn.index = kind, joint, index
    return fn


class JointFriction:
    """The joints' damping and dry friction a run uses (see the module docstring)."""

    def __init__(self, robot: Robot, spec: Any, file: str | None = None):
        nv = robot.nv
        self.names = list(robot.joint_names)
        self.units = list(robot.joint_units)
        from_urdf = spec.joint_friction == "urdf"
        self.damping = robot.model.damping.copy() if from_urdf else np.zeros(nv)  #: b [N·m·s/rad or N·s/m]
        self.static = robot.model.friction.copy() if from_urdf else np.zeros(nv)  #: τ_s [N·m or N]
        self.kinetic = self.static.copy()  #: τ_k [N·m or N]
        self.source = ["urdf"] * nv  # (the URDF's values were checked as it loaded: robot.urdf_check)
        for name, js in spec.joints.items():
            if name not in self.names:
                raise SceneError(f"robot.joint.{name}", f"a table named after an active joint of the robot "
                                 f"({', '.join(self.names)})", name, file)
            i = self.names.index(name)
            self.damping[i], self.static[i], self.kinetic[i] = js.damping, js.static, js.kinetic
            self.source[i] = "scene"
        self.dry = [i for i in range(nv) if self.static[i] > 0.0]  #: joints with dry friction
        self.any = bool(self.dry) or bool(np.any(self.damping))  #: any joint damping or friction at all

    def describe(self) -> dict[str, dict]:
        """Per joint with damping or friction: its values and where they came from (``Result.meta``)."""
        out = {}
        for i, name in enumerate(self.names):
            if self.damping[i] or self.static[i]:
                out[name] = {"damping": float(self.damping[i]), "friction_static": float(self.static[i]),
                             "friction_kinetic": float(self.kinetic[i]), "source": self.source[i],
                             "unit": "N·m" if self.units[i] == "rad" else "N"}
        return out

    # ---- modes ------------------------------------------------------------------------------
    def initial_modes(self, x: np.ndarray, nQ: int) -> tuple[tuple[int, int], ...]:
        """Per dry joint: stuck at rest (q̇ᵢ = 0), else sliding along its velocity (decided again at the start)."""
        return tuple((i, STUCK if x[nQ + i] == 0.0 else (1 if x[nQ + i] > 0.0 else -1)) for i in self.dry)

    @staticmethod
    def held(modes: tuple, limits: tuple = ()) -> list[int]:
        """The stuck joints that carry a row: not those pressing on a position limit (its row holds them)."""
        pressing = {i for i, _ in limits}
        return [i for i, m in modes if m == STUCK and i not in pressing]

    @staticmethod
    def left_limit(x: np.ndarray, i: int, phase: Any, nQ: int) -> np.ndarray:
        """x as joint i leaves its position limit (a release): from rest where its dry friction holds it (mode stuck,
        its row back), its velocity, the limit row's stabilization drift (~1e-12 rad/s), set to exactly 0; so its
        friction decides from rest (stick, or slip where the load passes τ_s), not from the drift's sign."""
        if (i, STUCK) not in phase.joint_modes or x[nQ + i] == 0.0:
            return x
        x = x.copy()
        x[nQ + i] = 0.0
        return x

    @staticmethod
    def with_mode(phase: Any, i: int, mode: int) -> Any:
        """``phase`` with joint i's friction mode set."""
        return replace(phase, joint_modes=tuple((j, mode if j == i else m) for j, m in phase.joint_modes))

    # ---- forces and rows ----------------------------------------------------------------------
    def torques(self, modes: tuple, x: np.ndarray, nQ: int, nv: int) -> np.ndarray:
        """The joints' damping and sliding friction −b q̇ − s τ_k [N·m or N] (nv,) (a stuck joint's torque is its
        row's force)."""
        tau = -self.damping * x[nQ:nQ + nv]
        for i, m in modes:
            if m != STUCK:
                tau[i] -= m * self.kinetic[i]
        return tau

    def add_rows(self, modes: tuple, limits: tuple, x: np.ndarray, nQ: int, rows, omega: float) -> None:
        """A row per stuck joint into ``rows`` (:class:`~contactdyn.model.constraints.Rows`): eᵢ Q̈ + γ = 0 with
        γ = ω q̇ᵢ [rad/s² or m/s²], ω [1/s] the stabilization rate; its force is the holding torque."""
        for i in self.held(modes, limits):
            row = np.zeros(nQ)
            row[i] = 1.0
            rows.add(row, omega * float(x[nQ + i]), (self.names[i], "joint", i))

    # ---- events -------------------------------------------------------------------------------
    def events(self, modes: tuple, limits: tuple, x0: np.ndarray, nQ: int, torque=None) -> list:
        """Event functions of one segment: ``joint_slip`` of stuck joints (g = τ_s − |λᵢ|; ``torque(t, x)`` gives
        the holding torques {i: λᵢ}), ``joint_stick`` of sliding ones (g = s q̇ᵢ − min(s q̇ᵢ(t₀), 0) + STICK_TOL)."""
        out = []
        for i in self.held(modes, limits):  # (watched at every stage: hybrid.events.StageWatch, which holds g = 0)
            out.append(_event(lambda t, x, i=i, ts=self.static[i]: ts - abs(torque(t, x)[i]), "joint_slip",
                              self.names[i], i))
        for i, m in modes:
            if m != STUCK:
                floor = min(m * float(x0[nQ + i]), 0.0) - STICK_TOL
                fn = _event(lambda t, x, s=m, f=floor, k=nQ + i: s * x[k] - f, "joint_stick", self.names[i], i)
                fn.state = (nQ + i, m, floor)  # (g = s x[k] − floor of the state alone: hybrid.events.StateWatch)
                out.append(fn)
        return out

    # ---- switching ------------------------------------------------------------------------------
    def switch(self, system: Any, t: float, x: np.ndarray, modes: list, phase: Any, event, holds) -> tuple:
        """Apply a ``joint_slip`` or ``joint_stick`` event: (x, phase, info); ``info["kind"]`` renames the event
        where it is a false alarm (``joint_slip_check``) or a reversal (``joint_reverse``); a ``joint_stick`` a stage
        saw but its located instant does not confirm never reaches here (``hybrid.events.StateWatch.unconfirmed``).
        ``holds(t, x, modes, phase)``: the stuck joints' holding torques there, by joint (the transitions'
        ``LastEvaluation.joint_hold``)."""
        i, nQ = event.index, system.nQ
        if event.kind == "joint_slip":  # slides from rest where the load pushes (−sign λ), unless a false alarm
            hold = holds(t, x, modes, phase).get(i, 0.0)
            if self.breaks_away(i, hold, SLIP_ALARM):
                return x, self.with_mode(phase, i, -1 if hold > 0.0 else 1), {"torque": hold}
            return x, phase, {"torque": hold, "kind": "joint_slip_check"}
        x = x.copy()
        x[nQ + i] = 0.0  # at rest, exactly: stuck, or sliding back from rest
        trial = self.with_mode(phase, i, STUCK)
        hold = holds(t, x, modes, trial).get(i, 0.0)
        if self.breaks_away(i, hold):
            return x, self.with_mode(phase, i, -1 if hold > 0.0 else 1), {"torque": hold, "kind": "joint_reverse"}
        return x, trial, {"torque": hold}

    def contradicted(self, system: Any, t: float, x: np.ndarray, modes: list, phase: Any, evaluate) -> tuple:
        """The first joint mode the state contradicts, as (kind, joint, x, phase) with it changed, else ("", "", x,
        phase) (x: its stuck joints' velocities within ``STICK_TOL`` set to exactly 0): a sliding joint pressing on a
        limit is stuck (the limit holds it); a sliding joint that moves against its slide (an impact reversed it)
        slides along its velocity; a stuck joint that moves (an impact's velocity) slides along it, or holds where that
        slide is unresolved (:meth:`unresolved_slide`: the residual speeds projected away); a stuck joint
        whose holding torque exceeds τ_s slides where the load pushes. ``evaluate(t, x, modes, phase)``: the mode's
        Evaluation there (the transitions' ``LastEvaluation``)."""
        nQ = system.nQ
        pressing = {i for i, _ in phase.limits}
        for i, m in phase.joint_modes:
            if m != STUCK and i in pressing:
                return "joint_stick", self.names[i], x, self.with_mode(phase, i, STUCK)
            if m != STUCK and m * float(x[nQ + i]) < -STICK_TOL:  # (its kinetic friction would push it along)
                return "joint_reverse", self.names[i], x, self.with_mode(phase, i, -m)
        held = self.held(phase.joint_modes, phase.limits)
        residual = False
        for i in held:
            v = float(x[nQ + i])
            if abs(v) > STICK_TOL:
                if not self.unresolved_slide(system, t, x, modes, phase, i, evaluate):
                    return "joint_slip", self.names[i], x, self.with_mode(phase, i, 1 if v > 0.0 else -1)
                residual = True
            elif v != 0.0:
                x = x.copy()
                x[nQ + i] = 0.0
        if not held:
            return "", "", x, phase
        if residual:  # (held with their residual speeds projected away; the others' rows kept)
            x = project_velocity(system, x, modes, phase.limits, phase.joint_modes)
            x[[nQ + i for i in held]] = 0.0
        ev = evaluate(t, x, modes, phase)
        for i in held:
            hold = ev.joint_hold[i]
            if self.breaks_away(i, hold):
                return "joint_slip", self.names[i], x, self.with_mode(phase, i, -1 if hold > 0.0 else 1)
        return "", "", x, phase

    def unresolved_slide(self, system: Any, t: float, x: np.ndarray, modes: list, phase: Any, i: int,
                         evaluate) -> bool:
        """Would stuck joint i, moving at q̇ᵢ (a residual speed: an impact's, or another item's projection's), stop by
        its friction within a travel v²/(2|q̈ᵢ|) ≤ ``solver.atol`` [rad or m] if it slid: a slide below the
        integration's resolution, which it holds instead (the module docstring's "Impacts")? q̈ᵢ: its acceleration
        sliding along q̇ᵢ, the others as they are."""
        v = float(x[system.nQ + i])
        a = float(evaluate(t, x, modes, self.with_mode(phase, i, 1 if v > 0.0 else -1)).xdot[system.nQ + i])
        return v * a < 0.0 and v * v <= 2.0 * abs(a) * system.scene.solver.atol

    def breaks_away(self, i: int, hold: float, alarm: float = 0.0) -> bool:
        """Does a holding torque ``hold`` [N·m or N] exceed joint i's static limit (within ``alarm``, relative)?"""
        return abs(hold) > (1.0 - alarm) * self.static[i] if alarm else abs(hold) > self.static[i]


def summary(joints: dict[str, dict]) -> str:
    """One line for ``contactdyn run`` from ``Result.meta["joint_friction"]`` ("" when no joint has any)."""
    parts = [f"{name} b = {d['damping']:g}, τs = {d['friction_static']:g}, τk = {d['friction_kinetic']:g} "
             f"({d['source']})" for name, d in joints.items()]
    return ("joint damping and friction used: " + "; ".join(parts)) if parts else ""


def joint_friction_channels(system: Any, phases_of: list, samples: Any) -> dict[str, np.ndarray]:
    """``joint_friction`` [N·m or N] (per joint: damping + dry friction, a stuck joint's holding torque; from the
    output ``samples``) and ``joint_stuck`` (per joint, 1 stuck, 0 sliding or without dry friction)."""
    stuck = np.zeros((len(phases_of), system.nv))
    k = 0
    for _, run in groupby(phases_of, key=id):  # a run of samples in one phase: its modes at once
        run = list(run)
        for i, m in run[0].joint_modes:
            stuck[k:k + len(run), i] = float(m == STUCK)
        k += len(run)
    return {"joint_friction": samples.joint_friction.copy(), "joint_stuck": stuck}
