"""Joint limits: position limits as unilateral constraints, velocity and effort limits checked.

A position limit of an active joint is handled like a rigid contact (``robot.joint_limits =
"enforce"``, the default; ``"ignore"`` turns it off):

- ``limit`` event: the joint's coordinate reaches its lower or upper limit (located by the
  integrator, as a ``touch``);
- plastic impact map: the momentum law M ΔQ̇ = Cᵀ Λ that stops the joint (q̇ᵢ⁺ = 0) while every
  active constraint (bonds, sticks, other limits) keeps holding, the one of a touch with the
  limit's row among the rows (:func:`~contactdyn.model.impact.limit_impact`): a contact sliding on a
  rigid or bonded normal takes its friction impulse −μ_k Λ_n d, or jams, as at a touch;
- while the joint presses on its limit: a constraint row eᵢ with an unknown torque λ [N·m or N]
  and Baumgarte stabilization q̈ᵢ = −2ω q̇ᵢ − ω² (qᵢ − limit) (ω = ``solver.stabilization``);
  λ ≥ 0 at a lower limit, λ ≤ 0 at an upper one;
- ``release`` event: λ reaches zero (the joint stops pressing) and the joint is free again.

The joints pressing on a limit are part of the run's :class:`~contactdyn.model.system.Phase`
(``Phase.limits``), so every segment knows its constraint rows; the one pipeline carries
them as rows of its KKT system (:func:`contactdyn.model.pipeline.contacts.limit_rows`). Continuous joints (and
limits given as lower = upper) have no position limit. Velocity and effort limits of the URDF (0: none given)
are checked on the run's samples: count and first time per joint in ``Result.stats["limits"]``,
a warning per joint in ``Result.meta["limit_warnings"]``.
"""

from __future__ import annotations

from dataclasses import replace
from itertools import groupby
from typing import Any, NamedTuple

import numpy as np

from ..robot.robot import Robot
from .impact import limit_impact

__all__ = ["JointLimits", "limit_channels", "rate_limit_report"]

TOUCH_TOL = 1e-13  #: [rad or m] a free joint's limit event fires this far past min(0, its start margin)
RELEASE_TOL = 1e-9  #: [N·m or N] a pressing joint whose torque pulls by more than this is released at once


class Limit(NamedTuple):
    index: int  #: the joint's coordinate in Q
    name: str
    lower: float  #: [rad or m]
    upper: float


def _event(fn, kind: str, joint: str, index: int, side: int):
    fn.terminal, fn.direction = True, -1
    fn.kind, fn.contact, fn.index, fn.side = kind, joint, index, side
    return fn


