"""The hybrid loop: smooth phase, event, mode transition (impact map), next smooth phase.

A contact task (Part II's description) alternates smooth motions, in which the contact
modes and the task phase are fixed, and instants at which they change. The loop:

1. integrate the smooth phase from (t, x) with error control (``solve_ivp``, or the compiled
   DOP853 of :mod:`contactdyn.numerics.dop853`; the method from :mod:`contactdyn.numerics.integrators`) on the
   mode's right-hand side — the one pipeline's (:mod:`contactdyn.hybrid.pipeline_mode`: one compiled call, its own
   compiled steps; interpreted on a scene kind's first run) — with the mode's events
   (:mod:`contactdyn.hybrid.events`);
2. at the first event, apply the transition (:mod:`contactdyn.hybrid.transitions`): an impact,
   a separation, a stick or a slip; or, at a phase's end, start the next phase; at a
   corner of the phase's set-points (:class:`~contactdyn.laws.trajectory.Corner`: a jump of the
   reference's acceleration or of a force ramp's rate) go on past it with the same state,
   so that no step straddles the jump (:meth:`HybridRun._pass_corner`);
3. repeat until the duration; then sample the segments into channels
   (:mod:`contactdyn.output.channels`).

Integrator choice per segment: the scene's ``solver.method``; ``auto`` runs DOP853 with a
step budget and switches to Radau for a segment whose steps are stability-bound; a 2-D
slip launching from rest runs on LSODA (its direction relaxes at a rate ∝ 1/|v_t|, stiff
for an explicit method) until the next event; while damped chain ends relax after a
separation an explicit method's step is at most their time constant (``RELAX_STEP``). After
a friction event the next segment (or a corner) starts with the step size the solver had
reached. An integration failure reports what the state says: a singular contact system or
stiffness. Steps that shrink a billion-fold against calls with no answer (a law's NaN next to the state they crawl
towards) have the call's laws checked, and a law that returned NaN or ±inf there stops the run at once, named
(:class:`~contactdyn.hybrid.events.LawStall`, :func:`_stall_check`).
"""

from __future__ import annotations

import gc
import math
import time
from contextlib import nullcontext
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import SceneError, SimulationError, numerical_errors
from ..laws.failures import LawError, law_error
from ..laws.trajectory import min_span
from ..model.constraints import kkt_condition
from ..model.contact import ContactMode
from ..model.limits import rate_limit_report
from ..model.paths import LivePipelines, PathLog, mode_label
from ..model.phases import Phase
from ..model.pipeline.pipeline import call_time
from ..model.system import System
from ..numerics.integrators import (
    AUTO_EXPLICIT,
    EXPLICIT,
    FIXED,
    HOLD_SWITCH,
    IMPLICIT,
    STABILITY_RADIUS,
    STEP_BUDGET,
    FiniteDifferenceJacobian,
    carries_hold,
    integrate,
    jacobian_eigenvalues,
    stability_bound,
)
from ..numerics.notice import compiling
from ..numerics.twins import running
from ..output.channels import Held, Segment, output_grid, sample_states
from ..output.physics_checks import StartAudit, run_checks, violations
from ..output.result import Result
from ..scene.budget import STEPS_BASE, STEPS_PER_SAMPLE, sample_rate, step_budget
from .charts import chart_events
from .events import EventLog, LawStall, StepBudget, StepCollapse, WorkWatch, fired_across, segment_events
from .pipeline_mode import PipelineMode
from .progress import CALLS_PER_STEP, OverBudget, Progress, Work
from .sampling import SampledPhases
from .transitions import Transitions

__all__ = ["HybridRun", "RESUME_STEP", "LAUNCH_METHOD"]

HELD_STEPS_SEEN = 10  #: under a hold, the stiffness checks (auto's, a collapse's) take the longest of the last steps

