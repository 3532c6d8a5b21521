"""Event-driven hybrid integration: smooth phases, located events, impact maps.

Within a smooth phase the modes (touching, sticking, sliding direction) and the task
phase are fixed and ``solve_ivp`` integrates with error control. Events are zeros of
functions of the state, located by ``solve_ivp`` on its dense output:

- ``touch``: a contact's normal gap reaches zero (then the impact map, where touching
  makes velocities jump; with friction it slides or jams, see ``System.impact``);
- ``separate``: a touching contact's normal force reaches zero;
- ``stop``: a sliding contact's slip velocity along its sliding direction r falls to
  the stick band v_ε (``solver.stick_velocity``); then it sticks if the friction needed
  to hold it stays within μ_s F, else it slides on where that force pushes
  (``reverse``: the same decision for a slip from rest that runs backwards past −v_ε);
- ``turn`` (2-D): the slip velocity turned 60° away from r; r is refreshed (no mode
  change; it keeps ``stop`` meaningful and the friction force continuous in a segment);
- ``slip``: a sticking contact's friction reaches the cone, |F_f| = μ_s F; it slides
  from rest in the direction the holding force pushes (−F_f);
- phase ends (a time, or ``touch:<contact>``).

Coulomb friction is never smoothed: sliding is F_f = −μ_k F d (+ viscous −c v_t) with d
the slip direction, sticking is a constraint row whose force is an unknown.

Stick/slip guard (the band v_ε, default 1e-9 m/s). A slip that starts from rest keeps
the direction chosen at break-away (2-D: the consistent one, below) until v_t·r > v_ε,
and no ``stop`` is declared
before it has risen above v_ε; a slide stops when v_t·r falls back to v_ε, and the
residual slip is then removed by the smallest kinetic-energy-norm velocity change that
keeps every constraint (``System.project_velocity``). So a stick → slip → stick cycle
needs the slip speed to cross v_ε: no zero-length slides and no event storm at the
cone's edge (a push that holds exactly at μ F, or chatter around it, slides at v ≈ 0
with |F_f| = μ_k F instead of switching at every step). Its error, per stop: the stop
is located v_ε/|a_t| early, a velocity jump ≤ v_ε, a position error ≤ v_ε²/(2|a_t|).
Mode decisions at rest compare |F_f| with μ_s F with a relative slack of 1e-10.

Three more guards keep the events exact and the cost bounded. A stuck contact's state
may not move at all, so ``solve_ivp`` (which tests events at step ends only) could step
over a whole excursion out of the cone: the friction impulses are integrated (their error
control makes the step follow the forces) and the ``slip`` event also looks at the
Runge–Kutta stages inside each step (:class:`_SlipWatch`). A 2-D slip from rest starts
along the consistent direction (where it accelerates, ``System._launch_directions``), and
its segment is integrated by LSODA: near v_t = 0 the direction of 2-D friction relaxes at
a rate ∝ 1/|v_t|, stiff for an explicit method (the scene's method takes over at the next
event, or if LSODA fails). After a friction event the next segment starts with the step
size the solver had reached.

Guards against what the band cannot prevent: more than ``storm_count`` events within
``storm_window`` seconds, or more than ``max_events`` in the run, stop with a
:class:`SimulationError` naming the events.

Cost. Each (modes, phase) is compiled once into a :class:`~contactdyn.rhsplan.ModePlan`
(the right-hand side as one affine map and one small solve, ~8 µs per call for B1 against
~50 µs for :meth:`System.evaluate`); the event functions read its values, and the output
samples are computed all at once per segment. A plan that cannot represent the system
(motors, force-reading controllers, a 2-D slip launching from rest, the energy audit)
falls back to :meth:`System.evaluate`; ``Result.stats["fallback_modes"]`` says why.
``solver.method = "auto"`` picks DOP853, or Radau for a stiff segment
(:mod:`contactdyn.integrators`); ``RK4`` takes fixed steps of ``solver.max_step``. An
integration failure reports what the state says: a singular contact system or stiffness.
"""

from __future__ import annotations

import math
import time
from collections import deque
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np
from scipy.integrate import solve_ivp

from .chain import NodeKind
from .contact import ContactMode
from .drives import drive_channels
from .errors import SceneError, SimulationError
from .integrators import (
    EXPLICIT,
    FIXED,
    IMPLICIT,
    STABILITY_RADIUS,
    STEP_BUDGET,
    FiniteDifferenceJacobian,
    jacobian_eigenvalues,
    solver_class,
    stability_bound,
)
from .limits import LIMIT_EVENTS, limit_channels, rate_limit_report
from .result import Result
from .rhsplan import ModePlan, Samples, cached_plan
from .scene import Scene, load_scene
from .system import CONE_TOL, FORCE_ABS_TOL, Evaluation, Phase, System

__all__ = ["simulate", "run_system", "prepare"]