class JointLimits:
    """The position limits a run enforces (none with ``robot.joint_limits = "ignore"``)."""

    def __init__(self, robot: Robot, enforce: bool):
        bounded = np.isfinite(robot.lower) & np.isfinite(robot.upper)
        self.limits = [Limit(i, name, float(robot.lower[i]), float(robot.upper[i]))
                       for i, name in enumerate(robot.joint_names) if enforce and bounded[i]]
        self.by_index = {lim.index: lim for lim in self.limits}

    # ---- events ------------------------------------------------------------------------
    def events(self, pressing: tuple[tuple[int, int], ...], x0: np.ndarray, torque=None) -> list:
        """Event functions of one segment: ``limit`` for free joints, ``release`` for pressing ones.

        ``torque(t, x)`` gives the pressing joints' limit torques {index: λ} (needed only when
        some joint presses).
        """
        out = []
        held = {i for i, _ in pressing}
        for lim in self.limits:
            if lim.index in held:
                continue
            i = lim.index
            floor_lo = min(float(x0[i]) - lim.lower, 0.0) - TOUCH_TOL
            floor_hi = min(lim.upper - float(x0[i]), 0.0) - TOUCH_TOL
            # (x.item: a Python float, the same difference as NumPy's float64, at a third of its cost per step end)
            out.append(_event(lambda t, x, i=i, lo=lim.lower, f=floor_lo: x.item(i) - lo - f, "limit", lim.name, i,
                              1))
            out.append(_event(lambda t, x, i=i, hi=lim.upper, f=floor_hi: hi - x.item(i) - f, "limit", lim.name, i,
                              -1))
        for i, side in pressing:
            out.append(_event(lambda t, x, i=i, s=side: s * torque(t, x)[i], "release", self.by_index[i].name, i,
                              side))
        return out

    def resting(self, x: np.ndarray, nQ: int) -> tuple[tuple[int, int], ...]:
        """(index, side) of the joints at rest on a limit in x (within TOUCH_TOL of it, q̇ᵢ = 0): a run starts them
        pressing on it, with no impact (those whose torque pulls are let go: ``Transitions.start``)."""
        out = []
        for lim in self.limits:
            q, v = float(x[lim.index]), float(x[nQ + lim.index])
            if v == 0.0 and abs(q - lim.lower) <= TOUCH_TOL:
                out.append((lim.index, 1))
            elif v == 0.0 and abs(lim.upper - q) <= TOUCH_TOL:
                out.append((lim.index, -1))
        return tuple(out)

    # ---- constraint rows -----------------------------------------------------------------
    def add_rows(self, pressing, x: np.ndarray, nQ: int, rows, omega: float) -> None:
        """A row per pressing joint into ``rows`` (contactdyn.model.constraints.Rows): eᵢ Q̈ + γ = 0 with
        γ = 2ω q̇ᵢ + ω² (qᵢ − limit), ω [1/s] the Baumgarte rate (0 at velocity level)."""
        for i, side in pressing:
            lim = self.by_index[i]
            row = np.zeros(nQ)
            row[i] = 1.0
            gap = float(x[i]) - (lim.lower if side > 0 else lim.upper)
            rows.add(row, 2.0 * omega * float(x[nQ + i]) + omega * omega * gap, (lim.name, "limit", i))

    # ---- switching -------------------------------------------------------------------------
    @staticmethod
    def release(system: Any, x: np.ndarray, phase: Any, i: int) -> tuple[np.ndarray, Any]:
        """(x, phase) as joint i stops pressing on its limit: the limit out of the phase, the joint from rest where
        its dry friction holds it (:meth:`~contactdyn.model.joint_friction.JointFriction.left_limit`)."""
        phase = replace(phase, limits=tuple(p for p in phase.limits if p[0] != i))
        return system.joint_friction.left_limit(x, i, phase, system.nQ), phase

    def switch(self, system: Any, t: float, x: np.ndarray, modes: list, phase: Any, event) -> tuple:
        """Apply a ``limit`` (plastic impact, then pressing) or ``release`` event: (x, phase, info, impact).

        ``impact`` (:class:`~contactdyn.model.impact.Impact`, None at a release) is the momentum law with
        the limit's row among the rows, a sliding contact's friction impulse included
        (:func:`~contactdyn.model.impact.limit_impact`); its contact is "" when no contact took part.
        """
        i = event.index
        if event.kind == "release":
            x, phase = self.release(system, x, phase, i)
            return x, phase, {"joint": event.contact}, None
        phase = replace(phase, limits=(*phase.limits, (i, event.side)))
        v_before = float(x[system.nQ + i])
        x, imp, impulse = limit_impact(system, t, x, modes, phase.limits)
        info = {"joint": event.contact, "side": "lower" if event.side > 0 else "upper",
                "velocity_before": v_before, "impulse": impulse,  # [N·m·s or N·s] the limit row's Λ
                "impulse_unit": "N·m·s" if system.robot.joint_units[i] == "rad" else "N·s",
                "energy_loss": imp.energy_loss}
        return x, phase, info, imp

    def pulling(self, phase: Any, ev: Any) -> list[tuple[int, int]]:
        """Pressing joints whose limit torque pulls (λ·side < 0): they release at once."""
        return [(i, s) for i, s in phase.limits if s * ev.limit_torque.get(i, 0.0) < -RELEASE_TOL]


def limit_channels(system: Any, phases_of: list, samples: Any) -> dict[str, np.ndarray]:
    """``limit.torque`` [N·m or N] (per joint, 0 when free; from the output ``samples``,
    :class:`~contactdyn.output.samples.Samples`) and ``limit.side`` (+1 lower, −1 upper, 0 free)."""
    side = np.zeros((len(phases_of), system.nv))
    k = 0
    for _, run in groupby(phases_of, key=id):  # a run of samples in one phase: its sides at once
        run = list(run)
        for i, s in run[0].limits:
            side[k:k + len(run), i] = s
        k += len(run)
    return {"limit.torque": samples.limit_torque.copy(), "limit.side": side}


def rate_limit_report(robot: Robot, t: np.ndarray, v: np.ndarray, tau: np.ndarray) -> tuple[dict, list[str]]:
    """Velocity and effort limits (URDF values > 0) against the run's samples: stats and warnings."""
    stats, warnings = {}, []
    for what, values, limit, units in (("velocity", v, robot.velocity_limit, {"rad": "rad/s", "m": "m/s"}),
                                       ("effort", tau, robot.effort_limit, {"rad": "N·m", "m": "N"})):
        for j, name in enumerate(robot.joint_names):
            if not limit[j] > 0.0:
                continue
            unit = units[robot.joint_units[j]]
            over = np.flatnonzero(np.abs(values[:, j]) > limit[j] * (1.0 + 1e-12))
            if len(over):
                first = float(t[over[0]])
                stats[f"{what}.{name}"] = {"samples": int(len(over)), "first_t": first,
                                           "peak": float(np.abs(values[:, j]).max()), "limit": float(limit[j])}
                warnings.append(f"joint {name!r} exceeds its {what} limit {limit[j]:.4g} [{unit}] in {len(over)} "
                                f"samples, first at t = {first:.6g} s (peak {np.abs(values[:, j]).max():.4g})")
    return stats, warnings
