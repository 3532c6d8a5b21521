"""Event-driven hybrid integration: smooth phases, located events, impact maps.

Within a smooth phase the modes (touching, sticking, sliding direction) and the task
phase are fixed and ``solve_ivp`` integrates with error control. Events are zeros of
functions of the state, located by ``solve_ivp`` on its dense output:

- ``touch``: a contact's normal gap reaches zero (then the impact map, where touching
  makes velocities jump);
- ``separate``: a touching contact's normal force reaches zero;
- ``stop``: a sliding contact's slip velocity reaches zero along its sliding direction
  (then stick if the friction needed stays within μ_s F, else slide the other way);
- ``slip``: a sticking contact's friction reaches μ_s F (slide where the force points);
- ``turn``: 2-D sliding turned 60° from its reference direction (reference refreshed;
  not a mode change);
- phase ends (a time, or ``touch:<contact>``).

Guards: more than ``storm_count`` events within ``storm_window`` seconds, or more than
``max_events`` in the run, stop with a :class:`SimulationError` naming the events.
"""

from __future__ import annotations

import math
import time
from collections import deque
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from scipy.integrate import solve_ivp

from .contact import ContactMode
from .errors import SceneError, SimulationError
from .integrators import (
    EXPLICIT,
    FIXED,
    STABILITY_RADIUS,
    FiniteDifferenceJacobian,
    choose_method,
    jacobian_eigenvalues,
    solver_class,
)
from .result import Result
from .rhsplan import ModePlan, Samples
from .scene import Scene, load_scene
from .system import Evaluation, Phase, System

__all__ = ["simulate", "run_system", "prepare"]

STOP_TOL = 1e-12  #: [m/s] slip speed below which an impact leaves the contact to the stick test
FORCE_TOL = 1e-9  #: [N] relative tolerance of the consistency checks


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


def _event(fn, kind: str, contact: str):
    fn.terminal = True
    fn.direction = -1
    fn.kind, fn.contact = kind, contact
    return fn


def _events(system: System, modes: list[ContactMode], phase: Phase, plan: ModePlan | None = None) -> list:
    """Event functions of one mode; they read the compiled plan's values when there is one."""
    if plan is not None:
        return _plan_events(system, modes, plan)
    cache = _Cache(system, modes, phase)
    out = []
    for c, mode in zip(system.contacts, modes, strict=True):
        name = c.name
        if not mode.touching:
            out.append(_event(lambda t, x, n=name: cache(t, x).gap[n], "touch", name))
            continue
        if not c.spec.bonded:
            out.append(_event(lambda t, x, n=name: cache(t, x).normal_force[n], "separate", name))
        if c.friction is None or not len(c.tangents):
            continue
        fr = c.friction
        if mode.stuck:
            out.append(_event(lambda t, x, n=name, mu=fr.mu_s: mu * cache(t, x).normal_force[n]
                              - float(np.linalg.norm(cache(t, x).friction[n])), "slip", name))
        else:
            ref = np.asarray(mode.slip, float)
            out.append(_event(lambda t, x, n=name, r=ref: float(cache(t, x).slip[n] @ r), "stop", name))
            if len(ref) == 2:
                out.append(_event(lambda t, x, n=name, r=ref: float(cache(t, x).slip[n] @ r)
                                  - 0.5 * float(np.linalg.norm(cache(t, x).slip[n])), "turn", name))
    return out


