"""The controller interface: read the state and measured forces, write joint torques.

A controller never reaches into the integrator. It receives a :class:`ControlInput`
(state, tip kinematics, model terms, references and measured contact forces) and returns
joint torques [N·m or N] and the rates of its own states (integrators), if it has any.
Where a joint has a motor the system turns the torque into a voltage by inverting the
motor model (see :mod:`contactdyn.laws.drives`); a controller with ``outputs = "voltage"``
returns voltages [V] instead.

Measured forces. Deformable contacts give their force as a function of the state. A bond
(model b, rigid contact) or a stick has an unknown force that only the system's linear
solve knows; a controller that reads forces (``uses_forces = True``) must then be affine
in them (τ = τ₀ + B F, ż = ż₀ + D F) and the system folds B into its linear system, so
the force it measures is the exact one at the same instant (no delay, no iteration).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, ClassVar

import numpy as np

from ...errors import SceneError
from ..drive_kinds import DRIVE_KINDS
from ..params import Param, check_declaration, claim_name
from ..sensors import read_sampling

__all__ = ["ControlInput", "Controller", "BindContext", "CONTROLLERS", "register", "read_controller",
           "FEEDFORWARD", "DeclaredConfig", "TABLE_KEYS", "OUTPUTS", "MAX_STATES", "is_count",
           "DEFAULT_KIND"]

FEEDFORWARD = ("none", "gravity", "bias")
DEFAULT_KIND = "task_pd"  #: a controller table's kind where it names none
#: the keys of every controller table besides its kind's own (read_controller; laws.sensors.read_sampling)
TABLE_KEYS = ("kind", "sample_rate", "delay", "hold", "sensor")
OUTPUTS = ("torque", "voltage")  #: what a controller's command gives (``Controller.outputs``)
MAX_STATES = 10_000  #: a controller's own states at most (each is integrated and stored with every output sample)


@dataclass
class ControlInput:
    t: float  #: scene time [s]
    q: np.ndarray  #: joint positions [rad or m]
    v: np.ndarray  #: joint velocities
    H: np.ndarray  #: inertia matrix of the rigid model, reflected rotor inertias included
    h: np.ndarray  #: Coriolis, centrifugal and uncompensated gravity
    gravity: np.ndarray | None  #: uncompensated gravity load g(q), when the controller asked for it
    p_tip: np.ndarray  #: tip position [m]
    v_tip: np.ndarray  #: tip velocity [m/s]
    J: np.ndarray  #: tip Jacobian (3, nv)
    drift: np.ndarray  #: J̇q̇ [m/s²]
    x_d: np.ndarray | None  #: reference position (task [m] or joint), None when the phase has none
    v_d: np.ndarray | None
    a_d: np.ndarray | None
    #: measured contact force [N], > 0 pressing: normal per contact name, tangential chain per "<contact>.t1"
    #: (filled only for a controller that reads forces, ``uses_forces``)
    forces: dict[str, float]
    #: force set-point and its rate [N, N/s]: per contact (normal) or "<contact>.t1" (tangential)
    force_d: dict[str, tuple[float, float]]
    #: unit direction of every set-point key (contact normals, "<contact>.t1" tangents); the robot pushes along −u
    normals: dict[str, np.ndarray]
    z: np.ndarray  #: controller states
    R_tip: np.ndarray | None = None  #: tip frame orientation (3, 3)
    J_ang: np.ndarray | None = None  #: tip angular Jacobian (3, nv)
    drift_ang: np.ndarray | None = None  #: J̇_ω q̇ of the tip frame [rad/s²]
    #: measured generalized contact force on the joints, Σ_c J_cᵀ F_c, friction included [N·m or N];
    #: without forces of constraints on the robot alone (rigid contact or stick on the fixed ground)
    tau_contact: np.ndarray | None = None
    #: per contact: a point of the undeformed surface [m] and its velocity [m/s] (world); per "<contact>.t1":
    #: the tangential chain's anchor (where it is undeformed since the latest touch) and its velocity
    surfaces: dict[str, tuple[np.ndarray, np.ndarray]] = field(default_factory=dict)
    touching: dict[str, bool] = field(default_factory=dict)  #: contact modes

    #: the set-points' inputs as arrays, in the phase's order of set-points (``force_d``'s keys): what a law meant to
    #: compile reads (the controller ABI's buffer has them, not the dictionaries); read-only views of the fields
    SET_POINT_ARRAYS: ClassVar[tuple[str, ...]] = ("force_set", "force_rate", "force_dir", "force_read", "surface_p",
                                                   "surface_v", "touch")

    @property
    def force_set(self) -> np.ndarray:
        """F_d [N] per set-point."""
        return np.array([value for value, _ in self.force_d.values()], dtype=float)

    @property
    def force_rate(self) -> np.ndarray:
        """Ḟ_d [N/s] per set-point."""
        return np.array([rate for _, rate in self.force_d.values()], dtype=float)

    @property
    def force_dir(self) -> np.ndarray:
        """(ns, 3): each set-point's unit direction (``normals``)."""
        return np.array([self.normals[key] for key in self.force_d], dtype=float).reshape(-1, 3)

    @property
    def force_read(self) -> np.ndarray:
        """The measured force [N] of each set-point's key (``forces``: a normal force, a tangential chain's)."""
        return np.array([self.forces[key] for key in self.force_d], dtype=float)

    @property
    def surface_p(self) -> np.ndarray | None:
        """(ns, 3) [m]: each set-point's surface point or tangential anchor (``surfaces``); None without them."""
        return np.array([self.surfaces[key][0] for key in self.force_d], dtype=float).reshape(-1, 3) \
            if self.surfaces else None

    @property
    def surface_v(self) -> np.ndarray | None:
        """(ns, 3) [m/s]: their velocities; None without surfaces."""
        return np.array([self.surfaces[key][1] for key in self.force_d], dtype=float).reshape(-1, 3) \
            if self.surfaces else None

    @property
    def touch(self) -> np.ndarray | None:
        """1.0 where the set-point's contact touches, else 0.0; None without the contact modes."""
        return np.array([float(self.touching[key.partition(".")[0]]) for key in self.force_d]) \
            if self.touching else None

    def replaced(self, **changes) -> ControlInput:
        """A shallow copy with ``changes`` (``dataclasses.replace`` without re-running ``__init__``: the
        force probes call it per right-hand-side call)."""
        new = object.__new__(ControlInput)
        new.__dict__.update(self.__dict__, **changes)
        return new