#: events after which the next segment starts with the step size the solver had reached (friction
#: mode switches change the forces, not the time scales; an impact or a separation does, so they restart; a free
#: body's chart switch changes its coordinates only)
RESUME_STEP = ("stop", "reverse", "slip", "turn", "joint_slip", "joint_stick", "chart")
#: methods whose calls fall inside their steps (the stages; Radau's and BDF's Newton iterates): events.DipWatch gates
#: its search on them; LSODA's are not kept per step (its DipWatch gates on the step's ends alone)
STAGED = ("DOP853", "DOP853C", "RK45", "RK23", "RK4", "Radau", "BDF")
LAUNCH_METHOD = "LSODA"  #: for segments where a 2-D slip starts from rest or comes to rest (see HybridRun._method)
LAUNCH_SETTLED = 0.5 * STABILITY_RADIUS  #: [-] period·|λ| below which a sampled launch leaves LAUNCH_METHOD
#: a 2-D slide's explicit steps shorter than COLLAPSE_RATIO × the segment's longest, COLLAPSE_STEPS of them, have
#: it checked for a stiff mode (events.StepCollapse): the steps shrink ~1/|v_t| as the slide comes to rest; a
#: short collapse costs the explicit method less than a switch would
COLLAPSE_RATIO, COLLAPSE_STEPS = 1.0 / 8.0, 50
#: [-] LAUNCH_METHOD finishing a slide that comes to rest runs at this × the scene's tolerances: its error is then
#: about DOP853's at the scene's own (5-DOF writer against its rtol 1e-11 reference: tip 1.1e-9 m at 1×, 3.4e-10 m
#: at 0.1×, as DOP853 alone); where it fails there, the scene's method takes over for the rest of the mode
RESTING_TOL = 0.1
#: [-] an explicit step while chain ends relax after a separation is at most this × their time constant
#: b / k: the relaxation is then resolved, and so are the gap and the re-touch located on it (at 1e-2 s
#: steps, 10 time constants, case 1's re-touch came out 1e-8 s late at rtol 3e-11)
RELAX_STEP = 1.0
#: a step shorter than STALL_RATIO × the segment's longest after a call with no answer, STALL_STEPS of them, has the
#: call's laws checked (events.LawStall): a law's NaN next to the state the steps crawl towards. A trial state that
#: overflows a law at a step too long is rejected, and a step a few times shorter passes: nowhere near 1e-9
STALL_RATIO, STALL_STEPS = 1e-9, 3


