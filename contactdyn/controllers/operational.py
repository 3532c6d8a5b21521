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

from ..errors import SceneError, SimulationError
from ..linalg import det, solve_matrix, solve_vector
from .base import BindContext, ControlInput, Controller, register
from .dynamic import K_NULL, KP, KV, _axes, _check_gain_size, _gain
from .pd import KD_TASK, KP_TASK, read_tool_axis

__all__ = ["OperationalSpace", "OperationalSpaceConfig", "SINGULAR"]

#: smallest det(Λ⁻¹) / Π diag(Λ⁻¹) (Hadamard ratio in (0, 1]: the product of sin² of the angles, in the
#: metric H⁻¹, between each task direction and the ones before it) the law accepts; below it the task is
#: singular: one direction within ~1e-4 rad of the others, Λ and the torques beyond what the arm can give
#: (the writing task runs at 2e-4 on the UR10, 0.013 on the Panda and the 5-DOF writer, 0.27 on the UR5)
SINGULAR = 1e-8


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


def _cross(a: list[float], b: list[float]) -> tuple[float, float, float]:
    """a × b of two 3-lists (np.cross costs ~15 µs a call, this ~0.3 µs)."""
    return a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]


def _perpendicular(a: list[float]) -> tuple[tuple[float, float, float], tuple[float, float, float]]:
    """An orthonormal basis (e1, a × e1) of the plane perpendicular to the unit 3-list a."""
    e1 = (0.0, a[2], -a[1]) if abs(a[0]) < 0.9 else (-a[2], 0.0, a[0])  # a × x or a × y
    s = 1.0 / math.sqrt(e1[0] * e1[0] + e1[1] * e1[1] + e1[2] * e1[2])
    e1 = (e1[0] * s, e1[1] * s, e1[2] * s)
    return e1, _cross(a, e1)


def _dot(a, b) -> float:
    """a · b of two 3-sequences of floats."""
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


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
        self._S = np.vstack((axes, forced))  #: (k + f, 3) position rows of the task [unit]
        self._k, self._m = k, m
        self._kp = np.broadcast_to(cfg.kp, k).copy()  # [N/m] per axis
        self._kd = np.broadcast_to(cfg.kd, k).copy()  # [N·s/m]
        self._null = bool(cfg.k_null) and m < self.nv  #: a redundant arm with null-space damping
        self._target = None if cfg.tool_target is None else cfg.tool_target.tolist()
        self._axes_rows = axes.tolist()
        self._forced_rows = forced.tolist()
        self._kp_list, self._kd_list = self._kp.tolist(), self._kd.tolist()
        self._W = np.zeros((m, 6))  #: [S 0; 0 E]: the task's rows on the tip's [linear; angular] motion
        self._W[:len(self._S), :3] = self._S

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
        set-points F_d [N] in the order of ``force_keys``. The readable ``command`` and the plan's call
        (:func:`~contactdyn.plan_law.operational_command`) both come here."""
        cfg, W = self.config, self._W
        a_task, f = self._task_terms(v_tip, p_tip, ref, set_points)
        if self._target is not None:
            a = R_tip.dot(cfg.tool_axis).tolist()  # current tool direction (world)
            e1, e2 = _perpendicular(a)
            W[-2:, 3:] = e1, e2
            omega = J_tip[3:].dot(v).tolist()  # [rad/s]
            c = _cross(a, self._target)
            ko, do = cfg.ko, cfg.do
            w = [ko * c[0] - do * omega[0], ko * c[1] - do * omega[1], ko * c[2] - do * omega[2]]
            a_task += [_dot(e1, w), _dot(e2, w)]
            f += [0.0, 0.0]
            Jt, drift_t = W.dot(J_tip), W.dot(drift_tip)
        else:
            Jt, drift_t = self._S.dot(J_tip), self._S.dot(drift_tip)
        L_inv = Jt.dot(solve_matrix(H, Jt.T))  # Λ⁻¹
        self._guard(L_inv, t)
        if self._null:  # a* − J̇_t q̇ + k_null ẋ_t, as floats (m ≤ 6)
            k_null = cfg.k_null
            rhs = [a - d + k_null * xd for a, d, xd in zip(a_task, drift_t.tolist(), Jt.dot(v).tolist(), strict=True)]
        else:
            rhs = [a - d for a, d in zip(a_task, drift_t.tolist(), strict=True)]
        ft = solve_vector(L_inv, np.array(rhs))  # Λ (a* − J̇_t q̇ + k_null ẋ_t)
        ft += f
        tau = ft.dot(Jt)
        tau += h
        if self._null:
            tau -= cfg.k_null * H.dot(v)
        return tau

    def _task_terms(self, v_tip: np.ndarray, p_tip: np.ndarray, ref: tuple | None,
                    set_points: list[float]) -> tuple[list[float], list[float]]:
        """(a* [m/s²], f [N]) on the position axes and force directions, as Python floats (k + f ≤ 6 terms:
        cheaper than one numpy call each, ~0.5 µs)."""
        axes, kp, kd = self._axes_rows, self._kp_list, self._kd_list
        vx, vy, vz = v_tip.tolist()
        if ref is not None:
            x_d, v_d, a_d = ref
            (ax, ay, az), (px, py, pz) = a_d.tolist(), p_tip.tolist()
            (xx, xy, xz), (wx, wy, wz) = x_d.tolist(), v_d.tolist()
            ex, ey, ez, fx, fy, fz = xx - px, xy - py, xz - pz, wx - vx, wy - vy, wz - vz  # x_d − p, ẋ_d − ṗ
            a_task = [n[0] * ax + n[1] * ay + n[2] * az for n in axes]  # a* [m/s², rad/s²], through Λ
            f = [kp[i] * (n[0] * ex + n[1] * ey + n[2] * ez) + kd[i] * (n[0] * fx + n[1] * fy + n[2] * fz)
                 for i, n in enumerate(axes)]  # [N], directly
        else:
            a_task = [0.0] * self._k
            f = [-kd[i] * (n[0] * vx + n[1] * vy + n[2] * vz) for i, n in enumerate(axes)]
        kd_normal = self.config.kd_normal
        for F_d, n in zip(set_points, self._forced_rows, strict=True):  # set-points along their directions
            a_task.append(0.0)
            f.append(-F_d - kd_normal * (n[0] * vx + n[1] * vy + n[2] * vz))  # [N]
        return a_task, f

    def _guard(self, L_inv: np.ndarray, t: float) -> None:
        ratio = det(L_inv) / math.prod(L_inv.diagonal().tolist())
        if not ratio >= SINGULAR:  # also NaN
            what = "position axes, force directions" + (" and tool tilt" if self.config.tool_axis is not None else "")
            raise SimulationError(
                f"t = {t:.6g} s: operational_space: the task ({what}: {self._m} directions) is singular at this "
                f"posture (Hadamard ratio of J_t H⁻¹ J_tᵀ {ratio:.3g} < {SINGULAR:g}): the arm cannot move the tip "
                "along one task direction independently of the others; move the task (robot.tip0) away from the "
                "arm's singularities, drop the tool_axis, or use task_pd")


def _direction(contact, direction: str) -> np.ndarray:
    """World direction of a force set-point: the contact's normal ("n") or its tangent ("t1", "t2")."""
    return contact.normal if direction == "n" else contact.tangents[int(direction[1:]) - 1]