@dataclass(frozen=True)
class BindContext:
    """What a controller may check or resolve once the system exists (before any run)."""

    scene: Any  #: the Scene
    phase: Any  #: the PhaseSpec this controller runs
    index: int  #: phase index
    joint_names: list[str]
    motorized: np.ndarray  #: bool per joint: the joint's drive takes a voltage (a motor)
    key: str  #: key path of the controller table, for errors (e.g. "phase[1].controller")

    def require_motors(self, key: str, what: str) -> None:
        """A SceneError naming ``key`` unless every joint has a motor (a drive that takes a voltage): ``what`` needs
        one on each."""
        if not self.motorized.all():
            bare = [n for n, m in zip(self.joint_names, self.motorized, strict=True) if not m]
            kinds = " or ".join(name for name, kind in DRIVE_KINDS.items() if kind.has_voltage)
            raise SceneError(key, f"{what} only with a motor on every joint (robot.drive.kind = {kinds})",
                             f"no motor on {bare}", self.scene.file)


@dataclass(frozen=True)
class DeclaredConfig:
    """The config of a controller that declares its parameters (``Controller.params``): its kind and the values,
    read as attributes (``config.stiffness``)."""

    kind: str
    values: tuple[tuple[str, float], ...] = ()

    def __getattr__(self, name: str) -> float:
        if name.startswith("_") or name == "values":  # (unpickling asks before the fields exist)
            raise AttributeError(name)
        for key, value in self.values:
            if key == name:
                return value
        raise AttributeError(f"controller {self.kind!r} declares no parameter {name!r}")


