"""PD control in joint space or task space, with optional feedforward and force set-point.

Task space: f = K_p P (x_d − x) + K_d P (ẋ_d − ẋ) − Σ F_d n, τ = Jᵀ f [+ feedforward],
where P projects on the position-controlled axes and F_d n presses with each force set-point F_d
along its direction n: a contact normal (benchmark B1's law) or a tangent (case 1's F1), damped
along n by ``kd_normal``: f −= D_n (n·ẋ) n (zero at rest, so the pressure's set-point is kept). Optionally
the task PD also holds a tool axis a (e.g. a pencil, the tip frame's local ``tool_axis``) along a
world direction d: moment m = K_o (a × d) − D_o ω⊥, τ += J_ωᵀ m, ω⊥ the angular velocity
without its roll about a (a 5-DOF robot cannot control that roll). Joint space:
τ = K_p (q_d − q) + K_d (q̇_d − q̇) [+ feedforward]. Feedforward: ``none``, ``gravity``
(the uncompensated gravity load g(q)) or ``bias`` (h(q, q̇)).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .base import FEEDFORWARD, ControlInput, Controller, TipForceLaw, register

__all__ = ["TaskPD", "JointPD", "KP_TASK", "KD_TASK", "read_tool_axis"]

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
        return TaskPDConfig(kp, kd, axes, r.str("feedforward", "none", choices=FEEDFORWARD), tool_axis, tool_target,
                            r.float("ko", 50.0, lo=0.0, unit="N·m/rad"), r.float("do", 2.0, lo=0.0, unit="N·m·s/rad"),
                            r.float("kd_joint", 0.0, lo=0.0, unit="N·m·s/rad"),
                            r.float("kd_normal", 0.0, lo=0.0, unit="N·s/m"))

    def __init__(self, config: TaskPDConfig, nv: int):
        super().__init__(config, nv)
        self.needs_gravity = config.feedforward == "gravity"
        self.reads_orientation = config.tool_axis is not None  # R_tip, J_ang: for the tool-axis moment only
        a = config.axes
        self._kp = (a.T * np.broadcast_to(config.kp, len(a))) @ a  # Σ kp_i a_i a_iᵀ [N/m]
        self._kd = (a.T * np.broadcast_to(config.kd, len(a))) @ a

    def command(self, inp: ControlInput) -> tuple[np.ndarray, None]:
        cfg = self.config
        tau = np.zeros(self.nv)
        if inp.x_d is not None:
            tau += inp.J.T @ (self._kp @ (inp.x_d - inp.p_tip) + self._kd @ (inp.v_d - inp.v_tip))
        if cfg.tool_axis is not None:
            a = inp.R_tip @ cfg.tool_axis  # current tool direction (world)
            omega = inp.J_ang @ inp.v
            omega_perp = omega - (omega @ a) * a
            tau += inp.J_ang.T @ (cfg.ko * np.cross(a, cfg.tool_target) - cfg.do * omega_perp)
        if cfg.kd_joint:
            tau -= cfg.kd_joint * inp.v
        f = np.zeros(3)
        for contact, (F_d, _) in inp.force_d.items():
            n = inp.normals[contact]
            f -= F_d * n + cfg.kd_normal * (n @ inp.v_tip) * n
        return tau + inp.J.T @ f + _feedforward(inp, cfg.feedforward), None

    def tip_force_law(self) -> TipForceLaw | None:
        cfg = self.config
        if cfg.tool_axis is not None or cfg.kd_normal:  # the tool-axis moment is not affine in the state,
            return None                                 # the normal damping is not in the data law
        return TipForceLaw(self._kp, self._kd, cfg.feedforward, float(cfg.kd_joint))


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
                from ..errors import SceneError

                raise SceneError(f"controller.{name}", f"one gain or {nv} (one per joint)", getattr(config, name))

    def command(self, inp: ControlInput) -> tuple[np.ndarray, None]:
        tau = np.zeros(self.nv)
        if inp.x_d is not None:
            tau += self.config.kp * (inp.x_d - inp.q) + self.config.kd * (inp.v_d - inp.v)
        return tau + _feedforward(inp, self.config.feedforward), None
