"""The events of a smooth phase: touch, separate, stop, reverse, turn, slip; the storm guard.

Within a smooth phase the modes (touching, sticking, sliding direction) and the task
phase are fixed. Events are zeros of functions of the state, located by ``solve_ivp``
on its dense output; each is terminal and fires when its function falls through zero:

- ``touch``: a free contact's normal gap [m] reaches zero (then the impact map,
  :mod:`contactdyn.model.impact`). The function is gap − (min(0, gap at the segment start) −
  ``TOUCH_TOL``): never zero at the start, so a re-touch right after a separation is seen; a gap that
  dips below zero and back within one step is found on the step's dense output (:class:`DipWatch`);
- ``separate``: a touching, unbonded contact's normal force F [N] reaches zero;
- ``stop``: a sliding contact's slip velocity along its sliding reference r falls to the
  stick band, v_t·r = v_ε [m/s] (``solver.stick_velocity``);
- ``reverse``: a slip from rest runs backwards past −v_ε (v_t·r = −v_ε); both also where the
  speed dips through and back within one step (:class:`DipWatch`);
- ``turn`` (2-D): the slip velocity turned 60° away from r, v_t·r − ½|v_t| + v_ε = 0
  (r is refreshed, no mode change; near rest and slowing it is decided as a stop, ``transitions.TURN_AT_REST``);
- ``slip``: a sticking contact's friction reaches the cone, g = μ_s F − |F_f| = 0
  (:class:`SlipWatch`, which also sees inside a step).

What happens at each event is decided in :mod:`contactdyn.hybrid.transitions`. At a corner of the
set-points, where no step straddles a jump of the forces, :func:`fired_across` finds the
events whose functions jump through zero there. The storm guard
(:class:`EventLog`): more than ``storm_count`` events within ``storm_window`` seconds, or
more than ``max_events`` in the run, stop with a :class:`SimulationError` naming them.

The event functions are written once (:func:`segment_events`) against the one pipeline's values
(:class:`~contactdyn.hybrid.pipeline_mode.PipelineMode`: its last calls', no second solve).
"""

from __future__ import annotations

import math
from collections import deque
from typing import Any

import numpy as np

from ..errors import SimulationError
from ..model.contact import ContactMode
from ..model.evaluation import Evaluation
from ..model.friction import cone_slack
from ..model.phases import Phase
from ..model.pipeline.pack import EV_FN, EV_GAP, EV_VT, EV_W
from ..model.system import System

__all__ = ["TOUCH_TOL", "AT_LIMIT", "terminal_event", "StageWatch", "StateWatch", "ValuesWatch", "AT_ONCE",
           "StageSwing", "DipSearch", "DipWatch", "SlipWatch", "StepBudget", "StepCollapse", "LawStall", "WorkWatch",
           "segment_events", "fired_across", "EventLog", "start_storm_cause"]

#: [m] a free contact touches when its gap falls TOUCH_TOL below min(0, its gap at the segment
#: start). Right after a separation the gap starts at 0 (± rounding): an event function that is
#: zero at the start misses a re-touch that lifts and returns within one step, and the tip then
#: passed through the surface unseen (case 2's writer, just after its impact).
TOUCH_TOL = 1e-13  # well above rounding of positions (~1e-16 m per metre)


class EventLog:
    """The run's event list, with the storm guard: too many events, or too many too close together."""

    def __init__(self, scene_name: str, solver, stats: dict[str, Any]):
        self.scene_name, self.solver, self.stats = scene_name, solver, stats
        self.events: list[dict[str, Any]] = []
        self.recent: deque[float] = deque(maxlen=solver.storm_count)  #: times [s] of the latest events

    def log(self, t: float, kind: str, name: str, check_storm: bool = True, **info) -> None:
        """Record an event at t [s]; with ``check_storm`` count it and stop a storm."""
        self.events.append({"t": t, "kind": kind, "name": name, **info})
        if not check_storm:
            return
        self.stats["events"] += 1
        self.recent.append(t)
        if self.stats["events"] > self.solver.max_events:
            raise SimulationError(f"{self.scene_name}: more than {self.solver.max_events} events by t = {t:.9g} s "
                                  f"(last: {kind} on {name}); " + (start_storm_cause(self.events, name) or
                                                                   "raise solver.max_events if this is expected"))
        if len(self.recent) == self.recent.maxlen and self.recent[-1] - self.recent[0] <= self.solver.storm_window:
            kinds = ", ".join(f"{e['kind']}:{e['name']}" for e in self.events[-5:])
            raise SimulationError(
                f"{self.scene_name}: event storm: {self.recent.maxlen} events within "
                f"{self.recent[-1] - self.recent[0]:.3g} s at t = {t:.9g} s (last: {kinds}); " +
                (start_storm_cause(self.events, name, since=self.recent[0]) or
                 _storm_cause(self.events[-self.recent.maxlen:], self.stats["singular_solves"])))