class Controller:
    """Base class: subclasses set ``name``, their parameters (``params``, or a ``read`` of their own) and
    implement :meth:`command`."""

    name: ClassVar[str] = ""
    #: the parameters the scene gives this controller (contactdyn.laws.params): the default :meth:`read` reads them
    params: ClassVar[tuple[Param, ...]] = ()
    n_states: int = 0
    needs_gravity: bool = False
    uses_forces: bool = False  #: reads measured forces (then it must be affine in them)
    outputs: str = "torque"  #: "torque" (generalized forces) or "voltage" (motor voltages [V])
    reads_orientation: bool = True  #: reads R_tip, J_ang and drift_ang (False: the compiled path leaves them None)

    def __init__(self, config: Any, nv: int):
        self.config = config
        self.nv = nv

    @classmethod
    def read(cls, r) -> Any:
        """The controller table into a config: by default the declared ``params`` (a :class:`DeclaredConfig`)."""
        return DeclaredConfig(cls.name, tuple((p.name, p.read(r)) for p in cls.params))

    def bind(self, context: BindContext) -> None:
        """Check the scene and resolve defaults (may set ``n_states``); raise SceneError on misuse."""


    def failure(self, t: float) -> str:
        """Why the law gave no finite command at t [s] (the compiled call found none there): its own words."""
        return f"t = {t:.6g} s: {self.name}: the law gave no finite command at this state"

    def command(self, inp: ControlInput) -> tuple[np.ndarray, np.ndarray | None]:
        """Joint torques and the rates of the controller's states."""
        raise NotImplementedError

    @staticmethod
    def applies_force_setpoints(config: Any) -> bool:
        """Whether this controller, so configured, acts on a phase's ``[[phase.force]]`` set-points."""
        return False


CONTROLLERS: dict[str, type] = {}


def register(cls: type) -> type:
    """Make ``cls`` a controller scenes can name (``kind = cls.name``): a :class:`Controller` whose declared
    parameters are a tuple of :class:`Param` named each once and none like a key of every controller table
    (:data:`TABLE_KEYS`: the table would give one value to both), its ``outputs`` one of :data:`OUTPUTS` (a typo
    would run it as a torque law) and its ``n_states`` a count."""
    check_declaration(cls, "controller", Controller, TABLE_KEYS)
    if cls.outputs not in OUTPUTS:
        raise ValueError(f"controller {cls.name!r}: outputs must be one of {OUTPUTS}, got {cls.outputs!r}")
    if not is_count(cls.n_states):
        raise ValueError(f"controller {cls.name!r}: n_states must be an integer in [0, {MAX_STATES}], got "
                         f"{cls.n_states!r}")
    claim_name(CONTROLLERS, cls, "controller")
    return cls


def is_count(n: object) -> bool:
    """A count of a controller's states: an integer in [0, MAX_STATES], not a bool."""
    return isinstance(n, int | np.integer) and not isinstance(n, bool) and 0 <= n <= MAX_STATES


def read_controller(reader) -> tuple[Any, Any]:
    """Validate a controller table into (its kind's config, its sampling or None): the sampling keys
    (``sample_rate``, ``delay``, ``sensor``: :func:`~contactdyn.laws.sensors.read_sampling`) are read
    first, for every kind, then the kind's ``read`` does its own keys."""
    kind = reader.str("kind", DEFAULT_KIND, choices=sorted(CONTROLLERS))
    sampling = read_sampling(reader)
    config = CONTROLLERS[kind].read(reader)
    reader.finish()
    return config, sampling
