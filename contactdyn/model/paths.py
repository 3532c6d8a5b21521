"""Which parts of a scene the compiled right-hand side runs, declared by the parts and known at load.

One description of the model serves both paths. The readable right-hand side
(:mod:`contactdyn.model.dynamics`) is the model; the compiled plan (:mod:`contactdyn.compiled.rhsplan`)
reads its affine parts off the same functions by unit probes (:mod:`contactdyn.compiled.plan_probe`)
and calls the rest — a controller's ``command`` — with the same inputs. A part therefore
needs no second implementation to be fast, *if* the plan can represent it. Where it
cannot, the part says so itself, with a ``fast_path_gap`` attribute ("" when compiled):
a stage law (:class:`~contactdyn.model.chain.ChainStage`), since only the linear law is affine,
and a drive kind that is not affine below its voltage limit (its ``affine``,
:mod:`contactdyn.laws.drive_kinds`; the plan reads the drives' law off by probes).
Controllers need none: the plan calls a controller's ``command`` per call, and folds a
force-reading law into its solve (:mod:`contactdyn.compiled.plan_fold`); a slip launching
from rest has its direction solved per call on the plan's own KKT system
(:mod:`contactdyn.compiled.plan_rhs`);
a joint pressing on its position limit is one more row of that system
(:mod:`contactdyn.compiled.plan_probe`). The system adds its own gap: the energy audit.
:func:`declared_gaps` collects them when the system is built (``System.fast_path_gaps``,
reported in ``Result.stats["fast_path_gaps"]``); the plan of a mode declines exactly when
one of them applies to that mode (:func:`mode_gap`). A plan that declines for any
other reason — its probes find a non-affine part, or its self-check disagrees with the
readable model — is an undeclared gap: its reason in ``Result.stats["fallback_modes"]``
starts with ``"undeclared: "``, which the tests treat as a bug.

A mode the plan declines for a declared gap runs on the one pipeline (:mod:`contactdyn.model.pipeline`) where
:func:`~contactdyn.model.pipeline.pack.unsupported` accepts it (:class:`LivePipelines`, the path ``PIPELINE``; with
``LivePipelines.prefer`` every mode it accepts), checked where it starts against the readable model as a plan is
(:func:`disagreement`); else on the readable model.

Which path each mode of a run took (:func:`path_of`), and which law or part kept
it off the compiled ones, is in ``Result.stats["paths"]`` (:class:`PathLog`); ``contactdyn run``
prints each such mode once.
"""

from __future__ import annotations

import os
from collections.abc import Callable
from typing import NamedTuple

import numpy as np

from .pipeline.pack import unsupported
from .pipeline.pipeline import Pipeline

__all__ = ["Gap", "declared_gaps", "mode_gap", "UNDECLARED", "ENERGY", "PIPELINE", "path_of", "PathLog",
           "slower_paths", "disagreement", "LivePipelines", "CHECK_RTOL"]

UNDECLARED = "undeclared: "  #: prefix of a plan's decline that no part declared
ENERGY = "energy audit (solver.record_energy)"
PIPELINE = "one pipeline"  #: the path of a mode the plan declines for a declared gap and the pipeline runs
PREFER_ENV = "CONTACTDYN_PIPELINE"  #: "1": LivePipelines.prefer for the process (a hidden switch, no scene key)
CHECK_RTOL = 1e-9  #: agreement a fast right-hand side must show with System.evaluate where a mode starts


class Gap(NamedTuple):
    """A part the compiled right-hand side does not run, and in which modes that matters."""

    part: str  #: the part's scene key, e.g. "solver.record_energy", "contact.tip.n.env1"
    reason: str
    when: str  #: in words: "always", "in its phase", ...
    applies: Callable  #: applies(modes, phase) -> bool: the plan of (modes, phase) must decline

    def describe(self) -> dict[str, str]:
        return {"part": self.part, "reason": self.reason, "when": self.when}