def _storm_cause(events: list[dict], singular: int = 0) -> str:
    """What a storm of these events says: a joint's stick and slip, or a contact's, chatter (or the state ran away);
    ``singular``: the transitions' calls so far whose holds were redundant (solved by least squares)."""
    joints = sorted({e["name"] for e in events if e["kind"].startswith("joint_")})
    if joints and len(joints) == len({e["name"] for e in events}):
        return (f"the stick and slip of joint {', '.join(joints)} chatter (its holding torque at its static limit), or "
                "the run diverged before it (a loop its gains, rate or delay make unstable); see "
                "solver.storm_count / storm_window")
    redundant = (f"; {singular} of the decisions met redundant holds (stuck joints and a stuck contact holding the "
                 "same motion leave their forces undetermined; they are split by the holds' limits, "
                 "contactdyn/model/joint_friction.py): is the "
                 "joints' dry friction above what the controller's torques overcome? (robot.joint_friction = "
                 "\"ignore\", or a lower [robot.joint.<joint>] friction)") if singular else ""
    return "the contact chatters (grazing or inconsistent stick/slip)" + redundant + \
        "; see solver.storm_count / storm_window"


START_STORM = 1e-3  #: [s] a storm whose contact events began this early started with the run


def start_storm_cause(events: list[dict], contact: str, since: float = 0.0) -> str | None:
    """The likely cause when the events flooding the run (since ``since`` [s]: a storm's first) are on one contact
    since t ≈ 0, else None."""
    on_contact = [e for e in events if e["kind"] != "phase"]
    if not on_contact or on_contact[0]["t"] > START_STORM or since > START_STORM or \
            sum(e["name"] == contact for e in on_contact) < 0.9 * len(on_contact):
        return None
    return (f"the events on contact {contact!r} began at t = {on_contact[0]['t']:.3g} s, with the run: the start "
            "posture does not suit the contact (initial penetration, the tip on the surface while moving or "
            "pulling away, a posture near a singularity); check robot.tip0, robot.q0 / q_seed and the contact's "
            "point, and `contactdyn run --verbose` for the posture found")


def terminal_event(fn, kind: str, contact: str):
    """Mark ``fn`` a terminal event of ``kind`` on ``contact`` that fires when it falls through zero."""
    fn.terminal = True
    fn.direction = -1
    fn.kind, fn.contact = kind, contact
    return fn


ALARM_TOL = 1e-9  #: [N] a ValuesWatch's value at its located instant above which its stage's alarm is false
#: a hold's event value of exactly 0 (its load exactly at the limit: |F_f| = μ_s F, |λ| = τ_s, λ = 0), kept above
#: zero: a value 0 at both ends of a step would count as a fall through zero, and the hold would break at the limit
AT_LIMIT = 5e-324


class DipSearch:
    """A watch's search of the step just ended for a dip of its g = value(t, x) − floor below zero and back, on the
    step's dense output (:class:`DipWatch`, a hold's :class:`StageWatch`). The watch keeps ``g_old``, ``g_end`` (g at
    the step's two ends), ``t_end`` [s], ``latch`` [s] and ``dipped``."""

    def could_dip(self, t_old: float) -> bool:
        """g positive at both ends of a step from t_old [s] (LSODA's steps may collapse: none then)."""
        return self.spans(t_old) and self.g_end > 0.0

    def spans(self, t_old: float) -> bool:
        """A step from t_old [s] that began with g positive (and finite: not the segment's first call)."""
        return 0.0 < self.g_old < math.inf and t_old < self.t_end

    def search(self, t_old: float, state_at, lo: float, hi: float) -> bool:
        """Where zero lies within g's swing over the step (``lo``, ``hi``: the least and greatest g its stages saw,
        and its ends), g searched for a dip (:func:`_dip`); one found is :attr:`latch`. Whether one was."""
        lo, hi = min(lo, self.g_old, self.g_end), max(hi, self.g_old, self.g_end)
        if lo >= hi - lo:  # (zero beyond the step's reach)
            return False
        found = _dip(lambda s: self.value(s, state_at(s)) - self.floor, t_old, self.t_end, self.g_old, self.g_end)
        if found is not None:
            self.latch, self.dipped = found, True
        return found is not None