class HybridRun:
    """One run of a system: the loop, its counters, its segments and events."""

    #: end segments at the corners of the phase's set-points (trajectory.Corner); False only for
    #: the benchmarks' before/after comparison (benchmarks/corners.py)
    at_corners = True

    def __init__(self, system: System, compiled: bool = True, interpreted: bool = False, twins=None):
        self.system = system
        self.scene = system.scene
        self.solver = system.scene.solver
        self.segments: list[Segment] = []
        self.impacts: list[dict[str, Any]] = []
        self.next_step: float | None = None  #: [s] first step of the next segment (None: solver's choice)
        self.chart_events = chart_events(system)  #: every segment's free-body chart switches (hybrid.charts)
        if self.solver.method in FIXED and not math.isfinite(self.solver.max_step):
            raise SceneError("solver.max_step", f"the step [s] of the fixed-step method {self.solver.method}",
                             "no max_step", self.scene.file)
        self.stats = {"steps": 0, "rhs_evals": 0, "events": 0, "segments": 0, "corners": 0, "singular_solves": 0,
                      "holds_split": 0,  # (of the singular solves: model.pipeline.kkt.coulomb_split)
                      "slips_seen_inside_a_step": 0, "slip_false_alarms": 0,  # (slip, joint_slip, release)
                      "dips_seen_inside_a_step": 0,  # (events.DipWatch, a hold's StageWatch)
                      "decided_together": 0}  # (hybrid.at_rest)
        self.log = EventLog(self.scene.name, self.solver, self.stats)
        self.events = self.log.events

        def runner(modes, phase):  # (what runs a mode: the transitions and samples read the model through it)
            return _runner(self, modes, phase)

        #: the samplers of sampled phases (hybrid.sampling)
        self.sampled = SampledPhases(system, self.stats, runner)
        self.transitions = Transitions(system, self.log, self.stats, self.impacts, self.sampled.start, runner)
        self.auto_state: str | None = None  #: ``auto``: the method fixed for the current mode (None: not yet)
        #: a 2-D slide whose explicit steps collapsed: LAUNCH_METHOD for the rest of the mode when a stiff mode held
        #: them, "" when none did (no more checks in the mode); None: not checked
        self.resting: str | None = None
        #: a 2-D slip launched from rest, sampled, whose direction relaxes slowly enough for explicit steps of one
        #: period (:func:`_launch_settled`): the scene's method for the rest of the mode
        self.launched = False
        self.step_checked = False  #: RK4's step checked against the current mode (at its first segment's start)
        #: the steps stalled against calls with no answer in the current mode, and no law's NaN was to blame
        #: (:func:`_stall_check`): not watched again in the mode
        self.stall_checked = False
        #: the modes' pipelines, compiled; ``interpreted`` (or not ``compiled``): the same call run as its twins
        #: (numerics.twins: a scene kind's first run), ``twins`` if given (a numerics.twins.Twins)
        self.pipelines = LivePipelines(system, PipelineMode, use=compiled and not interpreted, twins=twins)
        self.paths = PathLog()  #: which path each mode ran on, and why not a faster one (contactdyn.model.paths)
        self.starts = StartAudit()  #: the forces where each segment starts (contactdyn.output.physics_checks)
        #: integration steps at most (progress.py): a sampled law's samples add theirs
        self.budget = step_budget(self.solver, self.scene.duration, sample_rate(self.scene))
        self.work = Work(CALLS_PER_STEP * self.budget)  #: right-hand-side calls at most, rejected steps' too
        self.progress: Progress | None = None  #: shows the simulated time of a long run (contactdyn run sets it)

    def start(self) -> tuple[np.ndarray, list[ContactMode], Phase]:
        """Initial state, consistent modes and the first phase at t = 0."""
        x, modes = self.system.initial_state()
        phase = self.system.start_phase(0, 0.0, x, None)
        phase = replace(phase, limits=self.system.limits.resting(x, self.system.nQ))  # (pressing, unless they pull)
        x = self.sampled.start(0.0, x, modes, phase, None)  # a sampled law's first sample
        return self.transitions.start(0.0, x, modes, phase)

    # ---- main loop -------------------------------------------------------------------
    def run(self, wall0: float) -> Result:
        """Integrate the whole scene; numerical breakdowns become a SimulationError saying where."""
        gc.freeze()  # the ~1e5 objects made before (modules, compiled code) out of the collector's scans meanwhile
        try:
            with running(self.pipelines.twins):  # (interpreted: the model's helpers the loop calls too, twins.current)
                return self._run(wall0)
        except Exception as exc:  # a user's law that raised (where no failed call re-raised it), a blow-up, the budget
            error = _failure(self, exc)
            if error is exc:
                raise
            raise error from (exc if isinstance(error, LawError) else None)
        finally:
            gc.unfreeze()

    def _run(self, wall0: float) -> Result:
        T = self.scene.duration
        x, modes, phase = self.start()
        t = 0.0
        while T - t > min_span(t):  # (an event located within a few roundings of the end: the run ends there)
            until = phase.spec.until
            t_end = min(T, until) if isinstance(until, float) else T
            if t_end - t <= min_span(t):  # (at the phase's end already, or past it)
                self._new_mode()
                x, modes, phase = self._next_phase(phase, t, x, modes)
                continue
            corner = phase.next_corner(t, t_end) if self.at_corners else None
            if corner is not None and corner.before - t <= min_span(t):  # at it already (an event landed there)
                t, x, modes, phase = self._pass_corner(t, corner.after, x, modes, phase)
                continue
            t_sample = self.sampled.next_time(phase)  # a sampled law's next sample instant (hybrid.sampling)
            if t_sample <= t + min_span(t):
                t, x, modes, phase = self._pass_corner(t, max(t, t_sample), x, modes, phase, sample=True)
                continue
            stop = corner.before if corner else t_end
            sample = t_sample < stop - min_span(stop)
            sol, events, fun, held = self._segment(t, stop, x, modes, phase, t_sample if sample else None)
            sample = sample and not held  # the segment ended at the sample (else the integrator took it)
            self.sampled.carry(sol, sample)  # auto's step budget runs on over sample instants
            t, x = float(sol.t[-1]), sol.y[:, -1].copy()
            h0, self.next_step = self.next_step, None
            if sol.status == 0 and (corner is not None or sample):  # a corner or a sample: past it, the step reached
                self.next_step = _reached(sol, h0, sample)
                t, x, modes, phase = self._pass_corner(t, t if sample else corner.after, x, modes, phase, sample)
            elif sol.status == 1:
                fired = [e for e, te in zip(events, sol.t_events, strict=True) if len(te)]
                period = self.sampled.period(phase) if held else None
                if fired[0].kind == "budget":  # auto: stiff, or just long? (same modes, same phase)
                    self._auto_check(fun, t, x, _explicit_step(sol, held), t_end - t, period)
                    continue
                if fired[0].kind == "work":
                    raise SimulationError(_over_budget(self, t, x))
                if fired[0].kind == "collapse":  # a 2-D slide coming to rest? (same modes, same phase)
                    self._collapse_check(fun, t, x, _explicit_step(sol, held), t_end - t, period)
                    continue
                if fired[0].kind == "stall":  # a law's NaN holding the steps back? (same modes, same phase)
                    _stall_check(self, fired[0])
                    continue
                self._new_mode()
                if fired[0].kind in RESUME_STEP and len(sol.t) > 2:  # the step size the solver had reached
                    self.next_step = float(sol.t[-2] - sol.t[-3])
                x, modes, phase = self.transitions.handle(t, x, modes, phase, fired[0])
            elif t < T:
                self._new_mode()
                x, modes, phase = self._next_phase(phase, t, x, modes)
        self.work.limit = math.inf  # the output's interpolants are not the integration's work
        if self.segments and self.segments[-1].modes != modes:  # an event at the end: its modes are the last sample's
            self.segments.append(Segment(t, t, list(modes), phase, Held(x), _runner(self, modes, phase)))
        return self._result(time.perf_counter() - wall0)

    def _pass_corner(self, t: float, t_after: float, x: np.ndarray, modes: list[ContactMode], phase: Phase,
                     sample: bool = False):
        """Restart past a corner of the set-points at t_after [s] with the state x reached at t [s], or (``sample``)
        with the state after a sampled law's sample at t_after (its held command jumps: hybrid.sampling)
        (no event: the same modes, unless a contact force or limit torque jumps through zero there,
        which is handled as the event a step straddling the corner would have located)."""
        runner = _runner(self, modes, phase)
        if sample:
            x, before = self.sampled.take(t_after, x, phase, runner), x
            fired = self.sampled.jumped(t_after, before, x, modes, phase, runner)
        else:
            self.stats["corners"] += 1
            fired = fired_across(segment_events(self.system, modes, phase, t, x, runner)[0], t, t_after, x)
        if fired:
            self._new_mode()
            if fired[0].kind not in RESUME_STEP:
                self.next_step = None
            x, modes, phase = self.transitions.handle(t_after, x, modes, phase, fired[0])
        return t_after, x, modes, phase

    def _segment(self, t: float, t_end: float, x: np.ndarray, modes: list[ContactMode], phase: Phase,
                 t_sample: float | None = None):
        """Integrate one smooth phase from t towards t_end [s]: (solution, its events, its right-hand side, held).
        ``t_sample`` [s]: a sampled law's next sample instant before t_end; a method that carries the hold takes it
        and the later ones as step boundaries (held true), any other ends the segment there."""
        system = self.system
        runner = _runner(self, modes, phase, start=True)  # the one pipeline's mode
        fun = runner.rhs
        scene_method = self.solver.method if self.solver.method != "auto" else (self.auto_state or AUTO_EXPLICIT)
        if t_sample is not None and not self.launched and carries_hold(scene_method) and _launching(modes):
            self.launched = _launch_settled(self, fun, t, x, self.sampled.period(phase))
        for method in dict.fromkeys((self._method(modes, scene_method), scene_method)):
            held = t_sample is not None and carries_hold(method)
            end = t_sample if t_sample is not None and not held else t_end
            h0 = min(self.next_step, end - t) if self.next_step else None
            hold = self.sampled.hold(modes, phase, t_end, runner) if held else None
            events, rhs = segment_events(system, modes, phase, t, x, runner, swings=method in STAGED)
            self.starts.record(t, x, events)
            events += self._watches(modes, method, getattr(runner, "pipe", None)) + self.chart_events
            jac = FiniteDifferenceJacobian(fun) if method in ("Radau", "BDF") else None
            # LSODA finishing a slide that comes to rest (HybridRun._collapse_check): at RESTING_TOL × the tolerances
            finishing = method == self.resting and method != scene_method and not _launching(modes)
            scale = RESTING_TOL if finishing else 1.0
            with np.errstate(invalid="ignore", divide="ignore", over="ignore"):  # a singular call: see PipelineMode
                sol = integrate(self.work.wrap(rhs), (t, end), x, method, rtol=scale * self.solver.rtol,
                                atol=scale * self.solver.atol, max_step=self._max_step(modes, method), events=events,
                                first_step=h0, jac=jac, hold=hold, checked=self.step_checked)
            self.stats["rhs_evals"] += sol.nfev + (jac.calls if jac else 0)
            self.step_checked = self.step_checked or method in FIXED
            if sol.status >= 0 and np.all(np.isfinite(sol.y[:, -1])):
                break  # else a failed launch or finishing method: retry with the scene's
            if finishing:
                self.resting = ""  # and keep the scene's for the rest of the mode
        by = self.stats.setdefault("segments_by_method", {})
        by[method] = by.get(method, 0) + 1
        self.stats["steps"] += len(sol.t) - 1
        if sol.status < 0 or not np.all(np.isfinite(sol.y[:, -1])):
            why = sol.message if sol.status < 0 else "the state is not finite"  # never "successfully ..."
            raise SimulationError(f"{self.scene.name}: integration failed at t = {sol.t[-1]:.9g} s "
                                  f"({method}): {why}{_diagnose(self, sol, modes, phase, fun, method)}")
        self.segments.append(Segment(t, float(sol.t[-1]), list(modes), phase, sol.sol, runner))
        self.stats["segments"] += 1
        return sol, events, fun, held

    def _auto_check(self, fun, t: float, x: np.ndarray, h: float, span: float, period: float | None = None) -> None:
        """``auto`` after DOP853's step budget: Radau for the rest of the mode if the step h [s] was
        stability-bound by a decaying mode (:func:`_held_by_stability`), else DOP853 without a budget (see
        integrators); ``period`` [s]: a sampled law's, where its hold's samples were step boundaries."""
        stiff, lam = _held_by_stability(self, fun, t, x, h, span, period)
        self.stats["stiffness"] = max(self.stats.get("stiffness", 0.0), lam)
        self.auto_state = "Radau" if stiff else AUTO_EXPLICIT
        if stiff:
            self.stats["auto_switches"] = self.stats.get("auto_switches", 0) + 1
        else:
            self.next_step = h

    def _watches(self, modes: list[ContactMode], method: str, pipe=None) -> list:
        """The segment's watches: the run's work budget (and progress), ``auto``'s step budget, a 2-D slide's
        collapse watch, the stall watch of the mode's pipeline ``pipe`` (events.LawStall)."""
        left = self.budget - self.stats["steps"]
        if left <= 0:  # spent at a segment's end (an event there): stop before the next
            last = self.segments[-1]
            raise SimulationError(_over_budget(self, last.t1, last.sol(last.t1)))
        out: list = [WorkWatch(left, self.progress)]
        if self.solver.method == "auto" and method == AUTO_EXPLICIT and self.auto_state is None:
            out.append(StepBudget(max(STEP_BUDGET - self.sampled.carried, 1)))
        if self.resting is None and method in EXPLICIT and method not in FIXED and _sliding_2d(modes) \
                and not _launching(modes):
            out.append(StepCollapse(COLLAPSE_RATIO, COLLAPSE_STEPS))
        if pipe is not None and not self.stall_checked:
            out.append(LawStall(pipe, STALL_RATIO, STALL_STEPS))
        return out

    def _collapse_check(self, fun, t: float, x: np.ndarray, h: float, span: float, period: float | None = None
                        ) -> None:
        """A 2-D slide's explicit step collapsed to h [s] (events.StepCollapse): LAUNCH_METHOD for the rest of the
        mode if a decaying mode held it at the method's stability bound (:func:`_held_by_stability`), else the
        explicit method on, unwatched; ``period`` as :meth:`_auto_check`'s."""
        stiff, _ = _held_by_stability(self, fun, t, x, h, span, period)
        self.resting = LAUNCH_METHOD if stiff else ""
        if stiff:
            self.stats["resting_switches"] = self.stats.get("resting_switches", 0) + 1
        self.next_step = h

    def _new_mode(self) -> None:
        """Forget the method choices made for the mode that ends (auto's, a slide's coming to rest) and its stall
        check's verdict."""
        self.auto_state = self.resting = None
        self.launched = self.step_checked = self.stall_checked = False

    def _method(self, modes: list[ContactMode], method: str) -> str:
        """The segment's method, but a stiff-capable one while a 2-D slip launches from rest or comes to rest.

        Near v_t = 0 the direction of 2-D Coulomb friction relaxes at a rate ∝ μ F/(m |v_t|)
        (m: the arm's smallest tangential inertia): stiff for an explicit method until the
        slip has grown, worst when the push is just at the cone (thousands of tiny steps), and
        again as a slide comes to rest (its last 50 ms took the 5-DOF writer's DOP853 7265 calls,
        LSODA 899). LSODA switches to BDF while that lasts; the segment ends at the next event.
        A slide coming to rest is seen by its explicit steps collapsing (``resting``,
        :meth:`_collapse_check`). Under a sampled law's hold LSODA would end a segment at every sample: a launch goes
        back to the scene's method once its direction has settled (``launched``, :func:`_launch_settled`).
        """
        if method not in IMPLICIT and _launching(modes) and not self.launched:
            return LAUNCH_METHOD
        if method not in IMPLICIT and method not in FIXED and self.resting:  # the slide coming to rest: the same
            return self.resting
        return method

    def _max_step(self, modes: list[ContactMode], method: str) -> float:
        """[s] The scene's max_step, or for an explicit method at most RELAX_STEP relaxation times of
        the chain ends relaxing after a separation (their stiff decay, resolved)."""
        if method in IMPLICIT:
            return self.solver.max_step
        tau = min((c.relaxation_time(m) for c, m in zip(self.system.contacts, modes, strict=True)), default=math.inf)
        return min(self.solver.max_step, RELAX_STEP * tau)

    def _next_phase(self, phase: Phase, t: float, x: np.ndarray, modes: list[ContactMode]):
        """The next phase started at t [s]: (x, modes, phase). Its law changes the forces at once, so the modes
        are decided again under it (:meth:`Transitions.settle`): a stick its new friction leaves outside the
        cone slips there, a contact it pulls separates, a limit it pulls off is released."""
        nxt = phase.index + 1
        if nxt >= len(self.scene.phases):
            return x, modes, replace(phase, spec=replace(phase.spec, until=math.inf))  # the last phase runs on
        self.log.log(t, "phase", self.scene.phases[nxt].name, check_storm=False)
        phase, previous = self.system.start_phase(nxt, t, x, phase), phase
        x = self.sampled.start(t, x, modes, phase, previous)  # a sampled law's first sample
        return self.transitions.settle(t, x, modes, phase)

    # ---- output ---------------------------------------------------------------------
    def _result(self, wall: float) -> Result:
        system, scene = self.system, self.scene
        T = scene.duration
        channels, xs = sample_states(system, self.segments, output_grid(T, self.solver.output_rate), self.stats)
        checks = run_checks(system, xs, channels, self.starts, self.impacts, self.events)
        rate_stats, rate_warnings = rate_limit_report(system.robot, channels["t"], channels["v"], channels["tau"])
        self.stats["rhs_evals"] += sum(getattr(seg.sol, "late_calls", 0) for seg in self.segments)  # DOP853C's
        stats = dict(self.stats, wall_s=wall, real_time_factor=T / wall if wall > 0 else math.inf,
                     method=self.solver.method, rtol=self.solver.rtol, atol=self.solver.atol,
                     compiled_modes=self.pipelines.count(),
                     paths=self.paths.table(), limits=rate_stats)
        meta = {**system.robot.describe(), "posture": system.posture, "limit_warnings": rate_warnings,
                "joint_friction": system.joint_friction.describe(),
                "contacts": [c.name for c in system.contacts],
                "bodies": system.body_names, "robot": str(system.robot.source), "tip": scene.robot.tip,
                "name": scene.name, "duration": T, "checks": checks, "check_warnings": violations(checks),
                "scene_file": str(Path(scene.file).resolve()) if scene.file else None}  # (where it came from)
        return Result(channels, self.events, self.impacts, stats, scene.document, meta)