FORCE_TOL = 1e-9  #: [N] slack of the normal-force sign test (pulling contacts separate)
#: events after which the next segment starts with the step size the solver had reached (friction
#: mode switches change the forces, not the time scales; an impact or a separation does, so they restart)
RESUME_STEP = ("stop", "reverse", "slip", "turn")
LAUNCH_METHOD = "LSODA"  #: for segments where a 2-D slip starts from rest (see _Run._method)
SLIP_ALARM = 1e-6  #: a located slip is real if |F_f| ≥ (1 − this) μ_s F there (else a false alarm)
#: [m] a free contact touches when its gap falls TOUCH_TOL below min(0, its gap at the segment
#: start). Right after a separation the gap starts at 0 (± rounding): an event function that is
#: zero at the start misses a re-touch that lifts and returns within one step, and the tip then
#: passed through the surface unseen (case 2's writer, just after its impact).
TOUCH_TOL = 1e-13  # well above rounding of positions (~1e-16 m per metre)


@dataclass
class _Segment:
    t0: float
    t1: float
    modes: list[ContactMode]
    phase: Phase
    sol: Any
    plan: ModePlan


class _Cache:
    """Evaluations shared by the event functions of one step (they see the same states)."""

    def __init__(self, system: System, modes: list[ContactMode], phase: Phase):
        self.system, self.modes, self.phase = system, modes, phase
        self.key: tuple[float, bytes] | None = None
        self.value: Evaluation | None = None

    def __call__(self, t: float, x: np.ndarray) -> Evaluation:
        key = (t, x.tobytes())
        if key != self.key:
            self.value = self.system.evaluate(t, x, self.modes, self.phase)
            self.key = key
        return self.value  # type: ignore[return-value]


class _SlipCache:
    """Slip velocities [m/s] of the sliding contacts at (t, x): kinematics only, no linear solve."""

    def __init__(self, system: System, names: list[str]):
        self.system = system
        self.contacts = [c for c in system.contacts if c.name in names]
        self.key: tuple[float, bytes] | None = None
        self.value: dict[str, np.ndarray] = {}

    def __call__(self, t: float, x: np.ndarray) -> dict[str, np.ndarray]:
        key = (t, x.tobytes())
        if key != self.key:
            system, nQ, nv = self.system, self.system.nQ, self.system.nv
            system.robot.update(x[:nv], x[nQ:nQ + nv])
            self.value = {c.name: system.slip_velocity(c, system.kinematics(c, x)) for c in self.contacts}
            self.key = key
        return self.value


def _event(fn, kind: str, contact: str):
    fn.terminal = True
    fn.direction = -1
    fn.kind, fn.contact = kind, contact
    return fn


class _SlipWatch:
    """The ``slip`` event of a stuck contact, g = μ_s F − |F_f|, which also sees inside a step.

    ``solve_ivp`` tests events only at step ends, and a stuck robot's state may hardly move:
    the friction a push needs can leave the cone and come back within one step unseen. The
    right-hand side reports g at every Runge–Kutta stage (:meth:`sample`); if a stage inside
    the step just taken saw g < 0 while the step end did not, the event reports a crossing,
    and while ``solve_ivp`` locates it on the dense output, g is held negative from that
    stage's time on, so the root found is the first crossing. A false alarm (a stage state
    off the final solution) is caught by the handler, which keeps the stick.
    """

    terminal = True
    direction = -1

    def __init__(self, value, name: str, mu_s: float):
        self.value, self.contact, self.mu_s = value, name, mu_s  # value(t, x): g at a state
        self.kind = "slip"
        self.t_end = -math.inf  #: last step end seen [s]
        self.latch = math.inf  #: from this time on g is held negative [s]
        self.samples: list[tuple[float, float]] = []  #: (t, g) at the stages since the last step end

    def g(self, ev: Evaluation) -> float:
        return self.mu_s * ev.normal_force[self.contact] - float(np.linalg.norm(ev.friction[self.contact]))

    def sample(self, t: float, g: float) -> None:
        self.samples.append((t, g))

    def __call__(self, t: float, x: np.ndarray) -> float:
        g = self.value(t, x)
        if t > self.t_end:  # a new step end (solve_ivp calls events at step ends in increasing t)
            t_old, self.t_end = self.t_end, t
            hidden = [ts for ts, gs in self.samples if t_old < ts < t and gs < 0.0]
            self.samples = [(ts, gs) for ts, gs in self.samples if ts > t]
            if g > 0.0 and hidden:
                self.latch = min(hidden)
                return -1.0
            return g
        return min(g, -1e-300) if t >= self.latch else g  # root finding inside the last step


class _StepBudget:
    """``auto``'s budget: a terminal event at the end of DOP853's ``budget``-th step (see integrators).

    ``solve_ivp`` calls events once per step end with increasing t (and, while locating a
    root, inside the last step): the function is +1 before the step end where the budget
    ran out and −1 from there on, so the segment ends exactly there.
    """

    terminal = True
    direction = -1
    kind = "budget"
    contact = ""

    def __init__(self, budget: int):
        self.budget, self.count = budget, 0
        self.t_end, self.t_fire = -math.inf, math.inf

    def __call__(self, t: float, x: np.ndarray) -> float:
        if t > self.t_end:
            self.t_end = t
            self.count += 1
            if self.count > self.budget and self.t_fire == math.inf:
                self.t_fire = t
        return -1.0 if t >= self.t_fire else 1.0


