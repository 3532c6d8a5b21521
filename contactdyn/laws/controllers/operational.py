"""Operational-space (Khatib) motion/force control: the task's own inertia decouples its directions.

The task x = [S p; tilt] stacks the tip position p [m] along the position axes and the force
set-point directions (S: their orthonormal rows) and, when a ``tool_axis`` a is held, the two
components of the tip's angular motion perpendicular to a (E: an orthonormal basis of a⊥; the
roll about a is left to the null space). Its Jacobian J_t = [S J; E J_ω], its inertia
Λ = (J_t H⁻¹ J_tᵀ)⁻¹, and the law

    τ = J_tᵀ (Λ (a* − J̇_t q̇ + k_null ẋ_t) + f) − k_null H q̇ + h(q, q̇)

Through Λ, the commanded task acceleration a* [m/s², rad/s²]: the reference acceleration a_d
along each position axis, ko (a × d) − do ω⊥ on the tilt (d the ``tool_target``), zero along
the force directions. Directly, the task force f: along each position axis the stiffness
kp (x_d − p) + kd (ẋ_d − ṗ) [N] (−kd ṗ when the phase has no reference), along each force
set-point direction n the set-point −F_d − kd_normal (n·ṗ) [N]. The k_null [1/s] terms are the
null-space damping N_tᵀ(−k_null H q̇) of a redundant arm (they cancel when the task has as many
directions as the arm has joints).

Why this split. With the robot alone ẍ_t = a* + Λ⁻¹ (f + the contact force in task
coordinates): the reference's motion and the tilt's correction are realised without any push
along the normal (the Jacobian-transpose law ``task_pd`` turns its tilt moment into force on
the surface through the arm's inertia). The position error's stiffness is the part that must
balance friction at rest; as a force along the axes it has no component along the normal, so
at rest the normal force equals F_d whatever friction does. Sent through Λ it would press by
Λ_nt Λ_tt⁻¹ F_f (measured on the writing task: 3.3-10.7 N instead of 5 N on a Panda). A task
direction the arm cannot move (a task singularity) is a clear error.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ...errors import SceneError, SimulationError
from ...numerics.linalg import contiguous
from ...numerics.twins import current
from . import operational_law as law
from .base import BindContext, ControlInput, Controller, register
from .dynamic import K_NULL, KP, KV, _axes, _check_gain_size, _gain
from .operational_law import SINGULAR
from .pd import KD_TASK, KP_TASK, read_tool_axis

__all__ = ["OperationalSpace", "OperationalSpaceConfig", "SINGULAR"]

_NONE = np.empty(0)  #: no reference, no tool axis (operational_law's "none")
_NO_ROTATION = np.empty((0, 3))


@dataclass(frozen=True)
class OperationalSpaceConfig:
    kp: np.ndarray  #: [N/m] position stiffness, one or one per axis
    kd: np.ndarray  #: [N·s/m]
    axes: np.ndarray | None  #: (k, 3) position-controlled directions; None: every direction but the force ones
    tool_axis: np.ndarray | None = None  #: tool direction in the tip frame (None: orientation free)
    tool_target: np.ndarray | None = None  #: desired tool direction in the world (unit)
    ko: float = KP  #: [1/s²] tilt error transient
    do: float = KV  #: [1/s]
    k_null: float = K_NULL  #: [1/s] null-space joint damping of a redundant arm
    kd_normal: float = 0.0  #: [N·s/m] damping of the tip velocity along each force set-point direction
    kind: str = "operational_space"


@register
class OperationalSpace(Controller):
    """Operational-space motion/force law: motion and tool tilt through the task inertia, force set-points directly."""

    name = "operational_space"

    @staticmethod
    def applies_force_setpoints(config: OperationalSpaceConfig) -> bool:
        return True

    @staticmethod
    def read(r) -> OperationalSpaceConfig:
        tool_axis, tool_target = read_tool_axis(r)
        return OperationalSpaceConfig(
            kp=_gain(r, "kp", KP_TASK, "N/m"), kd=_gain(r, "kd", KD_TASK, "N·s/m"), axes=_axes(r),
            tool_axis=tool_axis, tool_target=tool_target,
            ko=r.float("ko", KP, lo=0.0, unit="1/s²"), do=r.float("do", KV, lo=0.0, unit="1/s"),
            k_null=r.float("k_null", K_NULL, lo=0.0, unit="1/s"),
            kd_normal=r.float("kd_normal", 0.0, lo=0.0, unit="N·s/m"))

    def bind(self, context: BindContext) -> None:
        cfg, key, file, phase = self.config, context.key, context.scene.file, context.phase
        self.reads_orientation = cfg.tool_axis is not None  # R_tip, J_ang, drift_ang: for the tilt only
        ref = phase.reference
        if ref is not None and ref.space != "task":
            raise SceneError(f"phase[{context.index}].reference.space", "'task' (operational_space tracks the tip)",
                             ref.space, file)
        self.force_keys = [f.key for f in phase.forces]  #: the set-points' keys, in the order of torque's F_d
        forced = np.array([_direction(context.scene.contacts[f.contact], f.direction) for f in phase.forces]
                          ).reshape(-1, 3)
        if np.max(np.abs(forced @ forced.T - np.eye(len(forced))), initial=0.0) > 1e-9:
            raise SceneError(f"phase[{context.index}].force", "set-points along mutually orthogonal directions",
                             forced.tolist(), file)
        if cfg.axes is not None:
            if np.max(np.abs(cfg.axes @ forced.T), initial=0.0) > 1e-9:
                raise SceneError(f"{key}.axes", f"directions orthogonal to the force set-points' {forced.tolist()}",
                                 cfg.axes.tolist(), file)
            axes = cfg.axes
        else:  # the orthogonal complement of the force directions
            _, sv, vt = np.linalg.svd(np.vstack((forced, np.zeros((1, 3)))))
            axes = vt[int(np.sum(sv > 1e-9)):]
        for name in ("kp", "kd"):
            _check_gain_size(getattr(cfg, name), (1, len(axes)), f"{key}.{name}", file)
        k, n_tilt = len(axes), 0 if cfg.tool_axis is None else 2
        m = k + len(forced) + n_tilt
        if m > self.nv:
            raise SceneError(key, f"a task of at most {self.nv} directions (the arm's joints): {k} position axes, "
                             f"{len(forced)} force directions" + (", 2 tool tilts" if n_tilt else ""), m, file)
        self._m = m
        kp, kd = np.broadcast_to(cfg.kp, k).copy(), np.broadcast_to(cfg.kd, k).copy()  # [N/m], [N·s/m] per axis
        null = bool(cfg.k_null) and m < self.nv  # a redundant arm with null-space damping
        self._target = cfg.tool_target
        tool = (_NONE, _NONE) if self._target is None else (contiguous(cfg.tool_axis), contiguous(self._target))
        #: the law's constant arguments (operational_law.torque's from ``axes`` on)
        self.constants = (contiguous(axes), contiguous(forced), kp, kd, *tool,
                          float(cfg.ko), float(cfg.do), float(cfg.k_null) if null else 0.0, float(cfg.kd_normal))

    def command(self, inp: ControlInput) -> tuple[np.ndarray, None]:
        ref = None if inp.x_d is None else (inp.x_d, inp.v_d, inp.a_d)
        set_points = [inp.force_d[key][0] for key in self.force_keys]
        J_tip, drift_tip = inp.J, inp.drift
        if self._target is not None:  # [J; J_ω], [J̇q̇; J̇_ω q̇]
            J_tip, drift_tip = np.concatenate((inp.J, inp.J_ang)), np.concatenate((inp.drift, inp.drift_ang))
        return self.torque(inp.t, inp.v, inp.H, inp.h, J_tip, drift_tip, inp.p_tip, inp.v_tip, ref, set_points,
                           inp.R_tip), None

    def torque(self, t: float, v: np.ndarray, H: np.ndarray, h: np.ndarray, J_tip: np.ndarray,
               drift_tip: np.ndarray, p_tip: np.ndarray, v_tip: np.ndarray, ref: tuple | None,
               set_points: list[float], R_tip: np.ndarray | None) -> np.ndarray:
        """τ [N·m or N] of the module's law at the joint velocities v, the rigid model's H and h, the tip's
        Jacobian J_tip and J̇q̇ ``drift_tip`` (its linear rows (3, nv) and (3,) [m/s²]; for a held tool axis
        the 6 rows [J; J_ω], [J̇q̇; J̇_ω q̇ [rad/s²]] in Pinocchio's order, and the tip's rotation R_tip,
        else None), p_tip [m], v_tip [m/s], the reference ``ref`` = (x_d, ẋ_d, ẍ_d) or None and the
        set-points F_d [N] in the order of ``force_keys``. The arithmetic is
        :func:`contactdyn.laws.controllers.operational_law.torque`, which the one pipeline's call
        (:mod:`contactdyn.model.pipeline.control_laws`) runs too; the readable ``command`` comes here."""
        c = contiguous
        x_d, v_d, a_d = (_NONE, _NONE, _NONE) if ref is None else (c(ref[0]), c(ref[1]), c(ref[2]))
        torque = current(law).torque
        tau, ratio = torque(v, c(H), h, c(J_tip), drift_tip, p_tip, v_tip, x_d, v_d, a_d, np.array(set_points, float),
                            _NO_ROTATION if R_tip is None else c(R_tip), *self.constants)
        self._guard(ratio, t)
        return tau

    def _guard(self, ratio: float, t: float) -> None:
        """Raise where the task is singular: its Hadamard ratio det(Λ⁻¹) / Π diag(Λ⁻¹) below SINGULAR (or nan)."""
        if not ratio >= SINGULAR:  # also NaN
            raise SimulationError(self.failure(t, ratio))

    def failure(self, t: float, ratio: float = math.nan) -> str:
        """The singular task's error at t [s] (the compiled law returns no command there: status 0)."""
        what = "position axes, force directions" + (" and tool tilt" if self.config.tool_axis is not None else "")
        below = f"{ratio:.3g} < {SINGULAR:g}" if math.isfinite(ratio) else f"below {SINGULAR:g}"
        return (f"t = {t:.6g} s: operational_space: the task ({what}: {self._m} directions) is singular at this "
                f"posture (Hadamard ratio of J_t H⁻¹ J_tᵀ {below}): the arm cannot move the tip "
                "along one task direction independently of the others; move the task (robot.tip0) away from the "
                "arm's singularities, drop the tool_axis, or use task_pd")


def _direction(contact, direction: str) -> np.ndarray:
    """World direction of a force set-point: the contact's normal ("n") or its tangent ("t1", "t2")."""
    return contact.normal if direction == "n" else contact.tangents[int(direction[1:]) - 1]