def _runner(run: HybridRun, modes: list[ContactMode], phase: Phase, start: bool = False):
    """What runs (modes, phase) of ``run``: the one pipeline's mode (:class:`~contactdyn.model.paths.LivePipelines`);
    a mode it cannot pack stops the run with the reason. ``start``: a segment starts there: the path is recorded."""
    pipes = run.pipelines
    why = pipes.declined(modes, phase)
    if why:
        label = mode_label(run.system, modes, phase)
        raise SimulationError(f"{run.scene.name}: the model cannot run phase {label}: {why}")
    # (a notice's watch is a thread: only while the mode's pipeline is first built, once per mode)
    with nullcontext() if pipes.built(modes, phase) or pipes.twins is not None else compiling("the one pipeline"):
        mode = pipes.mode(modes, phase)
    if start:
        run.paths.record(run.system, modes, phase, mode)
    return mode


def _failure(run: HybridRun, exc: Exception) -> Exception:
    """What a run that raised ``exc`` reports: a user's law's own error (its LawError, at the time of the interpreted
    call it raised in); the calls' budget spent (OverBudget) or a blow-up numpy noticed as a SimulationError saying
    when; a SimulationError as it is, or as the LawError of a law that returned NaN or ±inf in the failing segment
    (:func:`_non_finite`); else ``exc`` itself."""
    error = law_error(exc, call_time(exc))
    if error is not None or isinstance(exc, LawError):
        return error or exc
    t = run.segments[-1].t1 if run.segments else 0.0
    if isinstance(exc, OverBudget):  # (Work.count stopped counting: the report's own calls are free)
        exc = SimulationError(_over_budget(run, *_spent_at(run), calls=True))
    elif isinstance(exc, (*numerical_errors(), ZeroDivisionError)):
        exc = SimulationError(f"{run.scene.name}: numerical failure after t = {t:.9g} s ({type(exc).__name__}: "
                              f"{exc}); check the scene's magnitudes (initial velocities, gains, stiffness)")
    return (_non_finite(run, t, exc) or exc) if isinstance(exc, SimulationError) else exc