class StageWatch(DipSearch):
    """An event of a held constraint whose function ``value(t, x)`` reads its holding force, which also sees inside
    a step: a stuck contact's ``slip`` (:class:`SlipWatch`), a stuck joint's ``joint_slip``, a pressing joint's
    ``release``.

    ``solve_ivp`` tests events only at step ends, and a held state may hardly move (every joint stuck: not at all,
    so the steps grow without bound): the load can reach the holding limit and fall back within one step unseen.
    The right-hand side reports g at every Runge–Kutta stage (:meth:`sample`); if a stage inside the step just
    taken saw g < 0 while the step end did not, the event reports a crossing, and while ``solve_ivp`` locates it on
    the dense output, g is held negative from that stage's time on, so the root found is the first crossing. A false
    alarm (a stage state off the final solution) is caught by the handler, which keeps the hold.

    A load that passes the limit and falls back between two stages (a brief pull on a pressing limit, the steps of
    a held state grown to most of a second) is found on the step's dense output, as a :class:`DipWatch` finds a dip:
    where the stages' values say zero lies within g's swing over the step (:meth:`dips`).

    ``floor``: g where the segment starts if a hold was decided just outside its limit within round-off (else 0);
    the event is g − floor through zero.
    """

    terminal = True
    direction = -1
    holds = True  #: a hold's event (slip, joint_slip, release): a value of exactly 0 is at its limit, held (AT_LIMIT)

    def __init__(self, value, kind: str, name: str, floor: float = 0.0, index: int | None = None, side: int = 0):
        self.value, self.kind, self.contact, self.index = value, kind, name, index  # value(t, x): g at a state
        self.side = side  #: a limit's side (+1 lower, −1 upper: ``release``)
        self.floor = floor
        self.t_end = -math.inf  #: last step end seen [s]
        self.g_old = self.g_end = math.inf  #: g at the step end before the last one, and at the last
        self.latch = math.inf  #: from this time on g is held negative [s]
        self.outside: list[float] = []  #: times [s] of the stages since the last step end that saw g < 0
        self.lo, self.hi = math.inf, -math.inf  #: the least and greatest g of the stages since the last step end
        self.swing = (math.inf, -math.inf)  #: theirs over the last step (its attempts': a gate, not an alarm)
        self.dipped = False  #: found by :meth:`dips` (the run's ``dips_seen_inside_a_step``)

    def sample(self, t: float, g: float) -> None:
        g -= self.floor
        if g < 0.0:
            self.outside.append(t)
        if g < self.lo:
            self.lo = g
        if g > self.hi:
            self.hi = g

    def __call__(self, t: float, x: np.ndarray) -> float:
        g = self.value(t, x) - self.floor
        if g == 0.0 and self.holds:  # (exactly at the limit: held; only a fall below zero breaks it)
            g = AT_LIMIT
        if t > self.t_end:  # a new step end (solve_ivp calls events at step ends in increasing t)
            t_old, self.t_end = self.t_end, t
            self.g_old, self.g_end = self.g_end, g
            self.swing, self.lo, self.hi = (self.lo, self.hi), math.inf, -math.inf
            if not self.outside:
                return g
            hidden = [ts for ts in self.outside if t_old < ts < t]
            self.outside = [ts for ts in self.outside if ts > t]
            if g > 0.0 and hidden:
                self.latch = min(hidden)
                return -1.0
            return g
        return min(g, -1e-300) if t >= self.latch else g  # root finding inside the last step

    def dips(self, t_old: float, state_at) -> bool:
        """Whether g dips below zero inside the step just ended, from t_old [s] to the last step end, between its
        stages, on its dense output ``state_at(t)`` (:class:`DipSearch`); if so g is held negative from the instant
        found (:attr:`latch`)."""
        if self.latch < math.inf or not self.could_dip(t_old):
            return False
        return self.search(t_old, state_at, *self.swing)


class StateWatch(StageWatch):
    """A :class:`StageWatch` of a function of the state alone, g = s x[k] − floor (``fn.state``: (k, s, floor); a
    sliding joint's ``joint_stick``): a compiled step's stages are checked at once (:meth:`sample_all`), its alarm
    confirmed where it is located (:meth:`unconfirmed`)."""

    holds = False  # (a slide's stop: reaching its floor fires)
    dips = None  # (its stages' alarm, confirmed where located)

    def __init__(self, fn):
        super().__init__(fn, fn.kind, fn.contact, index=fn.index)
        self.column, self.sign, self.offset = fn.state

    def sample_all(self, times, Ys: np.ndarray, Es: np.ndarray) -> None:
        """The stages' states Ys and event values Es (one per row; ``times()`` their times [s]): the first whose
        g < 0, if any (the extreme stage first: one reduction per step, the times only on an alarm)."""
        v = Ys[:, self.column].tolist()  # (a list: NumPy's reductions of 12 numbers cost ~3× more)
        if self.sign * (min(v) if self.sign > 0 else max(v)) - self.offset < 0.0:  # (g's own arithmetic)
            self.outside.append(float(times()[next(k for k, vk in enumerate(v) if self.sign * vk - self.offset < 0.0)]))

    def unconfirmed(self, t: float, x: np.ndarray) -> bool:
        """A stage's alarm (latched inside a step) whose located instant (t [s], x) still moves along the slide: a
        stage state off the solution, not the stop."""
        return self.latch < math.inf and self.sign * x[self.column] > 0.0


