"""PD control in joint space or task space, with optional feedforward and force set-point.

Task space: f = K_p P (x_d − x) + K_d P (ẋ_d − ẋ) − Σ F_d n, τ = Jᵀ f [+ feedforward],
where P projects on the position-controlled axes and F_d n presses with each force set-point F_d
along its direction n: a contact normal (benchmark B1's law) or a tangent (case 1's F1), damped
along n by ``kd_normal``: f −= D_n (n·ẋ) n (zero at rest, so the pressure's set-point is kept).

Optionally the task PD also holds the tip's orientation, τ += J_ωᵀ m with J_ω the tip's angular Jacobian
(LOCAL_WORLD_ALIGNED) and ω = J_ω q̇, in one of two ways:

* a tool axis a (e.g. a pencil, the tip frame's local ``tool_axis``) along a world direction d
  (``tool_target``): m = K_o (a × d) − D_o ω⊥, ω⊥ the angular velocity without its roll about a
  (a 5-DOF robot cannot control that roll);
* the full orientation R_d (``orientation``, the tip frame's rotation in the world, by rows):
  m = K_o e_R − D_o ω with e_R = ½ vee(R_d Rᵀ − R R_dᵀ) = ½ Σ_c r_c × r_d,c (world), which is −sin θ k for
  R = exp(θ [k]ₓ) R_d: a moment K_o sin θ ≈ K_o θ back about the error's axis (K_o [N·m/rad], D_o [N·m·s/rad];
  why this error and not the log map: :mod:`contactdyn.laws.controllers.task_pd_law`).

The arithmetic of τ is :func:`contactdyn.laws.controllers.task_pd_law.torque`, compiled once for this readable law and
the one pipeline's call. Joint space: τ = K_p (q_d − q) + K_d (q̇_d − q̇) [+ feedforward]. Feedforward:
``none``, ``gravity`` (the uncompensated gravity load g(q)) or ``bias`` (h(q, q̇)).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ...numerics.compile_cache import njit
from ...numerics.linalg import contiguous
from ...numerics.twins import current
from . import task_pd_law as law
from .base import FEEDFORWARD, BindContext, ControlInput, Controller, register

__all__ = ["TaskPD", "JointPD", "KP_TASK", "KD_TASK", "read_tool_axis", "read_orientation", "joint_pd_torque"]

_NONE, _NO_ROTATION = np.empty(0), np.empty((0, 3))  #: task_pd_law's "none"
ROTATION_TOL = 1e-6  #: largest |R Rᵀ − I| accepted of a scene's orientation (then made exactly orthonormal)

KP_TASK, KD_TASK = 2000.0, 100.0  #: default task-space stiffness [N/m] and damping [N·s/m]


def _gains(reader, name: str, default: float, unit: str) -> np.ndarray:
    raw = reader.raw(name, default)
    if isinstance(raw, list):
        return reader.vector(name, unit=unit)
    return np.array([reader.float(name, default, lo=0.0, unit=unit)])


def read_tool_axis(r) -> tuple[np.ndarray | None, np.ndarray | None]:
    """(tool_axis in the tip frame, tool_target in the world), both unit; (None, None) without a tool_axis."""
    if not r.has("tool_axis"):
        return None, None
    return (r.vector("tool_axis", None, size=3, unit_norm=True),
            r.vector("tool_target", [0.0, 0.0, -1.0], size=3, unit_norm=True))


def read_orientation(r) -> np.ndarray | None:
    """The tip frame's rotation in the world to hold (3 × 3, ``orientation`` by rows), made exactly orthonormal
    (the nearest rotation); None without one."""
    if not r.has("orientation"):
        return None
    raw = r.raw("orientation")
    if not isinstance(raw, list) or len(raw) != 3:
        raise r.error("orientation", "a rotation matrix: 3 rows of 3 numbers", raw)
    R = np.array([type(r)({str(i): row}, r.key("orientation"), r.file).vector(str(i), size=3)
                  for i, row in enumerate(raw)])
    if np.max(np.abs(R @ R.T - np.eye(3))) > ROTATION_TOL or np.linalg.det(R) <= 0.0:
        raise r.error("orientation", f"a rotation matrix (orthonormal rows to {ROTATION_TOL:g}, determinant +1)", raw)
    U, _, Vt = np.linalg.svd(R)
    return U @ Vt


def _feedforward(inp: ControlInput, kind: str) -> np.ndarray | float:
    if kind == "bias":
        return inp.h
    if kind == "gravity":
        return inp.gravity
    return 0.0


@dataclass(frozen=True)
class TaskPDConfig:
    kp: np.ndarray  #: [N/m], scalar or one per axis
    kd: np.ndarray  #: [N·s/m]
    axes: np.ndarray  #: (k, 3) position-controlled directions (orthonormal)
    feedforward: str
    tool_axis: np.ndarray | None = None  #: tool direction in the tip frame (None: orientation free)
    tool_target: np.ndarray | None = None  #: desired tool direction in the world (unit)
    ko: float = 50.0  #: orientation stiffness [N·m/rad]
    do: float = 2.0  #: orientation damping [N·m·s/rad]
    kd_joint: float = 0.0  #: joint damping for redundant robots [N·m·s/rad]
    kd_normal: float = 0.0  #: damping of the tip's velocity along each force set-point's direction [N·s/m]
    orientation: np.ndarray | None = None  #: the tip frame's rotation to hold (3, 3) (None: no full orientation)
    kind: str = "task_pd"


@register
class TaskPD(Controller):
    """Tip-space PD on the position axes, minus the force set-points along their normals; tau = J^T f."""

    name = "task_pd"

    @staticmethod
    def applies_force_setpoints(config: TaskPDConfig) -> bool:
        return True

    @staticmethod
    def read(r) -> TaskPDConfig:
        axes_raw = r.raw("axes", [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]])
        if not isinstance(axes_raw, list) or not axes_raw:
            raise r.error("axes", "a list of direction vectors", axes_raw)
        axes = np.array([type(r)({str(i): a}, r.key("axes"), r.file).vector(str(i), size=3, unit_norm=True)
                         for i, a in enumerate(axes_raw)])
        kp, kd = _gains(r, "kp", KP_TASK, "N/m"), _gains(r, "kd", KD_TASK, "N·s/m")
        for name, g in (("kp", kp), ("kd", kd)):
            if len(g) not in (1, len(axes)):
                raise r.error(name, f"one gain or one per axis ({len(axes)})", g.tolist())
        tool_axis, tool_target = read_tool_axis(r)
        orientation = read_orientation(r)
        if orientation is not None and tool_axis is not None:
            raise r.error("orientation", "either orientation (the full rotation) or tool_axis (one direction), not "
                          "both", "both")
        return TaskPDConfig(kp, kd, axes, r.str("feedforward", "none", choices=FEEDFORWARD), tool_axis, tool_target,
                            r.float("ko", 50.0, lo=0.0, unit="N·m/rad"), r.float("do", 2.0, lo=0.0, unit="N·m·s/rad"),
                            r.float("kd_joint", 0.0, lo=0.0, unit="N·m·s/rad"),
                            r.float("kd_normal", 0.0, lo=0.0, unit="N·s/m"), orientation)

    def __init__(self, config: TaskPDConfig, nv: int):
        super().__init__(config, nv)
        self.needs_gravity = config.feedforward == "gravity"
        #: reads R_tip, J_ang: for the tool-axis or orientation moment only
        self.reads_orientation = config.tool_axis is not None or config.orientation is not None
        a = config.axes
        self._kp = (a.T * np.broadcast_to(config.kp, len(a))) @ a  # Σ kp_i a_i a_iᵀ [N/m]
        self._kd = (a.T * np.broadcast_to(config.kd, len(a))) @ a
        c = contiguous
        tool = (c(config.tool_axis), c(config.tool_target)) if config.tool_axis is not None else (_NONE, _NONE)
        #: task_pd_law.torque's constant arguments from ``axes`` to ``kd_normal``
        self.constants = (c(a), c(np.broadcast_to(config.kp, len(a))), c(np.broadcast_to(config.kd, len(a))), *tool,
                          _NO_ROTATION if config.orientation is None else c(config.orientation),
                          float(config.ko), float(config.do), float(config.kd_joint), float(config.kd_normal))

    def bind(self, context: BindContext) -> None:
        ref = context.phase.reference
        if ref is not None and ref.space != "task":
            from ...errors import SceneError

            raise SceneError(f"phase[{context.index}].reference.space", "'task' (task_pd tracks the tip)", ref.space,
                             context.scene.file)

    def command(self, inp: ControlInput) -> tuple[np.ndarray, None]:
        c = contiguous
        axes, kp, kd, tool_axis, target, R_d, ko, do, kd_joint, kd_normal = self.constants
        referenced = inp.x_d is not None
        keys = list(inp.force_d)
        set_points = np.array([inp.force_d[k][0] for k in keys])  # F_d [N]
        forced = np.array([inp.normals[k] for k in keys], dtype=float).reshape(-1, 3)
        orient = self.reads_orientation
        ff = _feedforward(inp, self.config.feedforward)
        torque = current(law).torque
        tau = torque(c(inp.v), c(inp.J), c(inp.J_ang) if orient else np.empty((0, self.nv)), c(inp.p_tip),
                     c(inp.v_tip), c(inp.x_d) if referenced else _NONE, c(inp.v_d) if referenced else _NONE,
                     set_points, c(inp.R_tip) if orient else _NO_ROTATION, axes, forced, kp, kd, tool_axis, target,
                     R_d, ko, do, kd_joint, kd_normal, _NONE if np.isscalar(ff) else c(ff))
        return tau, None


@dataclass(frozen=True)
class JointPDConfig:
    kp: np.ndarray  #: [N·m/rad or N/m]
    kd: np.ndarray  #: [N·m·s/rad or N·s/m]
    feedforward: str
    kind: str = "joint_pd"


@register
class JointPD(Controller):
    """Joint-space PD: tau = kp (q_d - q) + kd (v_d - v) [+ feedforward]; ignores force set-points."""

    name = "joint_pd"

    @staticmethod
    def read(r) -> JointPDConfig:
        return JointPDConfig(_gains(r, "kp", 100.0, "N·m/rad"), _gains(r, "kd", 10.0, "N·m·s/rad"),
                             r.str("feedforward", "none", choices=FEEDFORWARD))

    def __init__(self, config: JointPDConfig, nv: int):
        super().__init__(config, nv)
        self.needs_gravity = config.feedforward == "gravity"
        for name in ("kp", "kd"):
            if len(getattr(config, name)) not in (1, nv):
                from ...errors import SceneError

                raise SceneError(f"controller.{name}", f"one gain or {nv} (one per joint)", getattr(config, name))
        #: K_p, K_d per joint (joint_pd_torque's)
        self.gains = tuple(np.broadcast_to(np.asarray(g, float), nv).copy() for g in (config.kp, config.kd))

    def bind(self, context: BindContext) -> None:
        ref = context.phase.reference
        if ref is not None and ref.space != "joint" and self.nv != 3:  # (a tip's 3 coordinates for nv joints)
            from ...errors import SceneError

            raise SceneError(f"phase[{context.index}].reference.space", f"'joint' (joint_pd tracks the {self.nv} "
                             "joints)", ref.space, context.scene.file)

    def command(self, inp: ControlInput) -> tuple[np.ndarray, None]:
        ff = _feedforward(inp, self.config.feedforward)
        ref = (contiguous(inp.x_d), contiguous(inp.v_d)) if inp.x_d is not None else (_NONE, _NONE)
        tau = current(joint_pd_torque)(contiguous(inp.q), contiguous(inp.v), *ref, *self.gains,
                                       _NONE if np.isscalar(ff) else contiguous(ff))
        return tau, None


@njit(cache=True)
def joint_pd_torque(q, v, q_d, v_d, kp, kd, tau_ff):
    """τ = K_p (q_d − q) + K_d (q̇_d − q̇) [+ τ_ff] [N·m or N]: the joint PD law, compiled once for every path (its
    readable command, the one pipeline); no reference: q_d, q̇_d of size 0; no feedforward: τ_ff of size 0."""
    tau = np.zeros(q.size)
    if q_d.size:
        tau += kp * (q_d - q) + kd * (v_d - v)
    if tau_ff.size:
        return tau + tau_ff
    return tau
