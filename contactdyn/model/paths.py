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

Which path each mode of a run took (:func:`path_of`), and which law or part kept
it off the compiled ones, is in ``Result.stats["paths"]`` (:class:`PathLog`); ``contactdyn run``
prints each such mode once.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import NamedTuple

__all__ = ["Gap", "declared_gaps", "mode_gap", "UNDECLARED", "ENERGY", "path_of", "PathLog", "slower_paths"]

UNDECLARED = "undeclared: "  #: prefix of a plan's decline that no part declared
ENERGY = "energy audit (solver.record_energy)"


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


def path_of(plan) -> tuple[str, str]:
    """(path, the law or part that kept it off the compiled ones: "" when none) of a mode's plan. The paths, fastest
    first: "compiled call" (one numba call per right-hand side: the robot's terms, the law, the solve), "compiled
    kernel" (Pinocchio's terms, then one numba call), "compiled plan" (the map P φ and a NumPy solve per call),
    "compiled plan, law in Python" (the controller's command called per call), "readable model" (System.evaluate).
    Which compiled path runs a mode is the plan's choice by its parts' shapes (no drives and an affine tip law: the
    plan's map; motors or a task-space law that is not affine: a kernel), not a law's doing."""
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

    def record(self, system, modes, phase, plan) -> None:
        label = _mode_label(system, modes, phase)
        row = self.rows.get(label)
        if row is None:
            path, why = path_of(plan)
            row = self.rows[label] = {"path": path, "why": why, "segments": 0}
        row["segments"] += 1

    def table(self) -> dict[str, dict]:
        return {label: dict(row) for label, row in self.rows.items()}


def slower_paths(paths: dict[str, dict]) -> list[str]:
    """One line per mode that a law kept off the compiled paths, saying which it ran on and why."""
    return [f"{label}: {row['path']} ({row['why']})" for label, row in paths.items() if row["why"]]