class ValuesWatch(StageWatch):
    """A :class:`StageWatch` of one of a call's event values, g = e[column] (a touching contact's
    ``separate``: its normal force): a compiled step's stages checked at once (:meth:`sample_all`, on their
    calls' event values). A contact at rest does not move, so the steps grow, and its force can pull and push again
    within one step: unseen at its ends. Its alarm is confirmed where it is located (:meth:`unconfirmed`). (A slide's
    ``stop`` and ``reverse`` are not alarmed by their stages: their slip velocities stray across the stick band so often
    that the false alarms cost more than the dips they would find; a :class:`DipWatch` searches the dense output.)"""

    holds = False  # (a contact's force reaching 0 lets it go: a compliant contact's at its surface)
    dips = None  # (its stages' alarm, confirmed where located)

    def __init__(self, fn, column: int):
        super().__init__(fn, fn.kind, fn.contact)
        self.column = column

    def sample_all(self, times, Ys: np.ndarray, Es: np.ndarray) -> None:
        e = Es[:, self.column].tolist()  # (a list, as StateWatch's)
        if min(e) < 0.0:  # (the smallest stage first: one reduction per step)
            self.outside.append(float(times()[next(k for k, ek in enumerate(e) if ek < 0.0)]))

    def unconfirmed(self, t: float, x: np.ndarray) -> bool:
        """A stage's alarm (latched inside a step) whose own value at its located instant (t [s], x) is still
        clearly above zero (by more than ALARM_TOL; a root found on the dense output sits at ~0): a stage state off
        the solution, not the event."""
        return self.latch < math.inf and self.value(t, x) > ALARM_TOL


AT_ONCE = (StateWatch, ValuesWatch)  #: the watches that see a compiled step's stages at once, and confirm an alarm

#: [-] a dip search samples a step's dense output at DIP_SAMPLES − 1 inner instants, then narrows on the lowest by
#: successive parabolas, at most DIP_REFINE of them
DIP_SAMPLES, DIP_REFINE = 8, 12
DIP_MODEL = 0.1  #: [-] a parabola's minimum within this × its value of g at its vertex: g's minimum (no dip if > 0)
#: [-] a step's fall through zero whose stages' values reach beyond its ends' by more than this × g_old − g_end is
#: searched for an earlier fall (DipWatch.first_fall): g may have swung through zero more than once (a search that
#: finds one fall only changes no root: g stays negative after it)
WIDE_SWING = 0.01


class StageSwing:
    """The stages' values of one function of the state, value(t, x), over each step: their least and greatest, which
    the :class:`DipWatch` events sharing it read (a slide's ``stop`` and ``reverse`` share its speed's). A compiled
    step gives them once per attempt (:meth:`sample_all`; ``of_stages(Es)``: each stage's value off its call's event
    values Es, one row per stage), any other call one at a time (:meth:`sample`)."""

    def __init__(self, value, of_stages):
        self.value, self.of_stages = value, of_stages
        self.lo, self.hi = math.inf, -math.inf  #: the last attempt's stages': least, greatest
        self.staged: list[tuple[float, float]] = []  #: (t [s], value) of the stages one at a time
        self.step: tuple[float, float, float, float] | None = None  #: (t_old, t, least, greatest) of the last step

    def sample(self, t: float, value: float) -> None:
        self.staged.append((t, value))

    def sample_all(self, times, Ys: np.ndarray, Es: np.ndarray) -> None:
        values = self.of_stages(Es)  # (a list of floats: NumPy's reductions of 12 numbers cost ~3× more)
        self.lo, self.hi = min(values), max(values)

    def over(self, t_old: float, t: float) -> tuple[float, float]:
        """(least, greatest) of the stages' values inside the step from t_old to t [s] (read once, at its end)."""
        step = self.step
        if step is None or step[0] != t_old or step[1] != t:
            lo, hi = self.lo, self.hi
            values = [v for ts, v in self.staged if t_old < ts < t]
            if values:
                lo, hi = min(lo, min(values)), max(hi, max(values))
            self.staged.clear()
            self.step = step = (t_old, t, lo, hi)
            self.lo, self.hi = math.inf, -math.inf
        return step[2], step[3]