def declared_gaps(system) -> list[Gap]:
    """The parts of ``system`` that declare themselves not compiled, in the order the plan checks them."""
    gaps = []
    if system.energy_slot >= 0:
        gaps.append(Gap("solver.record_energy", ENERGY, "always", lambda modes, phase: True))
    for ci, c in enumerate(system.contacts):
        for dc in c.chains:
            for k, stage in enumerate(dc.chain.stages):
                if stage.fast_path_gap:
                    gaps.append(Gap(f"contact.{c.name}.{dc.label}.{stage.label}", stage.fast_path_gap,
                                    "while the stage carries force",
                                    lambda modes, phase, ci=ci, dc=dc, k=k: k in dc.plan(modes[ci].touching).active))
    for i, reason in system.drives.fast_path_gaps:  # a drive kind that is not affine (the plan probes the drives)
        name = system.drives.names[i]
        part = f"robot.drive ({name})" if i < system.nv else f"body.{name}.drive"
        gaps.append(Gap(part, reason, "always", lambda modes, phase: True))
    return gaps


def mode_gap(system, modes, phase) -> str:
    """Why the plan of (modes, phase) must decline: the first declared gap that applies ("" if none)."""
    for gap in system.fast_path_gaps:
        if gap.applies(modes, phase):
            return gap.reason
    return ""


def disagreement(system, modes, phase, rhs: Callable, t: float, x: np.ndarray) -> str:
    """"" when ``rhs`` (a fast right-hand side of (modes, phase)) agrees with System.evaluate at (t [s], x) — where a
    run starts the mode — and at a perturbation of x, else the undeclared reason: a law changed on one path only
    cannot pass unseen. Each component of ẋ is held to CHECK_RTOL × (1 + its largest magnitude at the two states):
    at an equilibrium a rate is ~0 but the terms it is made of are not (the perturbed state shows their size)."""
    rng = np.random.default_rng(7)
    scale_x = 1e-3 * (1.0 + np.abs(x))
    states = (x, x + scale_x * rng.normal(size=system.n))
    refs = [system.evaluate(t, state, modes, phase).xdot for state in states]
    scale = 1.0 + np.maximum(np.abs(refs[0]), np.abs(refs[1]))
    for state, ref in zip(states, refs, strict=True):
        got = rhs(t, state.copy())
        if not np.all(np.isfinite(got)) or np.any(np.abs(got - ref) > CHECK_RTOL * scale):
            return (f"{UNDECLARED}disagrees with System.evaluate by {float(np.abs(got - ref).max()):.3g} "
                    f"at t = {t:.6g} s")
    return ""


class LivePipelines:
    """The one pipeline (:class:`~contactdyn.model.pipeline.pipeline.Pipeline`) for the modes of a run whose plan
    declines for a declared gap (a stage law that is not affine, ...) and that the pipeline packs — with ``prefer``,
    for every mode it packs, before the plan is built: one per modes and phase, checked against System.evaluate
    where the run first starts it (:func:`disagreement`), kept wrapped by ``wrap`` (the loop's: its event values,
    compiled steps and output samples, :class:`~contactdyn.hybrid.pipeline_mode.PipelineMode`)."""

    use = True  #: False only for the benchmarks' and tests' before/after comparison: those modes on System.evaluate
    #: True: every mode ``pack.unsupported`` accepts runs on the pipeline, even where the plan runs it (the tests' and
    #: benchmarks' switch, benchmarks/pipeline_loop.py); False: the plan first (the default until the pipeline
    #: covers every mode kind). The environment variable CONTACTDYN_PIPELINE=1 sets it at import, for a whole
    #: process (``contactdyn run`` included: benchmarks/first_run.py --prefer; docs/one_source.md)
    prefer = os.environ.get(PREFER_ENV, "") == "1"

    def __init__(self, system, wrap: Callable = lambda pipe: pipe) -> None:
        self.system, self.wrap = system, wrap
        self.pipes: dict[tuple, object] = {}  #: (modes, phase.key()) -> its pipeline (wrapped), or why not (undeclared)
        self.declines: dict[tuple, str] = {}  #: (modes, phase.key()) -> pack.unsupported's reason ("": it packs them)

    def wanted(self, modes, phase, plan=None) -> bool:
        """Does the pipeline run (modes, phase)? ``plan``: the mode's plan (None: not built; only ``prefer`` runs
        such a mode on the pipeline)."""
        if not self.use:
            return False
        if not self.prefer and (plan is None or plan.ok or plan.reason.startswith(UNDECLARED)):
            return False
        key = (tuple(modes), phase.key())
        if key not in self.declines:
            self.declines[key] = unsupported(self.system, modes, phase)
        return not self.declines[key]

    def built(self, modes, phase) -> bool:
        """Is the pipeline of (modes, phase) packed and checked already (or its check failed)?"""
        return (tuple(modes), phase.key()) in self.pipes

    def mode(self, modes, phase, t: float, x: np.ndarray) -> tuple[object | None, str]:
        """(the pipeline of a mode :meth:`wanted` says it runs, starting at (t [s], x), wrapped; or None and the
        undeclared reason its check disagreed with)."""
        key = (tuple(modes), phase.key())
        pipe = self.pipes.get(key)
        if pipe is None:
            pipe = Pipeline(self.system, modes, phase)
            reason = disagreement(self.system, modes, phase, pipe.rhs, t, x)
            pipe = self.pipes[key] = reason or self.wrap(pipe)
        return (None, pipe) if isinstance(pipe, str) else (pipe, "")