def _plan_events(system: System, modes: list[ContactMode], plan: ModePlan) -> list:
    """The same event functions as :func:`_events`, on the plan's values."""
    out = []
    for ci, (c, mode) in enumerate(zip(system.contacts, modes, strict=True)):
        name = c.name
        if not mode.touching:
            out.append(_event(lambda t, x, i=ci: plan.gap(i, t, x), "touch", name))
            continue
        if not c.spec.bonded:
            out.append(_event(lambda t, x, i=ci: plan.normal_force(i, t, x), "separate", name))
        if c.friction is None or not len(c.tangents):
            continue
        fr = c.friction
        if mode.stuck:
            out.append(_event(lambda t, x, i=ci, mu=fr.mu_s: mu * plan.normal_force(i, t, x)
                              - math.sqrt(float(np.dot(plan.stick_force(i, t, x), plan.stick_force(i, t, x)))),
                              "slip", name))
        else:
            ref = np.asarray(mode.slip, float)
            out.append(_event(lambda t, x, i=ci, r=ref: float(plan.slip(i, t, x) @ r), "stop", name))
            if len(ref) == 2:
                out.append(_event(lambda t, x, i=ci, r=ref: float(plan.slip(i, t, x) @ r)
                                  - 0.5 * float(np.linalg.norm(plan.slip(i, t, x))), "turn", name))
    return out


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
    x = run._init_controller(phase, 0.0, x, modes)
    return system, run._consistent(0.0, x, modes, phase), phase, x


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
        if self.solver.method in FIXED and not math.isfinite(self.solver.max_step):
            raise SceneError("solver.max_step", f"the step [s] of the fixed-step method {self.solver.method}",
                             "no max_step", self.scene.file)
        self.stats = {"steps": 0, "rhs_evals": 0, "events": 0, "segments": 0, "singular_solves": 0}
        self.plans: dict[tuple, ModePlan] = {}
        self.fallbacks: dict[str, int] = {}  #: reasons a mode ran on System.evaluate, with counts

    def _plan(self, modes: list[ContactMode], phase: Phase) -> ModePlan:
        """The compiled right-hand side of (modes, phase), built once and kept."""
        key = (tuple(modes), id(phase))
        plan = self.plans.get(key)
        if plan is None:
            plan = self.plans[key] = ModePlan(self.system, modes, phase)
        if not plan.ok:
            self.fallbacks[plan.reason] = self.fallbacks.get(plan.reason, 0) + 1
        return plan

    # ---- main loop -------------------------------------------------------------------
    def run(self, wall0: float) -> Result:
        system, T = self.system, self.scene.duration
        x, modes = system.initial_state()
        phase = system.start_phase(0, 0.0, x, None)
        x = self._init_controller(phase, 0.0, x, modes)
        t = 0.0
        modes = self._consistent(t, x, modes, phase)
        while t < T:
            until = phase.spec.until
            t_end = min(T, until) if isinstance(until, float) else T
            if t_end <= t:
                phase = self._next_phase(phase, t, x)
                continue
            plan = self._plan(modes, phase)
            fun = plan.rhs if plan.ok else system.rhs(modes, phase)
            events = _events(system, modes, phase, plan if plan.ok else None)
            method = self._method(fun, t, x, t_end - t)
            jac = FiniteDifferenceJacobian(fun) if method in ("Radau", "BDF") else None
            with np.errstate(invalid="ignore", divide="ignore"):  # a singular solve is caught by the plan
                sol = solve_ivp(fun, (t, t_end), x, method=solver_class(method),
                                rtol=self.solver.rtol, atol=self.solver.atol, max_step=self.solver.max_step,
                                events=events or None, dense_output=True, **({"jac": jac} if jac else {}))
            self.stats["rhs_evals"] += sol.nfev + (jac.calls if jac else 0)
            self.stats["steps"] += len(sol.t) - 1
            if sol.status < 0 or not np.all(np.isfinite(sol.y[:, -1])):
                raise SimulationError(f"{self.scene.name}: integration failed at t = {sol.t[-1]:.9g} s "
                                      f"({method}): {sol.message}{self._diagnose(sol, plan, fun, method)}")
            self.segments.append(_Segment(t, float(sol.t[-1]), list(modes), phase, sol.sol, plan))
            self.stats["segments"] += 1
            t, x = float(sol.t[-1]), sol.y[:, -1].copy()
            if sol.status == 1:
                fired = [e for e, te in zip(events, sol.t_events, strict=True) if len(te)]
                x, modes, phase = self._handle(t, x, modes, phase, fired[0])
            elif t < T:
                phase = self._next_phase(phase, t, x)
        return self._result(time.perf_counter() - wall0)

    def _method(self, fun, t: float, x: np.ndarray, span: float) -> str:
        """The segment's integrator: the scene's, or with ``auto`` DOP853 unless the segment is stiff."""
        method = self.solver.method
        if method == "auto":
            method, lam = choose_method(fun, t, x, span)
            self.stats["stiffness"] = max(self.stats.get("stiffness", 0.0), lam)
        by = self.stats.setdefault("segments_by_method", {})
        by[method] = by.get(method, 0) + 1
        return method

    def _diagnose(self, sol, plan, fun, method: str) -> str:
        """Why a segment failed, as far as the state at the failure says."""
        t, x = float(sol.t[-1]), sol.y[:, -1]
        if not np.all(np.isfinite(x)):
            return "; the state is not finite"
        notes = []
        if plan.ok:
            cond = plan.kkt_condition(t, x)
            if cond > 1e12:
                return "; " + (f"the constraint rows of the touching contacts are linearly dependent (condition "
                             f"number of the contact system {cond:.2g}): a rigid or sticking contact at a singular "
                             "pose of the arm; give the contact a compliant normal model or avoid the pose")
        lam = jacobian_eigenvalues(fun, t, x)
        if len(lam) and method in EXPLICIT:
            fast = float(np.abs(lam).max())
            notes.append(f"fastest mode |λ| = {fast:.3g} 1/s (an explicit method needs steps below "
                         f"~{STABILITY_RADIUS / fast:.2g} s); for a stiff scene use solver.method = "
                         "\"Radau\" or \"auto\"")
        return "; " + "; ".join(notes) if notes else ""

    def _init_controller(self, phase: Phase, t: float, x: np.ndarray, modes) -> np.ndarray:
        if phase.controller.n_states:
            ev = self.system.evaluate(t, x, modes, phase)
            from .controllers.base import ControlInput  # noqa: F401

            x = x.copy()
            x[2 * self.system.nQ + phase.z_slice.start: 2 * self.system.nQ + phase.z_slice.stop] = \
                phase.controller.initial_states(ev)  # type: ignore[arg-type]
        return x

    def _next_phase(self, phase: Phase, t: float, x: np.ndarray) -> Phase:
        nxt = phase.index + 1
        if nxt >= len(self.scene.phases):
            return Phase(phase.spec.__class__(phase.spec.name, math.inf, phase.spec.controller, phase.spec.reference,
                                              phase.spec.forces), phase.index, phase.t_start, phase.controller,
                         phase.z_slice, phase.reference, phase.forces)
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
                                  f"(last: {kind} on {name}); raise solver.max_events if this is expected")
        if len(self.recent) == self.recent.maxlen and self.recent[-1] - self.recent[0] <= self.solver.storm_window:
            kinds = ", ".join(f"{e['kind']}:{e['name']}" for e in self.events[-5:])
            raise SimulationError(
                f"{self.scene.name}: event storm: {self.recent.maxlen} events within "
                f"{self.recent[-1] - self.recent[0]:.3g} s at t = {t:.9g} s (last: {kinds}); the contact chatters "
                "(grazing or inconsistent stick/slip); see solver.storm_count / storm_window")

    def _handle(self, t, x, modes, phase, event):
        system = self.system
        i = next(k for k, c in enumerate(system.contacts) if c.name == event.contact)
        c = system.contacts[i]
        modes = list(modes)
        self._log(t, event.kind, c.name)
        if event.kind == "touch":
            modes[i], x = self._touch(t, x, modes, i)
            if c.normal.chain.bonded_when_touching:
                x, imp = system.impact(t, x, modes, c)
                self.impacts.append({"t": t, "contact": c.name, "normal_impulse": imp.normal_impulse,
                                     "friction_impulse": imp.friction_impulse.tolist(), "jammed": imp.jammed,
                                     "energy_loss": imp.energy_loss, "v_before": imp.v_before.tolist(),
                                     "v_after": imp.v_after.tolist()})
                if imp.jammed:
                    modes[i] = modes[i].with_(stuck=True)
            if phase.spec.until == f"touch:{c.name}":
                phase = self.system.start_phase(phase.index + 1, t, x, phase) \
                    if phase.index + 1 < len(self.scene.phases) else phase
                if phase.index < len(self.scene.phases):
                    self._log(t, "phase", phase.spec.name, check_storm=False)
        elif event.kind == "separate":
            x = system.separate(t, x, modes, phase, c)
            modes[i] = modes[i].with_(touching=False, stuck=False)
        elif event.kind == "stop":
            modes[i] = modes[i].with_(stuck=True)
        elif event.kind == "slip":
            ev = system.evaluate(t, x, modes, phase)
            F_f = ev.friction[c.name]
            modes[i] = modes[i].with_(stuck=False, slip=self._direction(-F_f))
        elif event.kind == "turn":
            ev = system.evaluate(t, x, modes, phase)
            modes[i] = modes[i].with_(slip=self._direction(ev.slip[c.name]))
        modes = self._consistent(t, x, modes, phase)
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
        for dc in c.tangent_chains:
            # shift the environment side rigidly so the two surface nodes meet undeformed
            s_tip = float(dc.u @ kin.p_tip)
            s_env = float(dc.u @ kin.p_env)
            robot_side = [n for n in dc.chain.nodes if n.side == "robot" and n.coord >= 0]
            s_r = x[robot_side[-1].coord] if robot_side else s_tip
            delta = s_r - s_env
            offsets.append(delta)
            for node in dc.chain.nodes:
                if node.side == "environment" and node.coord >= 0:
                    x[node.coord] += delta
                if node.side == "environment" and node.state >= 0:
                    x[2 * nQ + node.state] += delta
            if dc.junction_state >= 0:
                x[2 * nQ + dc.junction_state] = s_r
        if c.normal.junction_state >= 0:
            robot_masses = [n for n in c.normal.chain.nodes if n.side == "robot" and n.coord >= 0]
            x[2 * nQ + c.normal.junction_state] = x[robot_masses[-1].coord] if robot_masses else \
                float(c.normal.u @ kin.p_tip)
        vt = c.tangents @ (kin.v_tip - kin.v_env) if len(c.tangents) else np.zeros(0)
        slip = modes[i].slip
        if len(vt) and float(np.linalg.norm(vt)) > 0.0:
            slip = self._direction(vt)
        return modes[i].with_(touching=True, stuck=False, slip=slip, offsets=tuple(offsets)), x

    def _consistent(self, t, x, modes, phase) -> list[ContactMode]:
        """Fix modes the state contradicts (pulling contacts, unholdable sticks, resting slides)."""
        system = self.system
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
                if mode.stuck:
                    F_f = ev.friction[c.name]
                    if float(np.linalg.norm(F_f)) > c.friction.mu_s * max(F_n, 0.0) * (1 + 1e-12) + FORCE_TOL:
                        modes[i] = mode.with_(stuck=False, slip=self._direction(-F_f))
                        self._log(t, "slip", c.name)
                        changed = True
                        break
                elif float(np.linalg.norm(ev.slip[c.name])) <= STOP_TOL:
                    trial = list(modes)
                    trial[i] = mode.with_(stuck=True)
                    ev2 = system.evaluate(t, x, trial, phase)
                    F_f = ev2.friction[c.name]
                    if float(np.linalg.norm(F_f)) <= c.friction.mu_s * max(ev2.normal_force[c.name], 0.0) + FORCE_TOL:
                        modes[i] = trial[i]
                        self._log(t, "stick", c.name)
                    else:
                        direction = self._direction(-F_f)
                        if direction != mode.slip:
                            modes[i] = mode.with_(slip=direction)
                            self._log(t, "reverse", c.name)
                        else:
                            continue
                    changed = True
                    break
            if not changed:
                return modes
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
        for i in np.unique(idx):
            seg = self.segments[i]
            sel = np.flatnonzero(idx == i)
            ts = grid[sel]
            X = np.atleast_2d(seg.sol(ts).T) if len(ts) > 1 else seg.sol(ts[0])[None, :]
            xs[sel] = X
            if seg.plan.ok:
                parts.append(seg.plan.samples(ts, X))
                self.stats["singular_solves"] += seg.plan.singular
            else:
                part = Samples(len(ts), system)
                for k, (t, x) in enumerate(zip(ts, X, strict=True)):
                    part.fill(k, system.evaluate(t, x, seg.modes, seg.phase, full=True))
                parts.append(part)
            modes_of += [seg.modes] * len(sel)
        samples = Samples.concatenate(parts, system)
        channels = _channels(system, grid, xs, samples, modes_of)
        stats = dict(self.stats, wall_s=wall, real_time_factor=T / wall if wall > 0 else math.inf,
                     method=self.solver.method, rtol=self.solver.rtol, atol=self.solver.atol,
                     compiled_modes=sum(p.ok for p in self.plans.values()),
                     fallback_modes={k: v for k, v in self.fallbacks.items()})
        meta = {"joints": system.robot.joint_names, "contacts": [c.name for c in system.contacts],
                "bodies": system.body_names, "robot": str(system.robot.source), "tip": scene.robot.tip,
                "name": scene.name, "duration": T}
        return Result(channels, self.events, self.impacts, stats, scene.document, meta)


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