class DipWatch(DipSearch):
    """An event of the state's motion, g = value(t, x) − ``floor`` through zero, that also sees g dip below zero and
    back within one step: a free contact's ``touch`` (its gap [m]), a slide's ``stop`` and ``reverse`` (its slip
    velocity along its direction, less or plus the stick band [m/s]).

    A tip that turns around just short of a surface, or just past it, has a positive gap at both ends of the step
    that grazes it (a parabola, integrated exactly, lets the steps grow without bound: a 1 mm dip into a rigid floor
    went unseen); a slide's speed can dip through zero and back the same way. The stages' values (its
    :class:`StageSwing`) say whether zero lies within g's own swing over the step; if so, :meth:`dips` searches the
    step's dense output for g < 0 (:data:`DIP_SAMPLES` instants, then parabolas through the lowest). A dip found holds
    g negative from its instant on, so the root located is the first crossing, on the dense output itself: never a
    false alarm. (Every method's steps: our DOP853's and LSODA's, :class:`~contactdyn.numerics.dop853._EventWatch`;
    ``solve_ivp``'s, :func:`~contactdyn.numerics.integrators.integrate`.)"""

    terminal = True
    direction = -1

    def __init__(self, swing: StageSwing, kind: str, name: str, floor: float, armed: bool = True):
        self.swing, self.kind, self.contact, self.floor = swing, kind, name, floor
        self.value = swing.value  #: value(t, x): g + floor
        self.t_end, self.g_old, self.g_end = -math.inf, math.inf, math.inf  #: the last step end [s], g before, there
        self.latch = math.inf  #: [s] from here on g is held negative (a dip found inside the last step)
        self.dipped = False  #: a dip was found (the run's ``dips_seen_inside_a_step``)
        #: False: g is held negative until a step end after the segment's start sees g > 0 (a slide from rest that
        #: starts at its band's edge stops only once it has left the band: :func:`stop_armed`)
        self.armed = armed

    def __call__(self, t: float, x: np.ndarray) -> float:
        g = self.value(t, x) - self.floor
        if t > self.t_end:  # a new step end (they come in increasing t; root finding calls inside the last step)
            if not self.armed:
                self.armed = g > 0.0 and self.t_end > -math.inf  # (never at the segment's start)
            self.t_end, self.latch = t, math.inf
            g = self._held(t, g)
            self.g_old, self.g_end = self.g_end, g
            return g
        return self._held(t, g)

    def _held(self, t: float, g: float) -> float:
        """g, held negative while the stop is not armed or from the latch on."""
        return min(g, -1e-300) if not self.armed or t >= self.latch else g

    def dips(self, t_old: float, state_at) -> bool:
        """Whether g dips below zero inside the step just ended, from t_old [s] to the last step end, on its dense
        output ``state_at(t)`` (:class:`DipSearch`); if so g is held negative from the instant found (:attr:`latch`)."""
        if not self.could_dip(t_old):
            return False
        lo, hi = self.swing.over(t_old, self.t_end)
        return self.search(t_old, state_at, lo - self.floor, hi - self.floor)

    def first_fall(self, t_old: float, state_at) -> None:
        """At a step from t_old [s] whose ends fall through zero (g_old > 0 ≥ g_end) but whose stages swung wider than
        its ends (:data:`WIDE_SWING`: g may have fallen through zero before and come back, a plane turning past a point
        far from its axis), g at DIP_SAMPLES − 1 inner instants of the dense output ``state_at(t)``: the first where
        g ≤ 0 is :attr:`latch`, so the root located is the first fall, not a later one."""
        if not self.spans(t_old) or self.g_end > 0.0:
            return
        lo, hi = self.swing.over(t_old, self.t_end)
        wide = WIDE_SWING * (self.g_old - self.g_end)
        if hi - self.floor <= self.g_old + wide and lo - self.floor >= self.g_end - wide:
            return
        for j in range(1, DIP_SAMPLES):
            s = t_old + (self.t_end - t_old) * j / DIP_SAMPLES
            if self.value(s, state_at(s)) - self.floor <= 0.0:
                self.latch = s
                return


def _dip(g, a: float, b: float, g_a: float, g_b: float) -> float | None:
    """An instant in (a, b) [s] where g < 0 (g_a, g_b > 0 at the ends), or None: g at DIP_SAMPLES − 1 inner instants,
    then successive parabolas through the lowest three (Brent's minimization without its golden fallback: a dip is
    smooth), until g < 0, or until a parabola's minimum is where g is and above zero."""
    ts = [a + (b - a) * j / DIP_SAMPLES for j in range(DIP_SAMPLES + 1)]
    gs = [g_a] + [g(s) for s in ts[1:-1]] + [g_b]
    k = min(range(DIP_SAMPLES + 1), key=gs.__getitem__)
    if gs[k] < 0.0:
        return ts[k]
    k = min(max(k, 1), DIP_SAMPLES - 1)
    points = [(ts[k - 1], gs[k - 1]), (ts[k], gs[k]), (ts[k + 1], gs[k + 1])]
    for _ in range(DIP_REFINE):
        (t0, g0), (t1, g1), (t2, g2) = sorted(points)
        slope = (g1 - g0) / (t1 - t0)  # the parabola g0 + slope (t − t0) + curve (t − t0)(t − t1) through the three
        curve = ((g2 - g1) / (t2 - t1) - slope) / (t2 - t0)
        if curve <= 0.0:  # (not convex: no minimum between them)
            return None
        tv = 0.5 * (t0 + t1) - 0.5 * slope / curve
        if not t0 < tv < t2:
            return None
        gv = g(tv)
        if gv < 0.0:
            return tv
        model = g0 + slope * (tv - t0) + curve * (tv - t0) * (tv - t1)
        if abs(gv - model) <= DIP_MODEL * gv:  # (the parabola is g there: its minimum, above zero, is g's)
            return None
        points = sorted(points + [(tv, gv)], key=lambda p: p[1])[:3]
    return None