def _non_finite(run: HybridRun, since: float, exc: SimulationError) -> LawError | None:
    """The LawError of a law that returned NaN or ±inf in the latest call with no answer at or after ``since`` [s]
    (the failing segment's start; its pipeline's ``non_finite``), with what the run then said (``exc``); None if no
    law did."""
    pipes = [m.pipe for m in run.pipelines.pipes.values() if getattr(m, "pipe", None) is not None]
    pipes = [p for p in pipes if p.last_failed is not None and p.last_failed[0] >= since]
    n = max(pipes, key=lambda p: p.last_failed[0]).non_finite() if pipes else None
    return None if n is None else n.adding(f"the run then stopped: {exc}")


def _over_budget(run: HybridRun, t: float, x: np.ndarray, calls: bool = False) -> str:
    """Why a run that reached its step budget (``calls``: its right-hand-side calls' budget) stops: where, and
    the fastest mode if that says why."""
    lam = np.zeros(0)
    if run.segments and np.all(np.isfinite(x)):
        try:
            with np.errstate(all="ignore"):
                lam = jacobian_eigenvalues(run.segments[-1].runner.rhs, t, x)
        except LawError:  # (a user's law failing there: the cause)
            raise
        except (SimulationError, np.linalg.LinAlgError):  # (a call with no answer there: no mode to name)
            lam = np.zeros(0)
    stiff = (f"; its fastest mode |λ| = {float(np.abs(lam).max()):.3g} 1/s (solver.stabilization = "
             f"{run.solver.stabilization:g} 1/s, the contacts' stiffness and damping set it)") if len(lam) else ""
    advice = "a stiff scene runs with solver.method = \"Radau\" or \"auto\"" \
        if run.solver.method not in IMPLICIT else "even the implicit method needs more: check the magnitudes"
    spent = f"{run.work.calls} right-hand-side calls ({CALLS_PER_STEP} per budgeted step)" if calls \
        else f"{run.budget} integration steps"
    rate = sample_rate(run.scene)  # [Hz]
    per_sample = f" + {STEPS_PER_SAMPLE} per sample of its {rate:g} Hz law" if rate else ""
    return (f"{run.scene.name}: stopped at t = {t:.6g} s of {run.scene.duration:g} s after {spent}, "
            f"its budget ({STEPS_BASE} + solver.steps_per_second = "
            f"{run.solver.steps_per_second:g} per simulated second{per_sample}){stiff}; {advice}, or raise "
            "solver.steps_per_second")


