"""Which parts of a scene the compiled right-hand side runs, declared by the parts and known at load.

One description of the model serves both paths. The readable right-hand side
(:mod:`contactdyn.dynamics`) is the model; the compiled plan (:mod:`contactdyn.rhsplan`)
reads its affine parts off the same functions by unit probes (:mod:`contactdyn.plan_probe`)
and calls the rest — a controller's ``command`` — with the same inputs. A part therefore
needs no second implementation to be fast, *if* the plan can represent it. Where it
cannot, the part says so itself, with a ``fast_path_gap`` attribute ("" when compiled):
a stage law (:class:`~contactdyn.chain.ChainStage`), since only the linear law is affine.
The drives and controllers need none: the plan calls the drive law per call, and folds a
force-reading law into its solve (:mod:`contactdyn.plan_fold`); a slip launching from rest
has its direction solved per call on the plan's own KKT system (:mod:`contactdyn.plan_rhs`);
a joint pressing on its position limit is one more row of that system
(:mod:`contactdyn.plan_probe`). The system adds its own gap: the energy audit.
:func:`declared_gaps` collects them when the system is built (``System.fast_path_gaps``,
reported in ``Result.stats["fast_path_gaps"]``); the plan of a mode declines exactly when
one of them applies to that mode (:func:`mode_gap`). A plan that declines for any
other reason — its probes find a non-affine part, or its self-check disagrees with the
readable model — is an undeclared gap: its reason in ``Result.stats["fallback_modes"]``
starts with ``"undeclared: "``, which the tests treat as a bug.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import NamedTuple

__all__ = ["Gap", "declared_gaps", "mode_gap", "UNDECLARED", "ENERGY"]

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
    return gaps


def mode_gap(system, modes, phase) -> str:
    """Why the plan of (modes, phase) must decline: the first declared gap that applies ("" if none)."""
    for gap in system.fast_path_gaps:
        if gap.applies(modes, phase):
            return gap.reason
    return ""
