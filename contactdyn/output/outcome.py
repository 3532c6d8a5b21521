"""A run that did not do what its scene asked: warnings read off the result, never fatal.

The sanity warnings (:mod:`contactdyn.scene.sanity`) judge a scene before it runs; these judge
the run after it, so that a run that silently does nothing is never mistaken for one that
worked:

- a force set-point active in a phase whose contact never touched during that phase;
- a normal force set-point that the phase ends far from (|F − F_d| > MISSED |F_d| at its last sample);
- a phase ending at ``touch:<contact>`` whose touch never came (it ran out the duration);
- a contact that force set-points name but that never touched in the whole run.

:func:`contactdyn.simulate.simulate` adds them to ``Result.meta["warnings"]`` (saved in the
run's JSON, counted in a sweep's ``warnings`` column) and issues them as SanityWarning;
``contactdyn run`` prints them.
"""

from __future__ import annotations

import numpy as np

from ..scene.scene_file import Scene
from .result import Result

__all__ = ["outcome_warnings", "phase_spans", "MISSED"]

MISSED = 0.5  #: [-] a phase ending with |F − F_d| above this × |F_d| did not reach its set-point


def phase_spans(scene: Scene, result: Result) -> list[tuple[int, float, float]]:
    """(phase index, start [s], end [s]) of every phase that started, in order (from the ``phase`` events)."""
    starts = [0.0] + [e["t"] for e in result.events if e["kind"] == "phase"][:max(len(scene.phases) - 1, 0)]
    end = float(result.t[-1]) if len(result.t) else 0.0
    return [(i, t0, starts[i + 1] if i + 1 < len(starts) else end)
            for i, t0 in enumerate(starts[:len(scene.phases)])]


def _set_point_missed(result: Result, i: int, phase: str, c: str, inside: np.ndarray) -> list[str]:
    """A normal set-point whose phase ends with the force off by more than MISSED of the set-point."""
    F, F_d = result.channels[f"contact.{c}.F_n"][inside], result.channels[f"contact.{c}.F_d"][inside]
    if not len(F) or not np.isfinite(F_d[-1]) or F_d[-1] == 0.0 or abs(F[-1] - F_d[-1]) <= MISSED * abs(F_d[-1]):
        return []
    t_end = float(np.asarray(result.t)[inside][-1])
    return [f"phase[{i}] ({phase}): the force set-point on contact '{c}' is {F_d[-1]:.4g} N but the contact force "
            f"ends the phase (t = {t_end:.6g} s) at {F[-1]:.4g} N: the set-point was not reached"]


def outcome_warnings(scene: Scene, result: Result) -> list[str]:
    """The sentences for what the run did not do (see the module docstring)."""
    t = np.asarray(result.t, float)
    touched = {name: np.asarray(result.channels[f"contact.{name}.touching"]) > 0.5
               for name in scene.contacts if f"contact.{name}.touching" in result.channels}
    named = {f.contact for p in scene.phases for f in p.forces}
    never = {c for c in named if c in touched and not touched[c].any()}
    out = [f"contact '{c}' never touched, though force set-points name it ([[phase.force]] contact = \"{c}\"): "
           f"the run applied no contact force; check robot.tip0 (or q0) and contact.{c}.point" for c in sorted(never)]
    spans = phase_spans(scene, result)
    for k, (i, t0, t1) in enumerate(spans):
        phase = scene.phases[i]
        last = k == len(spans) - 1  # a sample at a phase's end belongs to the next phase
        inside = (t >= t0) & ((t <= t1) if last else (t < t1))
        if not inside.any():  # a phase shorter than the output step: nothing to judge
            continue
        for c in sorted({f.contact for f in phase.forces} - never):
            if c in touched and not touched[c][inside].any():
                out.append(f"phase[{i}] ({phase.name}): the force set-point on contact '{c}' was active from "
                           f"{t0:.6g} s to {t1:.6g} s but the contact never touched then: it applied nothing")
            elif c in touched:
                out += _set_point_missed(result, i, phase.name, c, inside)
        if isinstance(phase.until, str) and phase.until.startswith("touch:") and i == len(spans) - 1 \
                and i + 1 < len(scene.phases):
            out.append(f"phase[{i}] ({phase.name}) ends at {phase.until}, which never came: it ran out the "
                       f"duration ({t1:.6g} s) and phase[{i + 1}] ({scene.phases[i + 1].name}) never started")
    return out