def _diagnose(run: HybridRun, sol, modes: list[ContactMode], phase: Phase, fun, method: str) -> str:
    """Why a segment of (modes, phase) failed, as far as the state at the failure says."""
    t, x = float(sol.t[-1]), sol.y[:, -1].copy()  # (contiguous: the compiled call takes no strided state)
    if not np.all(np.isfinite(x)) or method in FIXED:  # RK4 states its own cause
        return ""
    with np.errstate(all="ignore"):
        cond = kkt_condition(run.system, x, modes, phase)
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


def _spent_at(run: HybridRun) -> tuple[float, np.ndarray]:
    """(t [s], x) where a run's calls' budget was spent: the counted call's, else (a compiled step counts no state)
    the last finished segment's end, else the start."""
    if run.work.last is not None:
        t, x = run.work.last
        return float(t), np.array(x, float)
    if run.segments:
        last = run.segments[-1]
        return last.t1, np.asarray(last.sol(last.t1), float)
    return 0.0, run.start()[0]


def _stall_check(run: HybridRun, stall: LawStall) -> None:
    """The steps shrank against calls with no answer (events.LawStall): the LawError of a law that returned NaN or
    ±inf in the last of them (``Pipeline.non_finite``: the call run again interpreted, its laws' results checked) is
    raised; else (no law's: a contact system not finite there) the run goes on as before from the step it had
    reached, the mode no longer watched."""
    error = stall.pipe.non_finite()
    if error is not None:
        raise error.adding(f"the run stalled there: its steps shrank from {stall.longest:.3g} s to {stall.short:.3g} s "
                           "against it")
    run.stall_checked = True
    run.next_step = stall.short