def path_of(plan, pipeline: bool = False) -> tuple[str, str]:
    """(path, the law or part that kept it off the compiled ones: "" when none) of a mode's plan. The paths, fastest
    first: "compiled call" (one numba call per right-hand side: the robot's terms, the law, the solve), "compiled
    kernel" (Pinocchio's terms, then one numba call), "compiled plan" (the map P φ and a NumPy solve per call),
    "compiled plan, law in Python" (the controller's command called per call), PIPELINE (``pipeline``: a mode the
    plan declines runs on the one pipeline's call, :class:`LivePipelines`), "readable model" (System.evaluate).
    Which compiled path runs a mode is the plan's choice by its parts' shapes (no drives and an affine tip law: the
    plan's map; motors or a task-space law that is not affine: a kernel), not a law's doing."""
    if pipeline:  # (plan None: preferred, not built)
        return PIPELINE, plan.reason if plan is not None and not plan.ok else ""
    if not plan.ok:
        return "readable model", plan.reason
    if plan.kernel is not None:
        return ("compiled call" if getattr(plan.kernel, "at", None) is not None else "compiled kernel"), ""
    if plan.python_command:
        kind = plan.phase.controller.config.kind
        return "compiled plan, law in Python", f"controller {kind!r} has no compiled command"
    return "compiled plan", ""


def _mode_label(system, modes, phase) -> str:
    """``press: tip sliding, wall free``: the phase and what each contact does."""
    def state(c, m) -> str:
        if not m.touching:
            return "free"
        if c.friction is None or not len(c.tangents):
            return "touching"
        return "stuck" if m.stuck else "sliding"

    return f"{phase.spec.name}: " + ", ".join(f"{c.name} {state(c, m)}" for c, m in zip(system.contacts, modes,
                                                                                     strict=True))


class PathLog:
    """Per mode of a run (its label): the path it ran on, why not a faster one, and its segments."""

    def __init__(self) -> None:
        self.rows: dict[str, dict] = {}

    def record(self, system, modes, phase, plan, pipeline: bool = False) -> None:
        label = _mode_label(system, modes, phase)
        row = self.rows.get(label)
        if row is None:
            path, why = path_of(plan, pipeline)
            row = self.rows[label] = {"path": path, "why": why, "segments": 0}
        row["segments"] += 1

    def table(self) -> dict[str, dict]:
        return {label: dict(row) for label, row in self.rows.items()}


def slower_paths(paths: dict[str, dict]) -> list[str]:
    """One line per mode that a law kept off the compiled paths, saying which it ran on and why."""
    return [f"{label}: {row['path']} ({row['why']})" for label, row in paths.items() if row["why"]]