class SlipWatch(StageWatch):
    """The ``slip`` event of a stuck contact, g = μ_s F − |F_f| [N] (:class:`StageWatch`).

    ``floor`` [N]: g where the segment starts if that is below 0 within the round-off slack of ``friction.in_cone``
    (a stick decided at the cone's edge), else 0; so such a stick slips as soon as its load grows, never held
    outside the cone unseen (a grip opening with μ_s = μ_k: both pads at the edge at once). A stick further outside
    is a wrong decision, left to the physics checks to report.
    """

    def __init__(self, value, name: str, mu_s: float, floor: float = 0.0):
        super().__init__(value, "slip", name, floor)
        self.mu_s = mu_s

    def g(self, ev: Evaluation) -> float:
        return self.mu_s * ev.normal_force[self.contact] - float(np.linalg.norm(ev.friction[self.contact]))


class _StepCount:
    """A terminal event at the end of the ``n``-th step end that counts (:meth:`counts`, given the step's length
    h [s]; the call at t0 has h = inf). ``solve_ivp`` calls events once per step end with increasing t (and,
    while locating a root, inside the last step: those calls neither count nor move it): the function is +1
    before that step end and −1 from there on, so the segment ends exactly there."""

    terminal = True
    direction = -1
    contact = ""

    def __init__(self, n: int):
        self.left = n
        self.t_end, self.t_fire = -math.inf, math.inf

    def counts(self, h: float) -> bool:
        raise NotImplementedError

    def __call__(self, t: float, x: np.ndarray) -> float:
        if t > self.t_end:
            if self.counts(t - self.t_end):
                self.left -= 1
                if self.left == 0:
                    self.t_fire = t
            self.t_end = t
        return -1.0 if t >= self.t_fire else 1.0


class WorkWatch(_StepCount):
    """The run's step budget (:mod:`contactdyn.hybrid.progress`): a terminal event at the step end where the run's steps
    reach ``left``; reports the simulated time to ``progress`` at each step end."""

    kind = "work"

    def __init__(self, left: int, progress=None):
        super().__init__(max(left, 1))
        self.progress = progress

    def counts(self, h: float) -> bool:
        return h != math.inf  # not the call at t0

    def __call__(self, t: float, x: np.ndarray) -> float:
        if t > self.t_end and self.t_end != -math.inf and self.progress is not None:
            self.progress(t)
        return super().__call__(t, x)


class StepBudget(_StepCount):
    """``auto``'s budget: a terminal event at the end of DOP853's ``budget``-th step (numerics.integrators)."""

    kind = "budget"

    def __init__(self, budget: int):
        super().__init__(budget + 1)  # the call at t0 counts too

    def counts(self, h: float) -> bool:
        return True


class StepCollapse(_StepCount):
    """A 2-D slide's guard: a terminal event at the end of the ``count``-th step shorter than ``ratio`` times the
    longest of the segment so far (the hybrid loop then checks whether a stiff mode holds the step: a slide
    coming to rest, its direction relaxing at a rate ∝ 1/|v_t|;
    :meth:`~contactdyn.hybrid.loop.HybridRun._collapse_check`)."""

    kind = "collapse"

    def __init__(self, ratio: float, count: int):
        super().__init__(count)
        self.ratio, self.longest = ratio, 0.0  #: [-], [s]

    def counts(self, h: float) -> bool:
        short = h < self.ratio * self.longest
        if math.isfinite(h):
            self.longest = max(self.longest, h)
        return short


class LawStall(_StepCount):
    """A law's NaN holding the steps back: a terminal event at the end of the ``count``-th step shorter than
    ``ratio`` times the segment's longest that follows a call with no answer from a finite state (``pipe``'s
    ``last_failed``, new since the step end before: the NaN rates that rejected the longer attempts). A step control
    that keeps meeting NaN there shrinks the step towards t's resolution and crawls on (a stage law NaN past some
    compression: 1e-15 s steps, until the run's budget); the hybrid loop then asks whether a law returned NaN or ±inf
    there (:func:`contactdyn.hybrid.loop._stall_check`). A trial state that overflows a law at a step too
    long is rejected and a step a few times shorter passes: that shrinks by far less than ``ratio``."""

    kind = "stall"

    def __init__(self, pipe, ratio: float, count: int):
        super().__init__(count)
        self.pipe, self.ratio = pipe, ratio
        self.longest = self.short = 0.0  #: [s] the segment's longest step, the last short step
        self.seen = pipe.last_failed

    def counts(self, h: float) -> bool:
        failed, self.seen = self.pipe.last_failed is not self.seen, self.pipe.last_failed
        short = failed and h < self.ratio * self.longest
        if short:
            self.short = h
        if math.isfinite(h):
            self.longest = max(self.longest, h)
        return short