def _events(system: System, modes: list[ContactMode], phase: Phase, t0: float, x0: np.ndarray,
            plan: ModePlan | None = None):
    """The event functions of one segment, and the right-hand side that feeds their stage watches."""
    if plan is not None:
        return _plan_events(system, modes, plan, t0, x0)
    cache = _Cache(system, modes, phase)
    slip = _SlipCache(system, [c.name for c, m in zip(system.contacts, modes, strict=True)
                               if m.touching and not m.stuck and c.friction is not None and len(c.tangents)])
    out: list = []
    watches: list[_SlipWatch] = []
    for c, mode in zip(system.contacts, modes, strict=True):
        name = c.name
        if not mode.touching:
            floor = min(cache(t0, x0).gap[name], 0.0) - TOUCH_TOL  # [m] never zero at the start
            out.append(_event(lambda t, x, n=name, g0=floor: cache(t, x).gap[n] - g0, "touch", name))
            continue
        if not c.spec.bonded:
            out.append(_event(lambda t, x, n=name: cache(t, x).normal_force[n], "separate", name))
        if c.friction is None or not len(c.tangents):
            continue
        fr, band = c.friction, system.slip_band
        if mode.stuck:
            watch = _SlipWatch(None, name, fr.mu_s)
            watch.value = lambda t, x, w=watch: w.g(cache(t, x))
            watches.append(watch)
            out.append(watches[-1])
            continue
        r = np.asarray(mode.slip, float)
        out.append(_event(lambda t, x, n=name, r=r, b=band: float(slip(t, x)[n] @ r) - b, "stop", name))
        out.append(_event(lambda t, x, n=name, r=r, b=band: float(slip(t, x)[n] @ r) + b, "reverse", name))
        if len(r) == 2:
            out.append(_event(lambda t, x, n=name, r=r, b=band: float(slip(t, x)[n] @ r)
                              - 0.5 * float(np.linalg.norm(slip(t, x)[n])) + b, "turn", name))
    out += system.limits.events(phase.limits, x0, lambda t, x: cache(t, x).limit_torque)
    if not watches:
        return out, system.rhs(modes, phase)

    def rhs(t: float, x: np.ndarray) -> np.ndarray:
        ev = system.evaluate(t, x, modes, phase)
        for w in watches:
            w.sample(t, w.g(ev))
        return ev.xdot

    return out, rhs


def _plan_events(system: System, modes: list[ContactMode], plan: ModePlan, t0: float, x0: np.ndarray):
    """:func:`_events` on a compiled plan's values (same functions, same order)."""
    out: list = []
    watches: list[_SlipWatch] = []
    for ci, (c, mode) in enumerate(zip(system.contacts, modes, strict=True)):
        name = c.name
        if not mode.touching:
            floor = min(plan.gap(ci, t0, x0), 0.0) - TOUCH_TOL
            out.append(_event(lambda t, x, i=ci, g0=floor: plan.gap(i, t, x) - g0, "touch", name))
            continue
        if not c.spec.bonded:
            out.append(_event(lambda t, x, i=ci: plan.normal_force(i, t, x), "separate", name))
        if c.friction is None or not len(c.tangents):
            continue
        fr, band = c.friction, system.slip_band
        if mode.stuck:
            def value(t, x, i=ci, mu=fr.mu_s):
                F_f = plan.stick_force(i, t, x)
                return mu * plan.normal_force(i, t, x) - math.sqrt(float(F_f @ F_f))

            watches.append(_SlipWatch(value, name, fr.mu_s))
            out.append(watches[-1])
            continue
        r = np.asarray(mode.slip, float)
        out.append(_event(lambda t, x, i=ci, r=r, b=band: float(plan.slip(i, t, x) @ r) - b, "stop", name))
        out.append(_event(lambda t, x, i=ci, r=r, b=band: float(plan.slip(i, t, x) @ r) + b, "reverse", name))
        if len(r) == 2:
            out.append(_event(lambda t, x, i=ci, r=r, b=band: float(plan.slip(i, t, x) @ r)
                              - 0.5 * float(np.linalg.norm(plan.slip(i, t, x))) + b, "turn", name))
    out += system.limits.events((), x0)  # (a plan has no joint pressing on a limit)
    if not watches:
        return out, plan.rhs
    fun = plan.rhs

    def rhs(t: float, x: np.ndarray) -> np.ndarray:
        xd = fun(t, x)
        for w in watches:
            w.sample(t, w.value(t, x))  # the plan's last call: no second solve
        return xd

    return out, rhs


def simulate(scene: Scene | str | Path, overrides: dict[str, Any] | None = None) -> Result:
    """Run a scene (an object, a path, or a name in ``sims/``) and return its Result."""
    if not isinstance(scene, Scene):
        scene = load_scene(scene, overrides)
    elif overrides:
        from .scene import parse_scene

        scene = parse_scene(scene.document, overrides, scene.file)
    wall0 = time.perf_counter()
    system = System(scene)
    return _Run(system).run(wall0)


