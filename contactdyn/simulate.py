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
from .errors import SimulationError
from .result import Result
from .scene import Scene, load_scene
from .system import Evaluation, Phase, System

__all__ = ["simulate"]

STOP_TOL = 1e-12  #: [m/s] slip speed below which an impact leaves the contact to the stick test
FORCE_TOL = 1e-9  #: [N] relative tolerance of the consistency checks


@dataclass
class _Segment:
    t0: float
    t1: float
    modes: list[ContactMode]
    phase: Phase
    sol: Any


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


def _events(system: System, modes: list[ContactMode], phase: Phase) -> list:
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


class _Run:
    def __init__(self, system: System):
        self.system = system
        self.scene = system.scene
        self.solver = system.scene.solver
        self.segments: list[_Segment] = []
        self.events: list[dict[str, Any]] = []
        self.impacts: list[dict[str, Any]] = []
        self.recent: deque[float] = deque(maxlen=self.solver.storm_count)
        self.stats = {"steps": 0, "rhs_evals": 0, "events": 0, "segments": 0, "singular_solves": 0}

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
            events = _events(system, modes, phase)
            sol = solve_ivp(system.rhs(modes, phase), (t, t_end), x, method=self.solver.method,
                            rtol=self.solver.rtol, atol=self.solver.atol, max_step=self.solver.max_step,
                            events=events or None, dense_output=True)
            self.stats["rhs_evals"] += sol.nfev
            self.stats["steps"] += len(sol.t) - 1
            if sol.status < 0 or not np.all(np.isfinite(sol.y[:, -1])):
                raise SimulationError(f"{self.scene.name}: integration failed at t = {sol.t[-1]:.9g} s: {sol.message}")
            self.segments.append(_Segment(t, float(sol.t[-1]), list(modes), phase, sol.sol))
            self.stats["segments"] += 1
            t, x = float(sol.t[-1]), sol.y[:, -1].copy()
            if sol.status == 1:
                fired = [e for e, te in zip(events, sol.t_events, strict=True) if len(te)]
                x, modes, phase = self._handle(t, x, modes, phase, fired[0])
            elif t < T:
                phase = self._next_phase(phase, t, x)
        return self._result(time.perf_counter() - wall0)

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
        rows: list[tuple[float, np.ndarray, Evaluation, list[ContactMode]]] = []
        seg_i = 0
        for t in grid:
            while seg_i + 1 < len(self.segments) and (self.segments[seg_i].t1 < t or
                                                     (self.segments[seg_i].t1 == t and
                                                      self.segments[seg_i + 1].t1 > t)):
                seg_i += 1
            seg = self.segments[seg_i]
            x = seg.sol(t)
            ev = system.evaluate(t, x, seg.modes, seg.phase, full=True)
            rows.append((t, x, ev, seg.modes))
        channels = _channels(system, rows)
        stats = dict(self.stats, wall_s=wall, real_time_factor=T / wall if wall > 0 else math.inf,
                     method=self.solver.method, rtol=self.solver.rtol, atol=self.solver.atol)
        meta = {"joints": system.robot.joint_names, "contacts": [c.name for c in system.contacts],
                "bodies": system.body_names, "robot": str(system.robot.source), "tip": scene.robot.tip,
                "name": scene.name, "duration": T}
        return Result(channels, self.events, self.impacts, stats, scene.document, meta)


def _channels(system: System, rows) -> dict[str, np.ndarray]:
    nQ, nv = system.nQ, system.nv
    xs = np.array([r[1] for r in rows])
    evs = [r[2] for r in rows]
    ch: dict[str, np.ndarray] = {
        "t": np.array([r[0] for r in rows]),
        "q": xs[:, :nv],
        "v": xs[:, nQ:nQ + nv],
        "tau": np.array([e.tau for e in evs]),
        "tip": np.array([e.p_tip for e in evs]),
    }
    if any(e.x_d is not None and len(e.x_d) == 3 for e in evs):
        ch["tip_ref"] = np.array([e.x_d if e.x_d is not None and len(e.x_d) == 3 else np.full(3, np.nan)
                                  for e in evs])
    for k, name in enumerate(system.body_names):
        idx = system.body_index[name]
        ch[f"body.{name}.x"] = xs[:, idx]
        ch[f"body.{name}.v"] = xs[:, nQ + idx]
        ch[f"body.{name}.force"] = np.array([e.body_force[k] for e in evs])
    for i, c in enumerate(system.contacts):
        p = f"contact.{c.name}"
        ch[f"{p}.F_n"] = np.array([e.normal_force[c.name] for e in evs])
        ch[f"{p}.gap"] = np.array([e.gap[c.name] for e in evs])
        ch[f"{p}.touching"] = np.array([float(r[3][i].touching) for r in rows])
        ch[f"{p}.F_d"] = np.array([e.force_d.get(c.name, np.nan) for e in evs])
        if c.friction is not None and len(c.tangents):
            k = len(c.tangents)
            ch[f"{p}.F_f"] = np.array([e.friction.get(c.name, np.zeros(k)) for e in evs])
            ch[f"{p}.v_slip"] = np.array([e.slip.get(c.name, np.zeros(k)) for e in evs])
            ch[f"{p}.stuck"] = np.array([float(r[3][i].stuck) for r in rows])
        for dc in c.tangent_chains:
            ch[f"{p}.{dc.label}.F"] = np.array([e.interface.get(f"{c.name}.{dc.label}", 0.0) for e in evs])
    for label in system.stage_labels:
        vals = np.array([e.stages.get(label, (0.0, 0.0, 0.0)) for e in evs])
        ch[f"stage.{label}.x"], ch[f"stage.{label}.xdot"], ch[f"stage.{label}.F"] = vals.T
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