#: event kinds whose functions read forces (normal force, friction, limit torque): these jump where the
#: set-points' acceleration or a force set-point jumps; touch, stop, reverse, turn and limit read the state
JUMPING = ("separate", "slip", "release", "joint_slip")
#: the joints' events watched at every Runge–Kutta stage (:class:`StageWatch`), as a stuck contact's ``slip`` is:
#: those of a hold that read its torque (a pressing limit's ``release``, a stuck joint's ``joint_slip``: a held
#: state may not move), and a sliding joint's ``joint_stick`` (its velocity can dip through zero and back within one
#: step, as a sampled law's 2 ms step lets it: the stop and the slip after it, unseen at the step ends)
STAGE_WATCHED = ("release", "joint_slip", "joint_stick")


def fired_across(events: list, t_before: float, t_after: float, x: np.ndarray, x_after: np.ndarray | None = None
                 ) -> list:
    """The events whose function falls through zero from (t_before, x) to (t_after, x_after), in list order
    (``x_after``: x unless given; a held command's jump, :mod:`contactdyn.hybrid.sampling`, changes the state).

    At a corner of the set-points (:class:`~contactdyn.laws.trajectory.Corner`) one segment ends at
    ``t_before`` and the next starts at ``t_after`` with the same state: a force that jumps
    there (a rigid contact's, with the reference's acceleration) is seen here, as a step
    straddling the corner would have seen it. Only functions of forces can jump (``JUMPING``):
    the others read the state alone.
    """
    fired = []
    x_after = x if x_after is None else x_after
    for e in events:
        if e.kind not in JUMPING:
            continue
        g = e.value if isinstance(e, SlipWatch) else e  # (a SlipWatch's call keeps step-end state)
        if g(t_before, x) > 0.0 >= g(t_after, x_after):
            fired.append(e)
    return fired


def _along(v: np.ndarray, r: tuple[float, ...]) -> float:
    """v·r [m/s]: a slip velocity (1 or 2 tangent components) along the mode's direction r, in Python floats (an
    event's value at every step end: a NumPy product of two 2-vectors costs more than the rest of the event)."""
    vs = v.tolist()
    return vs[0] * r[0] + vs[1] * r[1] if len(r) == 2 else vs[0] * r[0]


def _stages_along(at: int, r: tuple[float, ...]):
    """Es -> each stage's slip velocity along r [m/s], a list (its contact's event values' columns from ``at``)."""
    if len(r) == 1:
        return lambda E: [v * r[0] for v in E[:, at].tolist()]
    return lambda E: [a * r[0] + b * r[1] for a, b in E[:, at:at + 2].tolist()]


#: [-] a slide from rest whose slip along r starts within this × v_ε above the stick band v_ε is at the band's edge
#: (:func:`stop_armed`): the root of a located ``stop`` sits there, within the root finder's rounding
BAND_EDGE = 1e-6


def stop_armed(mode: ContactMode, v0: float, band: float) -> bool:
    """Is a slide's ``stop`` armed from its segment's start, its slip along r there v0 [m/s] (``band``: v_ε)? Not
    for a slide from rest that starts inside its stick band or at its edge (v0 ≤ v_ε (1 + BAND_EDGE)): it stops only
    once it has left the band (a step end with v·r > v_ε). Why: a stop decided at rest whose stick the cone cannot
    hold slides from rest where the holding force pushes, from the state as it was, its slip still at the band's edge
    (:func:`~contactdyn.hybrid.transitions._at_rest`); where a damping law slows that slip (the slide creeps toward
    its balance |F_f| = μ_k F below v_ε: the lever's hold at μ = 1e-3) a stop armed there fires at once and the same
    decision repeats at the same instant (an event storm). Inside the band a slide from rest could not stop before it
    left the band anyway (its stop falls through zero only from above): there this changes nothing."""
    return not mode.from_rest or v0 > band * (1.0 + BAND_EDGE)


def _turn_margin(v: np.ndarray, r: tuple[float, float], band: float) -> float:
    """The ``turn`` function v·r − ½|v| + v_ε [m/s] of a 2-D slip velocity v (|v| = √(v·v))."""
    v0, v1 = v.tolist()
    return v0 * r[0] + v1 * r[1] - 0.5 * math.sqrt(v0 * v0 + v1 * v1) + band


def _sampler(watches: list[StageWatch | StageSwing]):
    """sample(t, x): each watch's value at a stage (t [s], x), read off the runner's last call: no second solve."""
    def sample(t: float, x: np.ndarray) -> None:
        for w in watches:
            w.sample(t, w.value(t, x))
    return sample