def prepare(scene: Scene) -> tuple[System, list[ContactMode], Phase, np.ndarray]:
    """The system, consistent initial modes, first phase and initial state of a scene (for benchmarks)."""
    system = System(scene)
    run = _Run(system)
    x, modes = system.initial_state()
    phase = system.start_phase(0, 0.0, x, None)
    x, modes = run._consistent(0.0, x, modes, phase)
    return system, modes, phase, x


def run_system(system: System) -> Result:
    """Simulate an already built system (its wall time excludes loading the scene and robot)."""
    return _Run(system).run(time.perf_counter())


class _Run:
    def __init__(self, system: System):
        self.system = system
        self.scene = system.scene
        self.solver = system.scene.solver
        self.segments: list[_Segment] = []
        self.events: list[dict[str, Any]] = []
        self.impacts: list[dict[str, Any]] = []
        self.recent: deque[float] = deque(maxlen=self.solver.storm_count)
        self.next_step: float | None = None  #: [s] first step of the next segment (None: solver's choice)
        if self.solver.method in FIXED and not math.isfinite(self.solver.max_step):
            raise SceneError("solver.max_step", f"the step [s] of the fixed-step method {self.solver.method}",
                             "no max_step", self.scene.file)
        self.stats = {"steps": 0, "rhs_evals": 0, "events": 0, "segments": 0, "singular_solves": 0,
                      "slips_seen_inside_a_step": 0, "slip_false_alarms": 0}
        self.plans: dict[tuple, ModePlan] = {}
        self.auto_state: str | None = None  #: ``auto``: the method fixed for the current mode (None: not yet)
        self.fallbacks: dict[str, int] = {}  #: reasons a mode ran on System.evaluate, with counts

    def _plan(self, modes: list[ContactMode], phase: Phase) -> ModePlan:
        """The compiled right-hand side of (modes, phase), built once per system and kept."""
        key = (tuple(modes), id(phase))
        plan = self.plans.get(key)
        if plan is None:
            plan = self.plans[key] = cached_plan(self.system, modes, phase)
        if not plan.ok:
            self.fallbacks[plan.reason] = self.fallbacks.get(plan.reason, 0) + 1
        return plan

    # ---- main loop -------------------------------------------------------------------
    def run(self, wall0: float) -> Result:
        """Integrate the whole scene; numerical breakdowns become a SimulationError saying where."""
        try:
            return self._run(wall0)
        except (np.linalg.LinAlgError, FloatingPointError, OverflowError, ZeroDivisionError) as exc:
            t = self.segments[-1].t1 if self.segments else 0.0
            raise SimulationError(f"{self.scene.name}: numerical failure after t = {t:.9g} s "
                                  f"({type(exc).__name__}: {exc}); check the scene's magnitudes "
                                  "(initial velocities, gains, stiffness)") from None

    def _run(self, wall0: float) -> Result:
        system, T = self.system, self.scene.duration
        x, modes = system.initial_state()
        phase = system.start_phase(0, 0.0, x, None)
        t = 0.0
        x, modes = self._consistent(t, x, modes, phase)
        while t < T:
            until = phase.spec.until
            t_end = min(T, until) if isinstance(until, float) else T
            if t_end <= t:
                phase = self._next_phase(phase, t, x)
                continue
            h0 = min(self.next_step, t_end - t) if self.next_step else None
            plan = self._plan(modes, phase)
            fun = plan.rhs if plan.ok else system.rhs(modes, phase)
            scene_method = self.solver.method if self.solver.method != "auto" else (self.auto_state or "DOP853")
            for method in dict.fromkeys((self._method(modes, scene_method), scene_method)):
                events, rhs = _events(system, modes, phase, t, x, plan if plan.ok else None)
                if self.solver.method == "auto" and method == "DOP853" and self.auto_state is None:
                    events = [*events, _StepBudget(STEP_BUDGET)]
                jac = FiniteDifferenceJacobian(fun) if method in ("Radau", "BDF") else None
                with np.errstate(invalid="ignore", divide="ignore", over="ignore"):  # the plan catches these
                    sol = solve_ivp(rhs, (t, t_end), x, method=solver_class(method),
                                    rtol=self.solver.rtol, atol=self.solver.atol, max_step=self.solver.max_step,
                                    events=events or None, dense_output=True, first_step=h0,
                                    **({"jac": jac} if jac else {}))
                self.stats["rhs_evals"] += sol.nfev + (jac.calls if jac else 0)
                if sol.status >= 0 and np.all(np.isfinite(sol.y[:, -1])):
                    break  # else a failed launch method: retry with the scene's
            by = self.stats.setdefault("segments_by_method", {})
            by[method] = by.get(method, 0) + 1
            self.stats["steps"] += len(sol.t) - 1
            if sol.status < 0 or not np.all(np.isfinite(sol.y[:, -1])):
                raise SimulationError(f"{self.scene.name}: integration failed at t = {sol.t[-1]:.9g} s "
                                      f"({method}): {sol.message}{self._diagnose(sol, plan, fun, method)}")
            self.segments.append(_Segment(t, float(sol.t[-1]), list(modes), phase, sol.sol, plan))
            self.stats["segments"] += 1
            t, x = float(sol.t[-1]), sol.y[:, -1].copy()
            self.next_step = None
            if sol.status == 1:
                fired = [e for e, te in zip(events, sol.t_events, strict=True) if len(te)]
                if fired[0].kind == "budget":  # auto: stiff, or just long? (same modes, same phase)
                    self._auto_check(fun, t, x, float(sol.t[-1] - sol.t[-2]), t_end - t)
                    continue
                self.auto_state = None
                if fired[0].kind in RESUME_STEP and len(sol.t) > 2:  # the step size the solver had reached
                    self.next_step = float(sol.t[-2] - sol.t[-3])
                handle = self._limit if fired[0].kind in LIMIT_EVENTS else self._handle
                x, modes, phase = self._release_pulling(t, *handle(t, x, modes, phase, fired[0]))
            elif t < T:
                self.auto_state = None
                phase = self._next_phase(phase, t, x)
        return self._result(time.perf_counter() - wall0)

    def _auto_check(self, fun, t: float, x: np.ndarray, h: float, span: float) -> None:
        """``auto`` after DOP853's step budget: Radau for the rest of the mode if the step h [s] was
        stability-bound by a decaying mode, else DOP853 without a budget (see integrators)."""
        stiff, lam = stability_bound(fun, t, x, h, span)
        self.stats["rhs_evals"] += len(x) + 1
        self.stats["stiffness"] = max(self.stats.get("stiffness", 0.0), lam)
        self.auto_state = "Radau" if stiff else "DOP853"
        if stiff:
            self.stats["auto_switches"] = self.stats.get("auto_switches", 0) + 1
        else:
            self.next_step = h

    def _diagnose(self, sol, plan: ModePlan, fun, method: str) -> str:
        """Why a segment failed, as far as the state at the failure says."""
        t, x = float(sol.t[-1]), sol.y[:, -1]
        if not np.all(np.isfinite(x)):
            return "; the state is not finite"
        if plan.ok:
            cond = plan.kkt_condition(t, x)
            if cond > 1e12:
                return ("; the constraint rows of the touching contacts are linearly dependent (condition number "
                        f"of the contact system {cond:.2g}): a rigid or sticking contact at a singular pose of the "
                        "arm; give the contact a compliant normal model or avoid the pose")
        lam = jacobian_eigenvalues(fun, t, x)
        if len(lam) and method in EXPLICIT:
            fast = float(np.abs(lam).max())
            return (f"; fastest mode |λ| = {fast:.3g} 1/s (an explicit method needs steps below "
                    f"~{STABILITY_RADIUS / fast:.2g} s); for a stiff scene use solver.method = \"Radau\" or \"auto\"")
        return ""

    def _method(self, modes: list[ContactMode], method: str) -> str:
        """The segment's method, but a stiff-capable one while a 2-D slip launches from rest.

        Near v_t = 0 the direction of 2-D Coulomb friction relaxes at a rate ∝ μ F/(m |v_t|)
        (m: the arm's smallest tangential inertia): stiff for an explicit method until the
        slip has grown, worst when the push is just at the cone (thousands of tiny steps).
        LSODA switches to BDF while that lasts; the segment ends at the next event.
        """
        if method not in IMPLICIT and any(m.from_rest and len(m.slip) == 2 and not m.stuck for m in modes):
            return LAUNCH_METHOD
        return method

    def _next_phase(self, phase: Phase, t: float, x: np.ndarray) -> Phase:
        nxt = phase.index + 1
        if nxt >= len(self.scene.phases):
            return replace(phase, spec=replace(phase.spec, until=math.inf))  # the last phase runs on
        self._log(t, "phase", self.scene.phases[nxt].name, check_storm=False)
        return self.system.start_phase(nxt, t, x, phase)

    # ---- events --------------------------------------------------------------------
    def _log(self, t: float, kind: str, name: str, check_storm: bool = True, **info) -> None:
        self.events.append({"t": t, "kind": kind, "name": name, **info})
        if not check_storm:
            return
        self.stats["events"] += 1
        self.recent.append(t)
        if self.stats["events"] > self.solver.max_events:
            raise SimulationError(f"{self.scene.name}: more than {self.solver.max_events} events by t = {t:.9g} s "
                                  f"(last: {kind} on {name}); " + (_start_storm_cause(self.events, name) or
                                                                   "raise solver.max_events if this is expected"))
        if len(self.recent) == self.recent.maxlen and self.recent[-1] - self.recent[0] <= self.solver.storm_window:
            kinds = ", ".join(f"{e['kind']}:{e['name']}" for e in self.events[-5:])
            raise SimulationError(
                f"{self.scene.name}: event storm: {self.recent.maxlen} events within "
                f"{self.recent[-1] - self.recent[0]:.3g} s at t = {t:.9g} s (last: {kinds}); " +
                (_start_storm_cause(self.events, name) or "the contact chatters (grazing or inconsistent "
                                                          "stick/slip); see solver.storm_count / storm_window"))

    def _handle(self, t, x, modes, phase, event):
        system = self.system
        i = next(k for k, c in enumerate(system.contacts) if c.name == event.contact)
        c = system.contacts[i]
        modes = list(modes)
        self._log(t, event.kind, c.name)
        rest: set[int] = set()  #: contacts to decide at rest (a stop)
        released: set[int] = set()  #: contacts that broke away at this event
        if event.kind == "touch":
            modes[i], x = self._touch(t, x, modes, i)
            if c.normal.chain.bonded_when_touching:
                x, imp = system.impact(t, x, modes, c, phase.limits)
                self.impacts.append({"t": t, "contact": c.name, "normal_impulse": imp.normal_impulse,
                                     "friction_impulse": imp.friction_impulse.tolist(), "jammed": imp.jammed,
                                     "energy_loss": imp.energy_loss, "v_before": imp.v_before.tolist(),
                                     "v_after": imp.v_after.tolist(), "slip_before": imp.slip_before.tolist(),
                                     "slip_after": imp.slip_after.tolist()})
                if imp.jammed:
                    modes[i] = modes[i].with_(stuck=True)
                elif c.friction is not None and len(c.tangents):
                    after = imp.slip_after if np.linalg.norm(imp.slip_after) > system.slip_band else imp.direction
                    if np.any(after):
                        modes[i] = modes[i].with_(slip=self._direction(after))
            if phase.spec.until == f"touch:{c.name}":
                phase = self.system.start_phase(phase.index + 1, t, x, phase) \
                    if phase.index + 1 < len(self.scene.phases) else phase
                if phase.index < len(self.scene.phases):
                    self._log(t, "phase", phase.spec.name, check_storm=False)
        elif event.kind == "separate":
            x = system.separate(t, x, modes, phase, c)
            modes[i] = modes[i].with_(touching=False, stuck=False)
        elif event.kind in ("stop", "reverse"):
            rest.add(i)
        elif event.kind == "turn":  # 2-D: the slip turned 60° from the reference; refresh it (no mode change)
            ev = system.evaluate(t, x, modes, phase)
            modes[i] = modes[i].with_(slip=self._direction(ev.slip[c.name]), from_rest=False)
            return x, modes, phase
        elif event.kind == "slip":  # the cone is reached: slide from rest where the holding force pushes
            ev = system.evaluate(t, x, modes, phase)
            self.stats["slips_seen_inside_a_step"] += int(event.latch < math.inf)
            if event.g(ev) <= SLIP_ALARM * c.friction.mu_s * max(ev.normal_force[c.name], 0.0):
                modes[i] = modes[i].with_(stuck=False, slip=self._direction(-ev.friction[c.name]), from_rest=True)
                released.add(i)
            else:  # a stage saw the cone left, the located point does not: a false alarm, still stuck
                self.events[-1]["kind"] = "slip_check"
                self.stats["slip_false_alarms"] += 1
        x, modes = self._consistent(t, x, modes, phase, rest, released)
        return x, modes, phase

    def _limit(self, t, x, modes, phase, event):
        """A joint reaches a position limit (plastic impact, then it presses) or stops pressing (contactdyn.limits)."""
        x, phase, info = self.system.limits.switch(self.system, t, x, modes, phase, event)
        self._log(t, event.kind, event.contact, **info)
        x, modes = self._consistent(t, x, list(modes), phase)
        return x, modes, phase

    def _release_pulling(self, t, x, modes, phase):
        """Release, one at a time, the joints whose limit torque pulls after an event."""
        limits = self.system.limits
        while phase.limits and (pulling := limits.pulling(phase, self.system.evaluate(t, x, modes, phase))):
            phase = replace(phase, limits=tuple(p for p in phase.limits if p != pulling[0]))
            self._log(t, "release", limits.by_index[pulling[0][0]].name)
            x, modes = self._consistent(t, x, modes, phase)
        return x, modes, phase

    @staticmethod
    def _direction(vec: np.ndarray) -> tuple[float, ...]:
        if len(vec) == 1:
            return (1.0 if vec[0] >= 0.0 else -1.0,)
        norm = float(np.linalg.norm(vec))
        return tuple(vec / norm) if norm > 0 else (1.0, 0.0)

    def _touch(self, t, x, modes, i):
        """Mode after touch: touching, tangential chains anchored where the tip now is."""
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
            s_tip = float(dc.u @ kin.p_tip)
            s_env = float(dc.u @ kin.p_env) + old
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
            x[2 * nQ + c.normal.junction_state] = self._junction_at_rest(c.normal, kin, x)
        vt = system.slip_velocity(c, kin) if len(c.tangents) else np.zeros(0)
        slip = modes[i].slip
        if len(vt) and float(np.linalg.norm(vt)) > system.slip_band:
            slip = self._direction(vt)
        return modes[i].with_(touching=True, stuck=False, slip=slip, offsets=tuple(offsets)), x

    def _junction_at_rest(self, dc, kin, x) -> float:
        """[m] where the two surfaces meet: the interface junction's starting position.

        Damped surface ends have states (they relax after a separation): they meet where they
        are, the touch point. Undamped ends follow their stages at once; there the junction
        starts where the two interface stages' springs balance (zero compressions on a first
        touch; on a re-touch both stages share the overlap instead of one taking all of it).
        """
        chain, nQ = dc.chain, self.system.nQ
        ends = [chain.nodes[chain.env_surface].state, chain.nodes[chain.robot_surface].state]
        if min(ends) >= 0:
            return 0.5 * float(x[2 * nQ + ends[0]] + x[2 * nQ + ends[1]])

        def position(node: int) -> float:
            n = chain.nodes[node]
            if n.coord >= 0:
                return float(x[n.coord])
            if n.state >= 0:
                return float(x[2 * nQ + n.state])
            return float(dc.u @ (kin.p_tip if n.kind == NodeKind.TIP else kin.p_env))

        (e,) = [s for s in chain.stages if s.upper == chain.env_surface]
        (r,) = [s for s in chain.stages if s.lower == chain.robot_surface]
        return (e.k * position(e.lower) + r.k * position(r.upper)) / (e.k + r.k)

    def _consistent(self, t, x, modes, phase, rest=frozenset(), released=frozenset()):
        """Fix the modes the state contradicts; return (x, modes).

        Pulling contacts separate; a stick whose friction is outside the cone
        |F_f| ≤ μ_s F slides (from rest, where −F_f points); a slide at rest (|v_t| within
        the stick band, or a contact in ``rest``: it just stopped) sticks if the friction
        needed to hold it is within the cone, else slides where that force pushes; in
        both cases its residual slip is projected away. Contacts in ``released`` (they
        broke away at a located ``slip`` event) are not stuck again at the same instant.
        """
        system = self.system
        released = set(released)
        rest = set(rest)
        for _ in range(4 * len(modes) + 2):
            changed = False
            ev = system.evaluate(t, x, modes, phase)
            if not ev.regular:
                self.stats["singular_solves"] += 1
            for i, (c, mode) in enumerate(zip(system.contacts, modes, strict=True)):
                if not mode.touching:
                    continue
                F_n = ev.normal_force[c.name]
                if not c.spec.bonded and F_n < -FORCE_TOL * (1.0 + abs(F_n)):
                    x[:] = system.separate(t, x, modes, phase, c)
                    modes[i] = mode.with_(touching=False, stuck=False)
                    self._log(t, "separate", c.name)
                    changed = True
                    break
                if c.friction is None or not len(c.tangents):
                    continue
                mu_s = c.friction.mu_s
                if mode.stuck:
                    F_f = ev.friction[c.name]
                    if not _in_cone(F_f, F_n, mu_s):
                        modes[i] = mode.with_(stuck=False, slip=self._direction(-F_f), from_rest=True)
                        self._log(t, "slip", c.name)
                        released.add(i)
                        changed = True
                        break
                    continue
                if i in released:
                    continue
                vt = ev.slip[c.name]
                speed = float(np.linalg.norm(vt))
                if i not in rest and speed > system.slip_band:
                    if float(vt @ np.asarray(mode.slip)) < 0.5 * speed:  # moving, but not along r: refresh r
                        modes[i] = mode.with_(slip=self._direction(vt), from_rest=False)
                    continue
                # at rest: stick if the cone can hold it, else slide where the holding force pushes
                rest.discard(i)
                trial = list(modes)
                trial[i] = mode.with_(stuck=True)
                x = system.project_velocity(x, trial, phase.limits)
                ev2 = system.evaluate(t, x, trial, phase)
                F_f = ev2.friction[c.name]
                if _in_cone(F_f, ev2.normal_force[c.name], mu_s):
                    modes[i] = trial[i]
                    self._log(t, "stick", c.name)
                else:
                    modes[i] = mode.with_(slip=self._direction(-F_f), from_rest=True)
                    released.add(i)
                    self._log(t, "slip", c.name)
                changed = True
                break
            if not changed:
                return x, modes
        raise SimulationError(f"{self.scene.name}: no consistent contact mode at t = {t:.9g} s "
                              f"(modes tried: {modes})")

    # ---- output ---------------------------------------------------------------------
    def _result(self, wall: float) -> Result:
        system, scene = self.system, self.scene
        T = scene.duration
        n_out = int(round(T * self.solver.output_rate))
        grid = np.linspace(0.0, T, n_out + 1) if n_out > 0 else np.array([0.0, T])
        # the segment of each sample: the first ending at or after it; at an event time, the one after
        t1 = np.array([seg.t1 for seg in self.segments])
        idx = np.minimum(np.searchsorted(t1, grid, side="left"), len(t1) - 1)
        nxt = np.minimum(idx + 1, len(t1) - 1)
        idx = np.where((t1[idx] == grid) & (nxt > idx) & (t1[nxt] > grid), nxt, idx)
        xs = np.empty((len(grid), system.n))
        parts: list[Samples] = []
        modes_of: list[list[ContactMode]] = []
        phases_of: list[Phase] = []
        evs: list[Evaluation | None] = []
        for i in np.unique(idx):
            seg = self.segments[i]
            sel = np.flatnonzero(idx == i)
            ts = grid[sel]
            X = np.atleast_2d(seg.sol(ts).T) if len(ts) > 1 else seg.sol(ts[0])[None, :]
            xs[sel] = X
            if seg.plan.ok:
                parts.append(seg.plan.samples(ts, X))
                self.stats["singular_solves"] += seg.plan.singular
                evs += [None] * len(ts)
            else:
                part = Samples(len(ts), system)
                for k, (t, x) in enumerate(zip(ts, X, strict=True)):
                    ev = system.evaluate(t, x, seg.modes, seg.phase, full=True)
                    part.fill(k, ev)
                    evs.append(ev)
                parts.append(part)
            modes_of += [seg.modes] * len(sel)
            phases_of += [seg.phase] * len(sel)
        samples = Samples.concatenate(parts, system)
        channels = _channels(system, grid, xs, samples, modes_of)
        if system.limits.limits:
            channels.update(limit_channels(system, phases_of, evs))
        rate_stats, rate_warnings = rate_limit_report(system.robot, grid, channels["v"], channels["tau"])
        if system.drives.any_motor:  # (plans decline motors: every sample has its Evaluation)
            channels.update(drive_channels(system, xs, evs))
        stats = dict(self.stats, wall_s=wall, real_time_factor=T / wall if wall > 0 else math.inf,
                     method=self.solver.method, rtol=self.solver.rtol, atol=self.solver.atol,
                     compiled_modes=sum(p.ok for p in self.plans.values()),
                     fallback_modes=dict(self.fallbacks), limits=rate_stats)
        meta = {**system.robot.describe(), "posture": system.posture, "limit_warnings": rate_warnings,
                "contacts": [c.name for c in system.contacts],
                "bodies": system.body_names, "robot": str(system.robot.source), "tip": scene.robot.tip,
                "name": scene.name, "duration": T}
        return Result(channels, self.events, self.impacts, stats, scene.document, meta)


