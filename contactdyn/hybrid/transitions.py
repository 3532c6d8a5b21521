"""Mode transitions: what a located event does to the contact modes and the state.

At each event of :mod:`contactdyn.hybrid.events` (t fixed, x continuous unless an impact jumps Q̇):

- ``touch``: the contact touches; tangential chains anchor where the tip now is, the
  interface junction starts where its springs balance; a bonded touch maps velocities
  by the impact law (:mod:`contactdyn.model.impact`) and the contact slides or jams; every
  other rigid contact within ``CO_TOUCH`` of its surface and closing touches with it (logged
  as its own touch), the one impact holding them all;
- ``separate``: the contact lets go; damped surface ends relax from where they are;
- ``stop`` / ``reverse``: the slide has come to rest (|v_t| ≤ v_ε): decided at rest (below);
- ``turn``: the 2-D reference direction r is refreshed to the slip's own (no mode change), unless
  the slip is within ``TURN_AT_REST`` stick bands of rest and in the band or slowing: then it is a ``stop``;
- ``slip``: the stick's friction reached the cone |F_f| = μ_s F: it slides from rest where
  the holding force pushes (−F_f); a stage-only crossing not confirmed at the located point
  is a false alarm (``slip_check``), still stuck;
- a phase that ends at ``touch:<contact>`` starts the next phase;
- ``limit`` / ``release``: a joint reaches a position limit (plastic impact, then it presses)
  or its limit torque vanishes (:mod:`contactdyn.model.limits`); after any event, a joint whose
  limit torque pulls is released;
- ``joint_slip`` / ``joint_stick``: a stuck joint's holding torque reaches its static limit (it slides),
  or a sliding joint comes to rest (it sticks or reverses) (:mod:`contactdyn.model.joint_friction`);
  after any event, a stuck joint beyond its limit, or set moving by an impact, slides.

Then :meth:`Transitions.consistent` fixes whatever mode the state contradicts: a pulling
contact (F < −``FORCE_TOL``) separates; a stick outside the cone slides; a slide at rest
sticks if the friction needed to hold it is within μ_s F (its residual slip projected away,
:func:`~contactdyn.model.impact.project_velocity`), else slides where that force pushes, its
state as it was (:func:`_at_rest`). Where that projection is singular (it would stop a whole
motion whose slip is small only because the contact's row is: an arm through full stretch,
:func:`~contactdyn.model.impact.singular_stick`) the slide goes on where its slip goes.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from ..errors import SimulationError
from ..model.chain import NodeKind
from ..model.chain_forces import chain_sides
from ..model.friction import SLIP_ALARM, direction_of, in_cone, slip_acceleration, slip_velocity
from ..model.impact import impact, project_velocity, singular_stick
from ..model.system import System
from .at_rest import settle_together
from .charts import on_chart
from .events import AT_ONCE, BAND_EDGE, EventLog
from .pipeline_mode import mode_runner

__all__ = ["Transitions", "LastEvaluation", "FORCE_TOL", "TURN_AT_REST"]

FORCE_TOL = 1e-9  #: [N] slack of the normal-force sign test (pulling contacts separate)
#: [m] another rigid contact within this gap, closing, at a touch touches with it (one impact holds both): the
#: start's own touching test (contactdyn.model.system.System.initial_state)
CO_TOUCH = 1e-12
#: [-] a release seen inside a step is real if the located instant's pressing torque p [N·m or N] is at most
#: this × (1 + |p|): relative, with 1 N·m or N as the scale's floor (else a false alarm: still pressing)
RELEASE_ALARM = 1e-6
#: [-] a turn located with |v_t| ≤ this × v_ε, its slip in the band or slowing (:func:`_coming_to_rest`), is taken for
#: a slide coming to rest and decided at rest like a stop. Why: when a slide decelerates to rest, its ``turn`` and
#: ``stop`` tie within a rounding (the 5-DOF writer's turn fires at |v_t| = 4.1 v_ε); refreshing r there keeps a
#: slide of a few v_ε whose direction relaxes at a rate ∝ 1/|v_t| (stiff: 10x the steps). 10 leaves that case a
#: margin of ~2.4. Cost: a slowing slide slower than 10 v_ε that really turns loses its residual slip (≤ 10 v_ε) to
#: the decision at rest and, if the cone cannot hold it, restarts where the holding force pushes, not along its slip.
TURN_AT_REST = 10.0


class _After:
    """What an event handler leaves for the consistency pass: contacts to decide at rest, and released ones."""

    def __init__(self) -> None:
        self.rest: set[int] = set()  #: contacts to decide at rest (a stop)
        self.released: set[int] = set()  #: contacts that broke away at this event (not stuck again at once)


class LastEvaluation:
    """The model's Evaluation at an event instant: off the call that integrates the mode (``runner(modes, phase)``:
    the run's mode runner, :meth:`~contactdyn.hybrid.pipeline_mode.PipelineMode.evaluation`). Its last (t, x, modes,
    phase) and result kept: asked again at the same ones (the same t, x bit for bit, equal modes, the same phase
    object), the same Evaluation, not a second solve. Where a decision leaves everything as it was tried (a stick
    decided at rest, then the next consistency pass; the last pass, then the joints' check) the evaluation repeats
    exactly. A joint's stick-or-reverse decision reads only its holding torque (:meth:`joint_hold`: one plain
    call)."""

    def __init__(self, system: System, runner=None):
        self.system, self.runner = system, runner or mode_runner(system)
        self.key: tuple | None = None  #: (t [s], x's bytes, modes, phase) of ``ev``
        self.ev = None

    def __call__(self, t: float, x: np.ndarray, modes, phase):
        key = (t, x.tobytes(), tuple(modes), phase)
        if not self._kept(key):
            self.key, self.ev = key, self._evaluate(t, x, modes, phase)
        return self.ev

    def _kept(self, key: tuple) -> bool:
        """Is the kept Evaluation at ``key`` (t, x's bytes, modes, phase: the same phase object)?"""
        last = self.key
        return last is not None and last[3] is key[3] and last[0] == key[0] and last[1] == key[1] \
            and last[2] == key[2]

    def _evaluate(self, t: float, x: np.ndarray, modes, phase):
        return self.runner(modes, phase).evaluation(t, x)  # (PipelineMode.evaluation raises where there is no answer)

    def joint_hold(self, t: float, x: np.ndarray, modes, phase) -> dict[int, float]:
        """The stuck joints' holding torques [N·m or N] at (t [s], x), by joint: the kept Evaluation's where it is at
        these, else off one plain call of the mode (its event values), not a whole Evaluation; where that call has no
        answer (its status not 1), the Evaluation's, which says why."""
        if self._kept((t, x.tobytes(), tuple(modes), phase)):
            return self.ev.joint_hold
        mode = self.runner(modes, phase)
        if mode.values(t, x)[-1] == 1.0:
            return mode.joint_hold(t, x)
        return self(t, x, modes, phase).joint_hold


def _count_alarm(stats: dict, event, false_alarm: bool) -> bool:
    """Count a stage watch's event (events.StageWatch) in the run's stats: seen inside a step, and a false alarm
    (``false_alarm``, returned)."""
    stats["slips_seen_inside_a_step"] += int(getattr(event, "latch", math.inf) < math.inf)
    stats["slip_false_alarms"] += int(false_alarm)
    return false_alarm


def _false_alarm(stats: dict, log: EventLog, event, t: float, x: np.ndarray) -> bool:
    """An alarm of a watch of a step's stages at once (:data:`~contactdyn.hybrid.events.AT_ONCE`: a contact's
    ``separate``, a sliding joint's ``joint_stick``) that its located instant does not confirm (its
    ``unconfirmed``): counted, logged as ``<kind>_check``; True."""
    if not isinstance(event, AT_ONCE) or not _count_alarm(stats, event, event.unconfirmed(t, x)):
        return False
    log.events[-1]["kind"] += "_check"
    return True


class Transitions:
    """The mode decisions of one run: at events (:meth:`handle`) and at any instant (:meth:`consistent`)."""

    def __init__(self, system: System, log: EventLog, stats: dict[str, Any], impacts: list[dict[str, Any]],
                 phase_started=None, runner=None):
        self.system, self.scene = system, system.scene
        self.log, self.stats, self.impacts = log, stats, impacts
        #: phase_started(t, x, modes, phase, previous) -> x: a phase begun at an event (a sampled law's first
        #: sample, contactdyn.hybrid.sampling); None: nothing to do
        self.phase_started = phase_started
        #: the model at an instant (``runner``: the run's mode runners, LastEvaluation), the same instant's not twice
        self.evaluate = LastEvaluation(system, runner)

    def handle(self, t, x, modes, phase, event):
        """Apply a located event: (state, modes, phase) right after it.

        The event's kind picks its handler (:attr:`HANDLERS`: a new kind, a new handler); it changes ``modes`` in place
        and returns (x, phase, settle: then :meth:`consistent`). An unconfirmed alarm (:func:`_false_alarm`): none."""
        modes = list(modes)
        self.log.log(t, event.kind, event.contact, check_storm=event.kind not in self.UNCOUNTED)
        if _false_alarm(self.stats, self.log, event, t, x):
            return self.release_pulling(t, x, modes, phase)
        self.stats["dips_seen_inside_a_step"] += int(getattr(event, "dipped", False))
        after = _After()
        x, phase, settle = self.HANDLERS[event.kind](self, t, x, modes, phase, event, after)
        if settle:
            return self.settle(t, x, modes, phase, after.rest, after.released)
        return self.release_pulling(t, x, modes, phase)

    def settle(self, t, x, modes, phase, rest=frozenset(), released=frozenset()):
        """Decide the modes at an instant: after an event (``rest``, ``released``: see :meth:`consistent`) or where the
        law changed but no event fired (a phase start): :meth:`consistent`, the limits that pull released, then the
        items at rest checked together (:func:`~.at_rest.settle_together`). Returns (x, modes, phase)."""
        x, modes = self.consistent(t, x.copy(), list(modes), phase, rest, released)
        return settle_together(self, t, *self.release_pulling(t, x, modes, phase))

    def start(self, t, x, modes, phase):
        """(x, modes, phase) at a run's start: :meth:`consistent`, the joints at rest on a limit (``phase.limits``)
        pressing but those whose torque pulls, let go with no event (they never pressed); :meth:`settle_joints`; the
        items at rest checked together (:func:`~.at_rest.settle_together`)."""
        x, modes = self.consistent(t, x, modes, phase)
        return settle_together(self, t, *self.release_pulling(t, x, modes, phase, logged=False))

    def release_pulling(self, t, x, modes, phase, logged: bool = True):
        """Release, one at a time, the joints whose limit torque pulls (λ·side < 0) after an event (``logged``: as a
        ``release``; at the start they never pressed); then the joint friction modes the state contradicts
        (:meth:`settle_joints`)."""
        limits = self.system.limits
        while phase.limits and (pulling := limits.pulling(phase, self.evaluate(t, x, modes, phase))):
            x, phase = limits.release(self.system, x, phase, pulling[0][0])
            if logged:
                self.log.log(t, "release", limits.by_index[pulling[0][0]].name)
            x, modes = self.consistent(t, x, modes, phase)
        return self.settle_joints(t, x, modes, phase)

    def settle_joints(self, t, x, modes, phase):
        """Change, one at a time, the joint friction modes the state contradicts (a stuck joint beyond its static
        limit or moving slips; :meth:`~contactdyn.model.joint_friction.JointFriction.contradicted`), the contact modes
        decided again after each. Returns (x, modes, phase)."""
        for _ in range(2 * len(phase.joint_modes) + 1):
            if not phase.joint_modes:
                return x, modes, phase
            kind, joint, x, phase = self.system.joint_friction.contradicted(self.system, t, x, modes, phase,
                                                                            self.evaluate)
            if not kind:
                return x, modes, phase
            self.log.log(t, kind, joint)
            x, modes = self.consistent(t, x, modes, phase)
        raise SimulationError(f"{self.scene.name}: no consistent joint friction mode at t = {t:.9g} s "
                              f"(modes: {phase.joint_modes})")

    def _index(self, name: str) -> int:
        return next(k for k, c in enumerate(self.system.contacts) if c.name == name)

    def _on_touch(self, t, x, modes, phase, event, after):
        """Touching; a bonded touch maps velocities (impact) and slides or jams; a phase may end here."""
        i, contacts = self._index(event.contact), self.system.contacts
        touched = [i] + _touching_too(self.system, self.log, t, x, modes, i)  # (one impact holds them all)
        for j in touched:
            modes[j], x = self._touch(t, x, modes, j, co=j != i)
        names = [contacts[j].name for j in touched]
        if contacts[i].normal.chain.bonded_when_touching:
            x, imp = impact(self.system, t, x, modes, contacts[i], phase.limits)
            self._after_impact(imp, modes, after)
            self.impacts += _co_impacts(imp, names[1:])
        if phase.spec.until in {f"touch:{n}" for n in names} and phase.index + 1 < len(self.scene.phases):
            phase, previous = self.system.start_phase(phase.index + 1, t, x, phase), phase  # (the last runs on)
            self.log.log(t, "phase", phase.spec.name, check_storm=False)
            if self.phase_started is not None:
                x = self.phase_started(t, x, modes, phase, previous)
        return x, phase, True

    def _on_separate(self, t, x, modes, phase, event, after):
        """The contact lets go; damped surface ends relax from where they are."""
        i = self._index(event.contact)
        x = self.system.separate(x, self.system.contacts[i], self.evaluate(t, x, modes, phase))
        modes[i] = modes[i].separated()
        return x, phase, True

    def _on_stop(self, t, x, modes, phase, event, after):
        """A slide came to rest (``stop``, or ``reverse`` for a slip from rest): decide it at rest."""
        after.rest.add(self._index(event.contact))
        return x, phase, True

    def _on_turn(self, t, x, modes, phase, event, after):
        """2-D: the slip turned 60° from the reference: refreshed (no mode change), or a stop (_coming_to_rest)."""
        i = self._index(event.contact)
        ev = self.evaluate(t, x, modes, phase)
        if _coming_to_rest(self.system, self.system.contacts[i], x, ev):
            return self._on_stop(t, x, modes, phase, event, after)
        modes[i] = modes[i].with_(slip=direction_of(ev.slip[event.contact]), from_rest=False)
        return x, phase, False

    def _on_slip(self, t, x, modes, phase, event, after):
        """The cone is reached: slide from rest where the holding force pushes (or a false alarm)."""
        i = self._index(event.contact)
        c = self.system.contacts[i]
        ev = self.evaluate(t, x, modes, phase)
        self.stats["slips_seen_inside_a_step"] += int(event.latch < math.inf)
        if event.g(ev) <= SLIP_ALARM * c.friction.mu_s * max(ev.normal_force[c.name], 0.0):
            modes[i] = modes[i].with_(stuck=False, slip=direction_of(-ev.friction[c.name]), from_rest=True)
            after.released.add(i)
        else:  # a stage saw the cone left, the located point does not: a false alarm, still stuck
            self.log.events[-1]["kind"] = "slip_check"
            self.stats["slip_false_alarms"] += 1
        return x, phase, True

    def _on_limit(self, t, x, modes, phase, event, after):
        """A joint reaches a position limit (plastic impact, then it presses) or stops pressing (model.limits)."""
        if event.kind == "release" and getattr(event, "latch", math.inf) < math.inf:  # a stage's alarm: confirmed?
            pressing = event.side * self.evaluate(t, x, modes, phase).limit_torque.get(event.index, 0.0)
            if _count_alarm(self.stats, event, pressing > RELEASE_ALARM * (1.0 + abs(pressing))):
                self.log.events[-1]["kind"] = "release_check"  # (still pressing there: it keeps pressing)
                return x, phase, True
        x, phase, info, imp = self.system.limits.switch(self.system, t, x, modes, phase, event)
        self.log.events[-1].update(info)  # the joint, side, velocity before and impulse, with the event
        if imp is not None and imp.contact:  # a contact took part (its friction impulse too): recorded as at a touch
            self._after_impact(imp, modes, after, joint=info["joint"], limit_impulse=info["impulse"])
        elif imp is not None:
            self._release(imp, modes, after)
        return x, phase, True

    def _after_impact(self, imp, modes, after: _After, **extra) -> None:
        """Record an impact in ``Result.impacts``; the contact after it: stuck if it jammed, else sliding along its
        slip after the impact (or the impact's direction); the sticks it could not hold slide (:meth:`_release`)."""
        system = self.system
        self.impacts.append({"t": imp.t, "contact": imp.contact, "normal_impulse": imp.normal_impulse,
                             "friction_impulse": imp.friction_impulse.tolist(), "jammed": imp.jammed,
                             "energy_loss": imp.energy_loss, "v_before": imp.v_before.tolist(),
                             "v_after": imp.v_after.tolist(), "slip_before": imp.slip_before.tolist(),
                             "slip_after": imp.slip_after.tolist(), **extra})
        self._release(imp, modes, after)
        for name in imp.separated:  # holding it would have pulled: it lets go at the impact
            j = self._index(name)
            modes[j] = modes[j].separated()
            self.log.log(imp.t, "separate", name, check_storm=False)
        for name in imp.jammed_too:  # it slid into the impact, which stopped its slip
            j = self._index(name)
            modes[j] = modes[j].with_(stuck=True)
        i = self._index(imp.contact)
        c = system.contacts[i]
        if imp.jammed:
            modes[i] = modes[i].with_(stuck=True)
        elif c.friction is not None and len(c.tangents) and imp.contact not in imp.separated:  # (a limit's let go)
            moving = np.linalg.norm(imp.slip_after) > system.slip_band
            slip = imp.slip_after if moving else imp.direction
            if modes[i].stuck:  # a stick the impact could not hold (a limit's impact): it slides from here
                self._slide_from(imp.t, i, direction_of(slip), not moving, modes, after)
            elif np.any(slip):
                modes[i] = modes[i].with_(slip=direction_of(slip))

    def _release(self, imp, modes, after: _After) -> None:
        """The sticks the impact could not hold (their impulse left the cone) slide from it on, logged as slips
        (and not stuck again at the same instant)."""
        for name, d in imp.released.items():
            self._slide_from(imp.t, self._index(name), d, True, modes, after)

    def _slide_from(self, t: float, i: int, d: tuple[float, ...], from_rest: bool, modes, after: _After) -> None:
        """Contact i, stuck until an impact at t [s], slides along d from it on: logged as a slip, and not stuck
        again at the same instant."""
        modes[i] = modes[i].with_(stuck=False, slip=d, from_rest=from_rest)
        self.log.log(t, "slip", self.system.contacts[i].name)
        after.released.add(i)

    def _on_joint(self, t, x, modes, phase, event, after):
        """A stuck joint breaks away, or a sliding one comes to rest: sticks or reverses (model.joint_friction)."""
        x, phase, info = self.system.joint_friction.switch(self.system, t, x, modes, phase, event,
                                                           self.evaluate.joint_hold)
        self.log.events[-1].update(info)
        if event.kind == "joint_slip":  # (a joint_stick's alarm is counted where it is confirmed: _false_alarm)
            _count_alarm(self.stats, event, info.get("kind") == "joint_slip_check")
        return x, phase, True

    #: event kind -> handler (see :meth:`handle`)
    HANDLERS = {"limit": _on_limit, "release": _on_limit, "joint_slip": _on_joint, "joint_stick": _on_joint,
                "touch": _on_touch, "separate": _on_separate, "stop": _on_stop, "reverse": _on_stop,
                "turn": _on_turn, "slip": _on_slip, "chart": on_chart}
    UNCOUNTED = frozenset({"chart"})  #: event kinds that change coordinates, not motion: no event storm counts them

    def _touch(self, t, x, modes, i, co=False):
        """Mode after touch: touching, tangential chains anchored where the tip now is; touching with another
        (``co``) without slip, stuck (its stick holds in their impact)."""
        system = self.system
        c = system.contacts[i]
        nQ = system.nQ
        system.robot.update(x[:system.nv], x[nQ:nQ + system.nv])
        kin = system.kinematics(c, x)
        x = x.copy()
        offsets = []
        for k, dc in enumerate(c.tangent_chains):
            # shift the environment side rigidly so the two surface nodes meet undeformed; on a
            # re-touch the anchor already carries the previous touch's offset (and its masses too)
            old = modes[i].offsets[k] if k < len(modes[i].offsets) else 0.0
            u, p_tip, _, p_env, _ = chain_sides(c, dc, kin)
            s_tip, s_env = float(u @ p_tip), float(u @ p_env) + old
            robot_side = [n for n in dc.chain.nodes if n.side == "robot" and n.coord >= 0]
            env_side = [n for n in dc.chain.nodes if n.side == "environment" and n.coord >= 0]
            s_r = x[robot_side[-1].coord] if robot_side else s_tip
            s_e = x[env_side[-1].coord] if env_side else s_env  # the environment's surface node
            delta = s_r - s_e
            offsets.append(old + delta)
            for node in dc.chain.nodes:
                if node.side == "environment" and node.coord >= 0:
                    x[node.coord] += delta
                if node.side == "environment" and node.state >= 0:
                    x[2 * nQ + node.state] += delta
            if dc.junction_state >= 0:
                x[2 * nQ + dc.junction_state] = s_r
        if c.normal.junction_state >= 0:
            x[2 * nQ + c.normal.junction_state] = _junction_at_rest(system, c, kin, x)
        vt = slip_velocity(system, c, kin) if len(c.tangents) else np.zeros(0)
        slip, moving = modes[i].slip, len(vt) and float(np.linalg.norm(vt)) > system.slip_band
        if moving:
            slip = direction_of(vt)
        stuck = co and c.friction is not None and len(vt) > 0 and not moving
        return modes[i].with_(touching=True, stuck=stuck, slip=slip, offsets=tuple(offsets), relaxing=False), x

    def consistent(self, t, x, modes, phase, rest=frozenset(), released=frozenset()):
        """Fix the modes the state contradicts; return (x, modes).

        Pulling contacts separate; a stick whose friction is outside the cone
        |F_f| ≤ μ_s F slides (from rest, where −F_f points); a slide at rest (|v_t| within
        the stick band, or a contact in ``rest``: it just stopped) sticks if the friction
        needed to hold it is within the cone (its residual slip projected away), else slides
        where that force pushes (:func:`_at_rest`, which tells a singular stick row's slide
        on where its slip goes). Contacts in ``released`` (they
        broke away at a located ``slip`` event) are not stuck again at the same instant.
        Where no touching contact's mode is decided by its forces, nothing is solved.
        """
        system = self.system
        if not any(m.touching and _decided_by_forces(c) for c, m in zip(system.contacts, modes, strict=True)):
            return x, modes  # (a joint friction event of an arm on a bonded, frictionless contact)
        released = set(released)
        rest = set(rest)
        for _ in range(4 * len(modes) + 2):
            changed = False
            ev = self.evaluate(t, x, modes, phase)
            if not ev.regular:
                self.stats["singular_solves"] += 1
            for i, (c, mode) in enumerate(zip(system.contacts, modes, strict=True)):
                if not mode.touching:
                    continue
                F_n = ev.normal_force[c.name]
                if not c.spec.bonded and F_n < -FORCE_TOL * (1.0 + abs(F_n)):
                    x[:] = system.separate(x, c, ev)
                    modes[i] = mode.separated()
                    self.log.log(t, "separate", c.name)
                    changed = True
                    break
                if c.friction is None or not len(c.tangents):
                    continue
                mu_s = c.friction.mu_s
                if mode.stuck:
                    F_f = ev.friction[c.name]
                    if not in_cone(F_f, F_n, mu_s):
                        modes[i] = mode.with_(stuck=False, slip=direction_of(-F_f), from_rest=True)
                        self.log.log(t, "slip", c.name)
                        released.add(i)
                        changed = True
                        break
                    continue
                if i in released:
                    continue
                vt = ev.slip[c.name]
                speed, along = float(np.linalg.norm(vt)), float(vt @ np.asarray(mode.slip))  # [m/s]: |v_t|, v_t·r
                if i not in rest and speed > system.slip_band and not _at_stop(mode, along, speed, system.slip_band):
                    if along < 0.5 * speed:  # moving, but not along r: refresh r
                        modes[i] = mode.with_(slip=direction_of(vt), from_rest=False)
                    continue
                rest.discard(i)  # at rest: stick, or slide (_at_rest)
                x, modes[i], kind = _at_rest(system, self.evaluate, t, x, modes, phase, i, ev)
                if kind == "slip":
                    released.add(i)
                self.log.log(t, kind, c.name)
                changed = True
                break
            if not changed:
                return x, modes
        raise SimulationError(f"{self.scene.name}: no consistent contact mode at t = {t:.9g} s "
                              f"(modes tried: {modes})")


def _at_stop(mode, along: float, speed: float, band: float) -> bool:
    """Is a slide (not from rest) at its ``stop``: moving along r (its speed along r, ``along`` = v_t·r [m/s], at least
    half its ``speed`` |v_t|, as the turn's test) with ``along`` within BAND_EDGE of the stick band v_ε [m/s]? A 2-D
    slide's force turns from v̂ to r there (``contacts._slip_direction``), which moves every hold it loads: an event
    located there for a hold (the 5-DOF writer at 4 N·m per joint, a joint's check) leaves the slide on its stop,
    where its own event would fire at once, and a hold's check first, by a rounding, at every restart."""
    return not mode.from_rest and 0.5 * speed <= along <= band * (1.0 + BAND_EDGE)


def _coming_to_rest(system: System, c, x: np.ndarray, ev) -> bool:
    """Is contact c's 2-D slide, whose slip turned at x (``ev``: the Evaluation there), a slide coming to rest, to be
    decided at rest like a stop? Its slip v_t [m/s] within TURN_AT_REST stick bands of rest and either inside the band
    or slowing, v_t · ȧ_t ≤ 0 (ȧ_t: its rate [m/s²]). A slip that grows is leaving rest, not coming
    to it: its direction is its own (a slide from rest along −F_f of a stick trial whose holding force a split of
    redundant holds set, square to the only way the joints that slide move the tip: decided at rest, the same
    direction again, and its turn again at the same instant)."""
    slip = ev.slip[c.name]
    speed = float(np.linalg.norm(slip))
    if speed > TURN_AT_REST * system.slip_band:
        return False
    if speed <= system.slip_band:
        return True
    kin, nQ = _kinematics_at(system, c, x), system.nQ
    return float(slip @ slip_acceleration(system, c, kin, ev.xdot[nQ:2 * nQ])) <= 0.0


def _kinematics_at(system: System, c, x: np.ndarray):
    """Contact c's kinematics at x, the robot's and bodies' updated there (what its slip's rate reads too)."""
    system.update_at(x)
    return system.kinematics(c, x)


def _at_rest(system: System, evaluate, t: float, x: np.ndarray, modes, phase, i: int, ev):
    """Contact i's slide at rest at (t [s], x) (its slip within the stick band, or it just stopped; ``ev``: the
    Evaluation there in ``modes``, ``evaluate``: the run's LastEvaluation): (x, its mode, "stick" or "slip").

    Its stick is tried on x projected (:func:`~contactdyn.model.impact.project_velocity`: its residual slip set to
    exactly 0, what a stick row holds at velocity level): it sticks there if the friction that holds it is within
    μ_s F (a slide from rest, broken away and not launched yet, only strictly inside: friction.in_cone's hysteresis);
    else it slides from rest where that force pushes, from x as it was (the projection was the trial's). A projection
    at a singular stick row (:func:`~contactdyn.model.impact.singular_stick`) would stop a motion the cone cannot:
    no stick is tried, the slide goes on where its slip goes from the stop (its rate in ``modes``, along which it
    leaves the band: :func:`~contactdyn.model.friction.slip_acceleration`), from x as it was."""
    c, mode = system.contacts[i], modes[i]
    trial = list(modes)
    trial[i] = mode.with_(stuck=True)
    x_stuck = project_velocity(system, x, trial, phase.limits, phase.joint_modes)
    nQ = system.nQ
    kin = _kinematics_at(system, c, x)  # (once: the singularity's test and the slip's rate)
    if singular_stick(system, c, x, x_stuck, kin):
        a_t = slip_acceleration(system, c, kin, ev.xdot[nQ:2 * nQ])
        return x, mode.with_(slip=direction_of(a_t), from_rest=False), "slip"
    ev_stuck = evaluate(t, x_stuck, trial, phase)
    F_f = ev_stuck.friction[c.name]
    if in_cone(F_f, ev_stuck.normal_force[c.name], c.friction.mu_s, strictly=mode.from_rest):
        return x_stuck, trial[i], "stick"
    return x, mode.with_(slip=direction_of(-F_f), from_rest=True), "slip"


def _decided_by_forces(c) -> bool:
    """Is a touching contact's mode decided by its forces: can it pull off (not bonded), or stick and slip?"""
    return not c.spec.bonded or (c.friction is not None and len(c.tangents) > 0)


def _junction_at_rest(system: System, c, kin, x: np.ndarray) -> float:
    """[m] where the two surfaces of contact c's normal chain meet: the interface junction's starting position.

    Damped surface ends have states (they relax after a separation): they meet where they
    are, the touch point. Undamped ends follow their stages at once; there the junction
    starts where the two interface stages' springs balance (zero compressions on a first
    touch; on a re-touch both stages share the overlap instead of one taking all of it).
    """
    dc = c.normal
    chain, nQ = dc.chain, system.nQ
    ends = [chain.nodes[chain.env_surface].state, chain.nodes[chain.robot_surface].state]
    if min(ends) >= 0:
        return 0.5 * float(x[2 * nQ + ends[0]] + x[2 * nQ + ends[1]])
    u, p_tip, _, p_env, _ = chain_sides(c, dc, kin)

    def position(node: int) -> float:
        n = chain.nodes[node]
        if n.coord >= 0:
            return float(x[n.coord])
        if n.state >= 0:
            return float(x[2 * nQ + n.state])
        return float(u @ (p_tip if n.kind == NodeKind.TIP else p_env))

    (e,) = [s for s in chain.stages if s.upper == chain.env_surface]
    (r,) = [s for s in chain.stages if s.lower == chain.robot_surface]
    ke, kr = e.kelvin_voigt[0], r.kelvin_voigt[0]  # a junction joins affine stages only (chain._check)
    return (ke * position(e.lower) + kr * position(r.upper)) / (ke + kr)


def _touching_too(system: System, log: EventLog, t: float, x: np.ndarray, modes, i: int) -> list[int]:
    """The other rigid contacts that touch at rigid contact i's touch at t [s] (each logged as a touch): not touching
    yet, |gap| within CO_TOUCH [m] and closing (the normal velocity < 0). Located one at a time, simultaneous touches
    (a flat landing) would take their impacts in turn, each pulling on the last (an impact is unilateral: that one
    lets go, and touches again a rounding later): the impact holds them together. With friction, one arriving
    without slip holds by its stick (the impact's cone check lets it slide if it cannot); one sliding slides or jams
    through the impact as any other sliding contact does (:func:`~contactdyn.model.impact.impact`)."""
    if not system.contacts[i].normal.chain.bonded_when_touching:
        return []
    nQ = system.nQ
    system.robot.update(x[:system.nv], x[nQ:nQ + system.nv])
    out = []
    for j, c in enumerate(system.contacts):
        if j == i or modes[j].touching or c.spec.bonded or not c.normal.chain.bonded_when_touching:
            continue
        kin = system.kinematics(c, x)
        gap, closing = kin.gap, float(kin.normal @ (kin.v_tip - kin.v_env))
        if abs(gap) <= CO_TOUCH and closing < 0.0:
            log.log(t, "touch", c.name, check_storm=False)
            out.append(j)
    return out


def _co_impacts(imp, names: list[str]) -> list[dict]:
    """``Result.impacts`` entries of the contacts that touched with ``imp``'s own, each its normal and friction
    impulses [N·s] in the one impact, jammed if its slide stopped there (its loss and velocities are on the located
    contact's entry, ``with`` names it)."""
    def friction(name):  # a slide's −μ_k FΔt d, else its sticks' impulses
        if name in imp.slid:
            return imp.slid[name]
        return [v for (who, kind, _), v in imp.row_impulses.items() if who == name and kind == "t"]

    return [{"t": imp.t, "contact": name, "normal_impulse": float(imp.row_impulses.get((name, "n", 0), 0.0)),
             "friction_impulse": friction(name), "jammed": name in imp.jammed_too, "energy_loss": 0.0,
             "v_before": imp.v_before.tolist(),
             "v_after": imp.v_after.tolist(), "slip_before": [], "slip_after": [], "with": imp.contact}
            for name in names]