def _launch_settled(run: HybridRun, fun, t: float, x: np.ndarray, period: float) -> bool:
    """Under a sampled law's hold: has a 2-D slip launched from rest grown enough that its direction's relaxation
    (every decaying mode) is stable for explicit steps of one period [s], period·|λ| ≤ LAUNCH_SETTLED? Then the
    scene's method, one that carries the samples (DOP853C, ``auto`` on it), does so for the rest of the mode;
    LAUNCH_METHOD would end a segment at each sample and restart there (case2_writer_ur5 at 1 kHz: 797 such
    segments, 9× its continuous run). Another method ends a segment at each sample either way: it keeps LSODA."""
    lam = jacobian_eigenvalues(fun, t, x)
    run.stats["rhs_evals"] += len(x) + 1
    decaying = np.abs(lam[lam.real < 0.0])
    settled = not len(decaying) or float(decaying.max()) * period <= LAUNCH_SETTLED
    if settled:
        run.stats["launches_handed_over"] = run.stats.get("launches_handed_over", 0) + 1
    return settled


def _held_by_stability(run: HybridRun, fun, t: float, x: np.ndarray, h: float, span: float, period: float | None
                       ) -> tuple[bool, float]:
    """(is the explicit step h [s] held at its stability bound by a mode decaying within ``span`` [s], that mode's
    |λ| [1/s] or 0) (:func:`~contactdyn.numerics.integrators.stability_bound`; its n + 1 calls counted), but not where
    something bounds the stiff methods' steps too, so that no switch pays: the scene's max_step, or under a sampled
    law's hold a ``period`` [s] shorter than HOLD_SWITCH such steps (LAUNCH_METHOD and Radau end a segment at every
    sample: then not even its Jacobian is formed)."""
    if h >= (1.0 - 1e-9) * run.solver.max_step or (period is not None and period < HOLD_SWITCH * h):
        return False, 0.0
    run.stats["rhs_evals"] += len(x) + 1
    return stability_bound(fun, t, x, h, span)