START_STORM = 1e-3  #: [s] a storm whose contact events began this early started with the run


def _start_storm_cause(events: list[dict], contact: str) -> str | None:
    """The likely cause when the events flooding the run are on one contact since t ≈ 0, else None."""
    on_contact = [e for e in events if e["kind"] != "phase"]
    if not on_contact or on_contact[0]["t"] > START_STORM or \
            sum(e["name"] == contact for e in on_contact) < 0.9 * len(on_contact):
        return None
    return (f"the events on contact {contact!r} began at t = {on_contact[0]['t']:.3g} s, with the run: the start "
            "posture does not suit the contact (initial penetration, the tip on the surface while moving or "
            "pulling away, a posture near a singularity); check robot.tip0, robot.q0 / q_seed and the contact's "
            "point, and `contactdyn run --verbose` for the posture found")


def _in_cone(F_f: np.ndarray, F_n: float, mu_s: float) -> bool:
    """|F_f| ≤ μ_s F within round-off (a pulling contact holds nothing)."""
    return float(np.linalg.norm(F_f)) <= mu_s * max(F_n, 0.0) * (1.0 + CONE_TOL) + FORCE_ABS_TOL


def _channels(system: System, t: np.ndarray, xs: np.ndarray, smp: Samples,
              modes_of: list[list[ContactMode]]) -> dict[str, np.ndarray]:
    nQ, nv = system.nQ, system.nv
    ch: dict[str, np.ndarray] = {"t": t, "q": xs[:, :nv], "v": xs[:, nQ:nQ + nv], "tau": smp.tau, "tip": smp.tip}
    if smp.has_x_d:
        ch["tip_ref"] = smp.x_d
    for k, name in enumerate(system.body_names):
        idx = system.body_index[name]
        ch[f"body.{name}.x"] = xs[:, idx]
        ch[f"body.{name}.v"] = xs[:, nQ + idx]
        ch[f"body.{name}.force"] = smp.body_force[:, k]
    for i, c in enumerate(system.contacts):
        p = f"contact.{c.name}"
        ch[f"{p}.F_n"] = smp.F_n[c.name]
        ch[f"{p}.gap"] = smp.gap[c.name]
        ch[f"{p}.touching"] = np.array([float(m[i].touching) for m in modes_of])
        ch[f"{p}.F_d"] = smp.F_d[c.name]
        if c.friction is not None and len(c.tangents):
            ch[f"{p}.F_f"] = smp.F_f[c.name]
            ch[f"{p}.v_slip"] = smp.v_slip[c.name]
            ch[f"{p}.stuck"] = np.array([float(m[i].stuck) for m in modes_of])
        for dc in c.tangent_chains:
            ch[f"{p}.{dc.label}.F"] = smp.iface[f"{c.name}.{dc.label}"]
        for k in range(len(c.tangents)):
            key = f"{c.name}.t{k + 1}"
            if smp.has_F_d.get(key):
                ch[f"{p}.t{k + 1}.F_d"] = smp.F_d[key]
    for label in system.stage_labels:
        ch[f"stage.{label}.x"], ch[f"stage.{label}.xdot"], ch[f"stage.{label}.F"] = smp.stages[label].T
    k = 0
    for c in system.contacts:
        for dc in c.chains:
            for node in dc.chain.nodes:
                if node.coord >= 0:
                    label = system.mass_labels[k]
                    ch[f"mass.{label}.x"] = xs[:, node.coord]
                    ch[f"mass.{label}.v"] = xs[:, nQ + node.coord]
                    k += 1
    if system.energy_slot >= 0:
        ch["energy.work"] = xs[:, 2 * nQ + system.energy_slot]
        ch["energy.dissipated"] = xs[:, 2 * nQ + system.energy_slot + 1]
    return ch