def segment_events(system: System, modes: list[ContactMode], phase: Phase, t0: float, x0: np.ndarray, runner,
                   fun=None, swings: bool = True):
    """The event functions of one segment, and the right-hand side that feeds their stage watches.

    They read the mode ``runner``'s values (its last call's, no second solve: the one pipeline's mode,
    :class:`~contactdyn.hybrid.pipeline_mode.PipelineMode`). ``fun``: the right-hand side to integrate when it is
    not the runner's own. ``swings``: whether each :class:`StageSwing` also takes the calls made one at a time (the
    stages of DOP853 interpreted; a compiled step gives it its stages anyway); False for a method whose calls are not
    the stages of its steps (LSODA: each :class:`DipWatch` then gates on the step ends alone).
    """
    values = runner
    out: list = []
    watches: list[StageWatch | StageSwing] = []  # (what the stages feed)
    for ci, (c, mode) in enumerate(zip(system.contacts, modes, strict=True)):
        name = c.name
        if not mode.touching:  # (its gap may dip below the surface and back within one step: its stages watched)
            floor = min(values.gap(ci, t0, x0), 0.0) - TOUCH_TOL  # [m] never zero at the start
            watches.append(StageSwing(lambda t, x, i=ci: values.gap(i, t, x),
                                      lambda E, col=EV_W * ci + EV_GAP: E[:, col].tolist()))
            out.append(DipWatch(watches[-1], "touch", name, floor))
            continue
        if not c.spec.bonded:  # (its force may pull and push again within one step: watched at every stage)
            watches.append(ValuesWatch(terminal_event(lambda t, x, i=ci: values.normal_force(i, t, x), "separate",
                                                      name), EV_W * ci + EV_FN))
            out.append(watches[-1])
        if c.friction is None or not len(c.tangents):
            continue
        fr, band = c.friction, system.slip_band
        if mode.stuck:
            margin = lambda t, x, i=ci, mu=fr.mu_s: values.cone_margin(i, mu, t, x)  # noqa: E731
            g0, slack = margin(t0, x0), cone_slack(values.normal_force(ci, t0, x0), fr.mu_s)
            watches.append(SlipWatch(margin, name, fr.mu_s, g0 if -slack <= g0 < 0.0 else 0.0))
            out.append(watches[-1])
            continue
        r = tuple(float(c) for c in mode.slip)
        watches.append(StageSwing(lambda t, x, i=ci, r=r: _along(values.slip(i, t, x), r),
                                  _stages_along(EV_W * ci + EV_VT, r)))
        armed = stop_armed(mode, _along(values.slip(ci, t0, x0), r), band)
        for kind, floor in (("stop", band), ("reverse", -band)):  # (its speed may dip through the band and back)
            out.append(DipWatch(watches[-1], kind, name, floor, armed=armed or kind == "reverse"))
        if len(r) == 2:
            out.append(terminal_event(lambda t, x, i=ci, r=r, b=band: _turn_margin(values.slip(i, t, x), r, b), "turn",
                                      name))
    joints = system.limits.events(phase.limits, x0, getattr(values, "limit_torque", None))  # model.limits
    if phase.joint_modes:  # contactdyn.model.joint_friction
        joints += system.joint_friction.events(phase.joint_modes, phase.limits, x0, system.nQ, values.joint_hold)
    for fn in joints:
        if fn.kind in STAGE_WATCHED:  # watched at every stage (a held joint's state may not move; a slide may stop)
            fn = StateWatch(fn) if hasattr(fn, "state") else \
                StageWatch(fn, fn.kind, fn.contact, index=fn.index, side=getattr(fn, "side", 0))
            watches.append(fn)
        out.append(fn)
    fun = fun or values.rhs
    if not watches:
        return out, fun
    on_states = [w for w in watches if hasattr(w, "sample_all")]  # (a compiled step's stages at once)
    on_calls = [w for w in watches if not hasattr(w, "sample_all")]  # (they read the call's values, stage by stage)
    sample = _sampler(watches if swings else [w for w in watches if not isinstance(w, StageSwing)])

    def sample_states(times, Ys: np.ndarray, Es: np.ndarray) -> None:
        for w in on_states:
            w.sample_all(times, Ys, Es)

    def rhs(t: float, x: np.ndarray) -> np.ndarray:
        xd = fun(t, x)
        sample(t, x)
        return xd

    if fun is getattr(values, "rhs", None) and hasattr(values, "watched_step"):  # the one pipeline's compiled steps,
        rhs.step = values.watched_step(_sampler(on_calls) if on_calls else None,  # each stage sampled
                                       sample_states if on_states else None)
    for compiled in ("interpolant", "derivatives"):  # (the dense output's: its extra stages are watched by no one)
        if hasattr(fun, compiled):
            setattr(rhs, compiled, getattr(fun, compiled))
    return out, rhs