def _explicit_step(sol, held: bool) -> float:
    """[s] The step the explicit method had reached where its budget ran out or its steps collapsed: its last step;
    under a hold the longest of its last HELD_STEPS_SEEN steps (a step clipped to a sample instant is shorter than the
    method's own)."""
    if not held:
        return float(sol.t[-1] - sol.t[-2])
    return float(np.max(np.diff(sol.t[-HELD_STEPS_SEEN - 1:])))


def _reached(sol, h0: float | None, sample: bool) -> float | None:
    """[s] The step size a segment that reached its end had reached: after a corner its last full step (the one
    before the step cut short by the end); after a sample instant the step the solver proposes next (else its
    longest): segments one sample period long are often one step, the next starts with it, capped by the period."""
    if sample:
        h_next = getattr(sol, "h_next", None)  # the compiled DOP853's proposal (numerics.dop853)
        return h_next if h_next is not None else float(np.max(np.diff(sol.t))) if len(sol.t) > 1 else h0
    return float(sol.t[-2] - sol.t[-3]) if len(sol.t) > 2 else h0


def _sliding_2d(modes: list[ContactMode]) -> bool:
    """Does a contact slide with 2-D friction (its direction stiff near rest)?"""
    return any(m.touching and not m.stuck and len(m.slip) == 2 for m in modes)


def _launching(modes: list[ContactMode]) -> bool:
    """Does a 2-D slip start from rest (its direction stiff until the slip has grown)? (The loop's rule as it was:
    unlike :func:`~contactdyn.model.friction.launching` it also counts a contact that separated while launching.)"""
    return any(m.from_rest and len(m.slip) == 2 and not m.stuck for m in modes)
