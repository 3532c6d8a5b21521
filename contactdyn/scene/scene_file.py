"""Scenes: a TOML file validated into typed, frozen objects.

A scene composes a robot, environment bodies (a fixed ground is always there; active
bodies such as a cart, or a box on two slides, are named under ``[body.<name>]``), contact interfaces
(``[contact.<name>]``), a controller with task phases (``[[phase]]``) and solver
settings. Every value is checked; an error names the file, the key path, what was
expected and what was found. Overrides by key path (``contact.tip.normal.k=1e4``) apply
to the raw document before validation, from Python or the command line.
"""

from __future__ import annotations

import copy
import math
import re
import tomllib
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import RobotError, SceneError, close_matches
from ..laws.drives import DriveTable, read_drive_table
from ..laws.elements import STAGE_LAWS, ChainSpec, Element, Mass, Stage
from ..laws.friction_laws import FRICTION_LAWS, FrictionSpec
from ..laws.params import read_params
from ..laws.trajectory import PROFILES, RAMP_KINDS, Move, Ramp
from .budget import check_budget
from .reader import MAX_DEPTH, Reader, check_depth, read_toml

__all__ = [
    "Scene", "RobotSpec", "JointDynamicsSpec", "BodySpec", "BodyCoordinate", "ContactSpec", "ChainSpec", "Stage",
    "Mass", "FrictionSpec",
    "PhaseSpec", "ReferenceSpec", "SolverSpec", "load_scene", "parse_scene", "apply_overrides",
    "parse_override", "sims_dir", "scene_dirs", "find_scene",
]

NORMAL_MODELS = ("rigid", "a", "b", "c", "chain")
TANGENT_MODELS = ("free", "friction", "chain")
@dataclass(frozen=True)
class ContactSpec:
    name: str
    frame: str  #: robot frame whose origin touches (default: the robot's tip frame, ``robot.tip``), or a body
    #: whose point ``frame_point`` touches
    body: str  #: "ground" or the name of an active body
    point: np.ndarray  #: [m] a point of the undeformed surface (world, body at coordinate 0)
    normal: np.ndarray  #: unit outward surface normal (points from environment to robot)
    tangents: np.ndarray  #: (k, 3) unit tangential directions, k = 0, 1 or 2
    normal_chain: ChainSpec
    tangent_model: str  #: "free", "friction" or "chain"
    friction: FrictionSpec | None
    tangent_chain: ChainSpec | None  #: chain used along each tangent (bonded at touch)
    bonded: bool  #: never separates (e.g. benchmark B1)
    #: [m] when ``frame`` names a body: its touching point (world, at the body's coordinates 0); else None
    frame_point: np.ndarray | None = None
    #: with ``body = "robot"``: the robot frame carrying the surface, with ``body`` an articulated body: that body's
    #: frame (``point``, ``normal`` and ``tangents`` then in that frame's own coordinates: the surface moves and turns
    #: with it); else None
    surface_frame: str | None = None
    #: with ``frame`` an articulated body: the frame of that body (a link's, or any URDF frame) in whose coordinates
    #: ``frame_point`` is given (the point moves and turns with it); else None
    body_frame: str | None = None


@dataclass(frozen=True)
class BodyCoordinate:
    """One coordinate of a body: a direction it translates along."""

    joint: str  #: its name: the URDF's joint ("" for a body given by mass and axis)
    axis: np.ndarray  #: unit direction of travel (world)
    mass: float  #: [kg] the mass moving along it
    position0: float  #: [m] initial value
    velocity0: float  #: [m/s] initial rate


@dataclass(frozen=True)
class BodySpec:
    """An active environment body translating along one axis (a cart: its mass and axis given, or read off a URDF
    with one prismatic joint), or along two or three orthogonal axes (a URDF whose joints are all prismatic):
    one coordinate per axis (:mod:`contactdyn.robot.body`); or an articulated body (a URDF with revolute joints:
    one coordinate per joint, its angle [rad] or length [m]; its masses and axes then only informative)."""

    name: str
    mass: float  #: [kg] the body's mass (all its links)
    coordinates: tuple[BodyCoordinate, ...]  #: one per axis, in the URDF's joint order
    servo_velocity: float | None  #: velocity servo set-point [m/s], None: no drive force (one coordinate only)
    servo_gain: float  #: [N·s/m], F = gain (v_ref − v), realised by the body's drive
    drive: DriveTable = field(default_factory=DriveTable)  #: validated drive table (see contactdyn.laws.drives)
    urdf: str | None = None  #: the URDF the mass and axes come from (its visuals drawn by the viewer), or None
    articulated: bool = False  #: a URDF with revolute joints: its dynamics its own Pinocchio model's
    #: an articulated body whose root link moves freely: its first six coordinates x, y, z [m], yaw, pitch, roll
    #: [rad] (contactdyn.robot.body)
    free: bool = False

    @property
    def axis(self) -> np.ndarray:
        """The unit direction of travel of a body with one coordinate (the first one's otherwise)."""
        return self.coordinates[0].axis

    @property
    def axes(self) -> np.ndarray:
        """(k, 3) the coordinates' unit directions (world)."""
        return np.array([c.axis for c in self.coordinates])


@dataclass(frozen=True)
class JointDynamicsSpec:
    """A joint's damping and dry friction as a scene gives them (``[robot.joint.<joint>]``)."""

    damping: float  #: b [N·m·s/rad or N·s/m]
    static: float  #: τ_s, the static (break-away) limit [N·m or N]
    kinetic: float  #: τ_k ≤ τ_s, the sliding friction [N·m or N]


@dataclass(frozen=True)
class RobotSpec:
    source: str  #: URDF path, name in urdf/, or example-robot-data name
    tip: str
    active_joints: tuple[str, ...] | None
    locked: dict[str, float]
    gravity: np.ndarray  #: [m/s²]
    gravity_compensation: float  #: fraction in [0, 1]
    q0: np.ndarray | None  #: [rad or m]
    v0: np.ndarray | None  #: [rad/s or m/s]
    tip0: np.ndarray | None  #: [m] initial tip position, solved by inverse kinematics from q0/q_seed
    q_seed: np.ndarray | None  #: a hint for the start posture (ignored when its size is not the robot's)
    drive: DriveTable = field(default_factory=DriveTable)  #: validated drive table (see contactdyn.laws.drives)
    inertia: str = "check"  #: what a link failing the inertia checks does: "check", "repair", "trust"
    joint_limits: str = "enforce"  #: "enforce" position limits as unilateral constraints, or "ignore"
    #: "urdf": each joint's damping and dry friction from the URDF's <dynamics>; "ignore": none from the URDF
    joint_friction: str = "urdf"
    #: per joint name, the scene's own damping and friction (replacing the URDF's; see contactdyn.model.joint_friction)
    joints: dict[str, JointDynamicsSpec] = field(default_factory=dict)


@dataclass(frozen=True)
class ReferenceSpec:
    space: str  #: "task" (tip position) or "joint"
    start: np.ndarray | None  #: None: continue from the previous phase, or from the state
    moves: tuple[Move, ...]
    #: active body the reference rides on ("ground": the world). Then x_d(t) = o(t) + start + Σ moves with
    #: o = axis · (body coordinate) the body's origin, and its velocity and acceleration join v_d and a_d
    #: (the paper's task coordinates relative to the cart, eq. 5); ``start`` is relative to o
    body: str = "ground"


@dataclass(frozen=True)
class ForceSpec:
    contact: str
    ramp: Ramp
    #: "n" presses along the normal; "t1"/"t2" push along −(that tangent), i.e. the force set-point
    #: compresses the tangential chain (case 1's horizontal force F1)
    direction: str = "n"

    @property
    def key(self) -> str:
        """Set-point name: the contact for the normal, ``<contact>.t1`` for a tangent."""
        return self.contact if self.direction == "n" else f"{self.contact}.{self.direction}"


@dataclass(frozen=True)
class PhaseSpec:
    name: str
    until: float | str  #: end time [s] from the scene start, or "touch:<contact>"
    controller: Any  #: a controller config (see contactdyn.laws.controllers)
    reference: ReferenceSpec | None
    forces: tuple[ForceSpec, ...]
    #: the controller's sample rate, delay and sensors (contactdyn.laws.controllers.sampled.Sampling); None: continuous
    sampling: Any = None
    #: the key path errors in its controller name: the phase's own table's, else the scene's ``controller``
    controller_key: str = "controller"


MAX_EVENTS = 1_000_000  #: solver.max_events at most (each event is kept in the run's log and JSON)


@dataclass(frozen=True)
class SolverSpec:
    method: str = "DOP853C"  #: DOP853 on scipy's compiled core (contactdyn.numerics.dop853); "DOP853": solve_ivp's
    rtol: float = 1e-8
    atol: float = 1e-10
    max_step: float = math.inf  #: [s]
    output_rate: float = 1000.0  #: [Hz] samples in the Result
    record_energy: bool = False  #: integrate drive work and damper dissipation
    max_events: int = 10000  #: guard against event storms (whole run)
    #: integration steps a run may take per simulated second (contactdyn.hybrid.progress: plus STEPS_BASE)
    steps_per_second: float = 20_000.0
    storm_window: float = 1e-9  #: [s] events closer than this count towards a storm
    storm_count: int = 50  #: that many events inside the window stop the run
    stabilization: float = 20.0  #: [1/s] Baumgarte rate ω of bonds, rigid contacts and sticks (0: none)
    #: [m/s] slip-speed band of the stick/slip guard: a slide stops when |v_t| falls to it
    stick_velocity: float = 1e-9


@dataclass(frozen=True)
class Scene:
    name: str
    description: str
    duration: float  #: [s]
    robot: RobotSpec
    bodies: dict[str, BodySpec]
    contacts: dict[str, ContactSpec]
    phases: tuple[PhaseSpec, ...]
    solver: SolverSpec
    file: str | None
    document: dict[str, Any]  #: the raw document after overrides (saved with results)
    imports: tuple[str, ...] = ()  #: the user's modules this scene imported (contactdyn.scene.user_laws)


# ---- locating scenes ---------------------------------------------------------------------
def sims_dir() -> Path:
    """The project's ``sims/`` folder, from a checkout or an installed wheel."""
    package = Path(__file__).resolve().parents[1]  # contactdyn/
    packaged = package / "data" / "sims"
    return packaged if packaged.is_dir() else package.parent / "sims"


def scene_dirs() -> list[Path]:
    """Where scene names are looked up, in order: ``./sims`` of the working directory, then the installed ``sims/``."""
    local = Path.cwd() / "sims"
    dirs = [local] if local.is_dir() else []
    return dirs + [d for d in (sims_dir(),) if not dirs or d.resolve() != local.resolve()]


LISTED_SCENES = 12  #: an unknown scene name's error lists the scenes up to this many (else: where to list them)


def find_scene(name: str | Path) -> Path:
    """A scene path, or a scene name (with or without ``.toml``) in :func:`scene_dirs`, the first found."""
    path = Path(name)
    if path.is_file():
        return path
    for folder in scene_dirs():
        for candidate in (folder / f"{name}.toml", folder / str(name)):
            if candidate.is_file():
                return candidate
    if path.suffix == ".toml" or len(path.parts) > 1:  # a path, not a name: say it is not there
        what = "a directory" if path.is_dir() else "no such file"
        raise SceneError("scene", f"a scene file (.toml) at {str(path.resolve())!r}", f"{what}: {str(name)!r}")
    known = sorted({p.stem for folder in scene_dirs() for p in folder.glob("*.toml")})
    close = close_matches(name, known)
    hint = f"; did you mean {', '.join(close)}?" if close else ""
    listed = ", ".join(known) if len(known) <= LISTED_SCENES else f"{len(known)} of them: `contactdyn list scenes`"
    raise SceneError("scene", f"a scene file or a scene's name ({listed}){hint}", str(name))


def urdf_beside_scene(source: str, file: str | None) -> str:
    """A relative URDF path in a scene names a file beside the scene (not in the working directory)."""
    if file is None or Path(source).is_absolute():
        return source
    beside = Path(file).parent / source
    if beside.is_file() or "/" in source or "\\" in source:
        return str(beside.resolve())
    return source  # a name in urdf/ or of example-robot-data


# ---- overrides ---------------------------------------------------------------------------
def parse_override(text: str) -> tuple[str, Any]:
    """``key.path=value`` with the value read as TOML (``1e4``, ``true``, ``[1, 2]``) or a string."""
    if "=" not in text:
        raise SceneError("--set", "key.path=value", text)
    key, value = (part.strip() for part in text.split("=", 1))
    if "\n" in value or "\r" in value:  # more TOML after the value would be read and dropped
        raise SceneError(f"--set {key}", "one value on one line (one --set per key)", value)
    try:
        parsed = tomllib.loads(f"v = {value}")["v"]
    except tomllib.TOMLDecodeError:
        parsed = value
    except RecursionError:
        raise SceneError(f"--set {key}", f"a value nested at most {MAX_DEPTH} deep", "deeper") from None
    return key, parsed


NAMED_TABLES = ("contact", "body")  #: top-level tables of named tables: an override naming a new one adds it


def _new_name(key: str, name: str, tables: dict, file: str | None) -> None:
    """An override that would add the named table ``name`` where one of the scene's is that close: a typo, named."""
    close = close_matches(name, list(tables), n=1)
    if close:
        raise SceneError(key, f"a name the scene has ({', '.join(tables)}): did you mean {close[0]!r}? (an override "
                         f"that names a new one adds it)", name, file)


def apply_overrides(document: dict[str, Any], overrides: dict[str, Any], file: str | None = None) -> dict[str, Any]:
    """A copy of ``document`` with each ``key.path`` set; array items as ``phase.1.until``."""
    if not isinstance(overrides, dict):
        raise SceneError("<overrides>", 'a dict of key paths and values, like {"controller.kp": 500.0}',
                         overrides, file)
    doc = copy.deepcopy(document)
    for key, value in overrides.items():
        if not isinstance(key, str):
            raise SceneError("<overrides>", 'key paths as strings, like "controller.kp"', key, file)
        indexed = re.search(r"\[(\d+)\]", key)
        if indexed:  # phase[1].until: the array's item is a path part of its own
            raise SceneError(key, f"an array item as a path part of its own, e.g. "
                             f"{key[:indexed.start()]}.{indexed.group(1)}{key[indexed.end():]}", indexed.group(0), file)
        parts = key.split(".")
        node: Any = doc
        for i, part in enumerate(parts[:-1]):
            here = ".".join(parts[: i + 1])
            if isinstance(node, list):
                if not part.isdigit() or int(part) >= len(node):
                    raise SceneError(here, f"an index < {len(node)}", part, file)
                node = node[int(part)]
            elif isinstance(node, dict):
                if i == 1 and parts[0] in NAMED_TABLES and part not in node:
                    _new_name(here, part, node, file)
                node = node.setdefault(part, {})
            else:
                raise SceneError(here, "a table", node, file)
        last = parts[-1]
        if isinstance(node, list):
            if not last.isdigit() or int(last) >= len(node):
                raise SceneError(key, f"an index < {len(node)}", last, file)
            node[int(last)] = value
        elif isinstance(node, dict):
            node[last] = value
        else:
            raise SceneError(key, "a table to set a key in", node, file)
    return doc


# ---- loading -----------------------------------------------------------------------------
def load_scene(path: str | Path, overrides: dict[str, Any] | None = None) -> Scene:
    """Read, override and validate a scene file (a path or a name in ``sims/``)."""
    path = find_scene(path)
    return parse_scene(read_toml(path), overrides, file=str(path))


def parse_scene(document: dict[str, Any], overrides: dict[str, Any] | None = None, file: str | None = None) -> Scene:
    """Validate a scene document (a dict as TOML gives it)."""
    check_depth([document, overrides], "<document>", file)
    document = apply_overrides(document, overrides or {}, file)
    top = Reader(document, "", file)
    imports = _read_imports(top, file)  # first: the user's modules register the laws the rest may name
    name = top.str("name", Path(file).stem if file else "scene")
    description = top.str("description", "")
    duration = top.float("duration", lo=0.0, lo_open=True, unit="s")
    robot = _read_robot(top.sub("robot"))
    bodies = {n: _read_body(n, r) for n, r in top.named_tables("body").items()}
    if "ground" in bodies:
        raise top.error("body.ground", "a body name other than 'ground' (the fixed ground always exists)", "ground")
    contacts = {n: _read_contact(n, r, bodies, robot.tip) for n, r in top.named_tables("contact").items()}
    solver = _read_solver(top.sub("solver", {}))
    default_controller = top.sub("controller", {})
    phases = tuple(_read_phase(r, default_controller, contacts, duration, bodies) for r in top.tables("phase"))
    if not phases:
        phases = (_read_phase(Reader({"name": "main"}, "phase[0]", file), default_controller, contacts, duration,
                              bodies),)
    _check_phase_order(top, phases)
    top.finish()
    scene = Scene(name, description, duration, robot, bodies, contacts, phases, solver, file, document, imports)
    check_budget(scene)
    return scene


def _read_imports(top: Reader, file: str | None) -> tuple[str, ...]:
    """``imports``: the user's modules of laws, imported now (:mod:`contactdyn.scene.user_laws`)."""
    from .user_laws import import_scene_modules

    top._note("imports", "list", [])
    return tuple(import_scene_modules(top.raw("imports", []), file))


def _check_phase_order(top: Reader, phases: tuple[PhaseSpec, ...]) -> None:
    """Timed phase ends (``until`` [s] from the scene start) must not decrease: a phase cannot end before an
    earlier one did (it would end the moment it starts, unnoticed)."""
    last, where = -math.inf, ""
    for i, p in enumerate(phases[:-1]):  # (the last phase's until is the duration by default)
        if isinstance(p.until, float):
            if p.until < last:
                raise top.error(f"phase[{i}].until", f"a time no earlier than {where}'s ({last:g} s): phase ends "
                                "do not decrease", p.until)
            last, where = p.until, f"phase[{i}].until"


def _read_robot(r: Reader) -> RobotSpec:
    active = r.raw("active_joints", None)
    if active is not None and (not isinstance(active, list) or not active or not all(isinstance(a, str)
                                                                                   for a in active)):
        raise r.error("active_joints", "a list of joint names (at least one; leave the key out for the tip's chain)",
                      active)
    locked_r = r.sub("locked", {})
    locked = {k: locked_r.float(k, unit="rad or m") for k in locked_r.data}
    q0 = r.vector("q0", None) if r.has("q0") else None
    spec = RobotSpec(
        source=urdf_beside_scene(r.str("urdf"), r.file),
        tip=r.str("tip", "tip"),
        active_joints=tuple(active) if active is not None else None,
        locked=locked,
        gravity=r.vector("gravity", [0.0, 0.0, -9.81], size=3, unit="m/s²"),
        gravity_compensation=r.float("gravity_compensation", 0.0, lo=0.0, hi=1.0),
        q0=q0,
        v0=r.vector("v0", None) if r.has("v0") else None,
        tip0=r.vector("tip0", None, size=3, unit="m") if r.has("tip0") else None,
        q_seed=r.vector("q_seed", None) if r.has("q_seed") else None,
        drive=read_drive_table(r.sub("drive", {}), per_joint=True),
        inertia=r.str("inertia", "check", choices=["check", "repair", "trust"]),
        joint_limits=r.str("joint_limits", "enforce", choices=["enforce", "ignore"]),
        joint_friction=r.str("joint_friction", "urdf", choices=["urdf", "ignore"]),
        joints={name: _read_joint_dynamics(j) for name, j in r.named_tables("joint").items()},
    )
    r.finish()
    return spec


def _read_joint_dynamics(r: Reader) -> JointDynamicsSpec:
    """``[robot.joint.<joint>]``: damping, and ``friction`` (static = kinetic) or ``friction_static`` with
    ``friction_kinetic`` (≤ static; default: the static value). Keys not given are 0."""
    damping = r.float("damping", 0.0, lo=0.0, unit="N·m·s/rad or N·s/m")
    if r.has("friction") and (r.has("friction_static") or r.has("friction_kinetic")):
        raise r.error("friction", "friction alone (static = kinetic) or friction_static with friction_kinetic, "
                      "not both", r.data["friction"])
    if r.has("friction_kinetic") and not r.has("friction_static"):
        raise r.error("friction_static", "a static limit with friction_kinetic (kinetic <= static)", "nothing")
    static = r.float("friction", 0.0, lo=0.0, unit="N·m or N") if r.has("friction") else \
        r.float("friction_static", 0.0, lo=0.0, unit="N·m or N")
    kinetic = static if not r.has("friction_kinetic") else r.float("friction_kinetic", lo=0.0, unit="N·m or N")
    if kinetic > static:
        raise r.error("friction_kinetic", f"a kinetic friction <= friction_static ({static:g} N·m or N)", kinetic)
    r.finish()
    return JointDynamicsSpec(damping, static, kinetic)


def _read_body(name: str, r: Reader) -> BodySpec:
    servo = r.sub("servo", {})
    urdf = urdf_beside_scene(r.str("urdf"), r.file) if r.has("urdf") else None
    articulated = False
    free = r.bool("free", False) if urdf is not None or r.has("free") else False
    if free and urdf is None:
        raise r.error("free", "free = true beside urdf (a free body's links come from its URDF)", True)
    if urdf is not None:
        mass, joints, articulated = _urdf_body(r, urdf, free)
    else:
        mass = r.float("mass", lo=0.0, lo_open=True, unit="kg")
        joints = [("", r.vector("axis", [1.0, 0.0, 0.0], size=3, unit_norm=True), mass)]
    k = len(joints)
    unit = "rad or m" if articulated else "m"
    if k == 1:
        p0, v0 = [r.float("position0", 0.0, unit=unit)], [r.float("velocity0", 0.0, unit=f"{unit}/s")]
    else:  # one value per coordinate
        p0 = r.vector("position0", np.zeros(k), size=k, unit=unit).tolist()
        v0 = r.vector("velocity0", np.zeros(k), size=k, unit=f"{unit}/s").tolist()
    if k > 1 or articulated:
        for key in ("servo", "drive"):
            if r.has(key):
                what = "a free body" if free else "a body with revolute joints" if articulated else \
                    f"a body with {k} coordinates"
                raise r.error(key, f"no {key} on {what} (a drive acts on a one-coordinate translating body)",
                              r.raw(key))
    spec = BodySpec(
        name=name,
        mass=mass,
        coordinates=tuple(BodyCoordinate(j, axis, m, p, v) for (j, axis, m), p, v in zip(joints, p0, v0,
                                                                                          strict=True)),
        servo_velocity=servo.float("velocity", None, unit="m/s") if servo.has("velocity") else None,
        servo_gain=servo.float("gain", 1e3, lo=0.0, unit="N·s/m"),
        drive=read_drive_table(r.sub("drive", {}), per_joint=False),
        urdf=urdf,
        articulated=articulated,
        free=free,
    )
    servo.finish()
    r.finish()
    return spec


def _urdf_body(r: Reader, urdf: str, free: bool = False) -> tuple[float, list[tuple[str, np.ndarray, float]], bool]:
    """(mass [kg], per joint (name, unit axis, the mass moving along it [kg]), articulated) of a body read off its
    URDF (``urdf``; then no ``mass`` or ``axis`` of its own; ``free``: its root link moves freely)."""
    from ..robot.body import load_body  # (Pinocchio: imported for a scene that has such a body only)

    for key in ("mass", "axis"):
        if r.has(key):
            raise r.error(key, "no mass or axis beside urdf (the URDF gives them)", r.raw(key))
    try:
        body = load_body(urdf, free)
    except RobotError as exc:
        raise r.error("urdf", "a loadable URDF of one to three orthogonal prismatic joints, or of revolute (and "
                      "prismatic) joints fixed in the world (or free = true: its root link free)", exc) from None
    return body.mass, list(zip(body.joints, body.axes, body.masses, strict=True)), body.articulated


def _read_elements(r: Reader, name: str) -> tuple[Element, ...]:
    raw = r.raw(name, [])
    if not isinstance(raw, list):
        raise r.error(name, "a list of elements like {k = 1e4, b = 10} or {m = 10}", raw)
    out: list[Element] = []
    for i, item in enumerate(raw):
        e = Reader(item, f"{r.key(name)}[{i}]", r.file)
        if e.has("m"):
            out.append(Mass(e.float("m", lo=0.0, lo_open=True, unit="kg")))
        else:
            out.append(_read_stage(e))
        e.finish()
    return tuple(out)


def _read_stage(e: Reader, k: str = "k", b: str = "b") -> Stage:
    """A stage: its k and b (under the names given), its law, and the parameters the law declares."""
    stiffness = e.float(k, lo=0.0, lo_open=True, unit="N/m")
    damping = e.float(b, 0.0, lo=0.0, unit="N·s/m")
    saved = e.variant  # the law's own keys are documented under "law = ..."; the table's others are not
    law = e.str("law", "linear", choices=STAGE_LAWS)
    params = read_params(e, STAGE_LAWS[law].params)
    e.variant = saved
    return Stage(k=stiffness, b=damping, law=law, params=params)


def _read_chain(r: Reader) -> ChainSpec:
    """A direction's model: rigid, Part I's (a), (b), (c), or an explicit chain."""
    model = r.str("model", "chain" if (r.has("environment") or r.has("robot")) else "rigid", choices=NORMAL_MODELS)
    if model == "rigid":
        return ChainSpec()
    if model == "c":  # massless Kelvin–Voigt
        return ChainSpec(environment=(_read_stage(r),))
    if model == "b":  # ground —[k, b]— m′, struck by the tip
        return ChainSpec(environment=(_read_stage(r), Mass(r.float("m", lo=0.0, lo_open=True, unit="kg"))))
    if model == "a":  # ground —[k″, b″]— m′ —[k′, b′]— tip
        inner = _read_stage(r, "k_int", "b_int")
        mass = Mass(r.float("m", lo=0.0, lo_open=True, unit="kg"))
        return ChainSpec(environment=(inner, mass, _read_stage(r, "k_ext", "b_ext")))
    chain = ChainSpec(_read_elements(r, "environment"), _read_elements(r, "robot"))
    return chain


def _read_contact(name: str, r: Reader, bodies: dict[str, BodySpec], tip: str = "tip") -> ContactSpec:
    body = r.str("body", "ground", choices=["ground", "robot", *bodies])
    normal_r = r.sub("normal")
    normal = normal_r.vector("direction", size=3, unit_norm=True)
    normal_chain = _read_chain(normal_r)
    normal_r.finish()
    tangent_r = r.sub("tangent", {})
    model = tangent_r.str("model", "free", choices=TANGENT_MODELS)
    if tangent_r.has("directions"):
        raw = tangent_r.raw("directions")
        if not isinstance(raw, list) or not 1 <= len(raw) <= 2:
            raise tangent_r.error("directions", "a list of 1 or 2 direction vectors", raw)
        tangents = np.array([Reader({str(i): d}, tangent_r.key("directions"), r.file).vector(str(i), size=3,
                                                                                             unit_norm=True)
                             for i, d in enumerate(raw)])
        if np.any(np.abs(tangents @ normal) > 1e-9) or (len(tangents) == 2 and abs(tangents[0] @ tangents[1]) > 1e-9):
            raise tangent_r.error("directions", "directions orthogonal to the normal and to each other",
                                  raw)
    elif model != "free":
        raise tangent_r.error("directions", "1 or 2 tangential directions (required with friction or chain)", None)
    else:
        tangents = np.zeros((0, 3))
    friction = tangent_chain = None
    if model == "friction":
        saved = tangent_r.variant
        friction = FRICTION_LAWS[tangent_r.str("law", "coulomb", choices=FRICTION_LAWS)].read(tangent_r)
        tangent_r.variant = saved
    elif model == "chain":
        tangent_chain = _read_chain(tangent_r)
        if tangent_chain.rigid:
            raise tangent_r.error("environment", "a deformation chain (a rigid tangential bond is a stick)", [])
    tangent_r.finish()
    frame = r.str("frame", tip)  # default: the robot's tip frame (one line swaps robots)
    frame_point = None
    if r.has("frame_point"):  # a body's point touches
        if frame not in bodies:
            raise r.error("frame", f"a body beside frame_point (frame_point places a body's touching point; "
                          f"bodies: {list(bodies)})", frame)
        if frame == body:
            raise r.error("frame", f"a body other than the surface's ({body!r})", frame)
        frame_point = r.vector("frame_point", size=3, unit="m")
    body_frame = _body_frame(r, frame, bodies)
    surface_frame = _surface_frame(r, body, bodies)
    spec = ContactSpec(
        name=name,
        frame=frame,
        frame_point=frame_point,
        body_frame=body_frame,
        body=body,
        point=r.vector("point", size=3, unit="m"),
        normal=normal,
        tangents=tangents,
        normal_chain=normal_chain,
        tangent_model=model,
        friction=friction,
        tangent_chain=tangent_chain,
        bonded=r.bool("bonded", False),
        surface_frame=surface_frame,
    )
    r.finish()
    return spec


def _surface_frame(r: Reader, body: str, bodies: dict[str, BodySpec]) -> str | None:
    """The frame carrying the surface: a robot frame (``body = "robot"``) or a frame of an articulated body (required
    there); None for the ground or a translating body. A chain there runs along its turning directions, its masses
    riding it (contact.RidingMass)."""
    articulated = body in bodies and bodies[body].articulated
    if body != "robot" and not articulated:
        if r.has("surface_frame"):
            raise r.error("surface_frame", 'a surface carried by the robot (body = "robot") or by a body with '
                          "revolute joints only", r.raw("surface_frame"))
        return None
    owner = "the robot" if body == "robot" else f"body {body!r}"
    if not r.has("surface_frame"):
        raise r.error("surface_frame", f"the frame of {owner} carrying the surface (required with body = {body!r})",
                      None)
    return r.str("surface_frame")


def _body_frame(r: Reader, frame: str, bodies: dict[str, BodySpec]) -> str | None:
    """The frame of an articulated touching body in whose coordinates ``frame_point`` is given (required there;
    None otherwise)."""
    articulated = r.has("frame_point") and frame in bodies and bodies[frame].articulated
    if not articulated:
        if r.has("body_frame"):
            raise r.error("body_frame", "a frame of a body with revolute joints whose point touches (frame = "
                          "<body>, frame_point)", r.raw("body_frame"))
        return None
    if not r.has("body_frame"):
        raise r.error("body_frame", f"the frame of body {frame!r} in whose coordinates frame_point is given "
                      "(required: the body turns)", None)
    return r.str("body_frame")


def _read_solver(r: Reader) -> SolverSpec:
    from ..numerics.integrators import METHODS

    spec = SolverSpec(
        method=r.str("method", SolverSpec.method, choices=METHODS),
        rtol=r.float("rtol", SolverSpec.rtol, lo=1e-14, hi=1e-1),
        atol=r.float("atol", SolverSpec.atol, lo=1e-16, hi=1.0),
        max_step=r.float("max_step", math.inf, lo=0.0, lo_open=True, unit="s"),
        output_rate=r.float("output_rate", SolverSpec.output_rate, lo=0.0, lo_open=True, hi=1e7, unit="Hz"),
        record_energy=r.bool("record_energy", False),
        max_events=r.int("max_events", SolverSpec.max_events, lo=1, hi=MAX_EVENTS),
        steps_per_second=r.float("steps_per_second", SolverSpec.steps_per_second, lo=1.0, hi=1e9, unit="1/s"),
        storm_window=r.float("storm_window", SolverSpec.storm_window, lo=0.0, unit="s"),
        storm_count=r.int("storm_count", SolverSpec.storm_count, lo=2),
        stabilization=r.float("stabilization", SolverSpec.stabilization, lo=0.0, unit="1/s"),
        stick_velocity=r.float("stick_velocity", SolverSpec.stick_velocity, lo=0.0, lo_open=True, hi=1.0, unit="m/s"),
    )
    r.finish()
    return spec


def _read_phase(r: Reader, default_controller: Reader, contacts: dict[str, ContactSpec], duration: float,
                bodies: dict[str, BodySpec] | None = None) -> PhaseSpec:
    from ..laws.controllers.base import DEFAULT_KIND, read_controller
    from ..laws.failures import checked_config, naming_laws  # (the laws' layer cannot import them: a cycle)

    name = r.str("name", "main")
    until_raw = r.raw("until", duration)
    if isinstance(until_raw, str):
        kind, _, target = until_raw.partition(":")
        if kind != "touch" or target not in contacts:
            raise r.error("until", f"a time [s] or 'touch:<contact>' with a contact in {sorted(contacts)}", until_raw)
        until: float | str = until_raw
    else:
        until = r.float("until", duration, lo=0.0, unit="s")
    merged, inherited = _phase_controller(r.raw("controller", {}), default_controller.data)
    where = r.key("controller") if "controller" in r.data else default_controller.path  # (the file's table)
    with naming_laws(), _named_where_written(inherited, where, default_controller.path):  # (a user's read raising:
        controller, sampling = read_controller(Reader(merged, where, r.file))  # its LawError)
    controller = checked_config(merged.get("kind", DEFAULT_KIND), controller)
    reference = _read_reference(r.sub("reference"), bodies or {}) if r.has("reference") else None
    forces = tuple(_read_force(f, contacts) for f in r.tables("force"))
    r.finish()
    return PhaseSpec(name, until, controller, reference, forces, sampling, where)


def _phase_controller(own: object, top: dict) -> tuple[object, set[str]]:
    """A phase's controller table (``own``, its ``[phase.controller]``) over the scene's (``top``, ``[controller]``)
    and the keys it takes from the scene's. A phase that names another kind than the scene's takes only the keys of
    every controller table (``sample_rate``, ``delay``, ``hold``, ``sensor``: the sampling), not the other kind's
    parameters (a task PD's ``axes`` are no joint PD's; its ``kp`` is in N/m, not N·m/rad)."""
    from ..laws.controllers.base import DEFAULT_KIND, TABLE_KEYS  # (as _read_phase's)

    if not isinstance(own, dict):
        return own, set()  # (the reader says it is no table)
    other = "kind" in own and own["kind"] != top.get("kind", DEFAULT_KIND)
    inherited = {k for k in top if k not in own and (not other or k in TABLE_KEYS)}
    return {**{k: top[k] for k in inherited}, **own}, inherited


@contextmanager
def _named_where_written(inherited: set[str], where: str, top: str):
    """Inside: an error in a key the phase's controller table (at ``where``) took from the scene's (at ``top``) names
    the key where the file has it, ``controller.kp (inherited by phase[1].controller)``."""
    try:
        yield
    except SceneError as exc:
        name = exc.key[len(where) + 1:].split(".")[0].split("[")[0] if exc.key.startswith(where + ".") else None
        if name not in inherited or where == top:
            raise
        key = f"{top}.{exc.key[len(where) + 1:]} (inherited by {where})"
        exc.args = (exc.args[0].replace(exc.key, key, 1),)
        exc.key = key
        raise


def _read_reference(r: Reader, bodies: dict[str, BodySpec]) -> ReferenceSpec:
    space = r.str("space", "task", choices=["task", "joint"])
    body = r.str("body", "ground", choices=["ground", *bodies])
    if body != "ground" and space != "task":
        raise r.error("body", "'ground' for a joint-space reference (only a task reference rides on a body)", body)
    if body != "ground" and bodies[body].articulated:
        what = "a free body" if bodies[body].free else "a body with revolute joints"
        raise r.error("body", f"'ground' or a translating body (a reference does not ride on {what} yet)", body)
    if body != "ground" and len(bodies[body].coordinates) > 1:
        raise r.error("body", "'ground' or a body with one coordinate (a reference rides along one axis)", body)
    start = r.vector("start", None) if r.has("start") else None
    moves = []
    for m in r.tables("moves"):
        kind = m.str("kind", "trapezoid", choices=PROFILES)
        duration = m.float("duration", lo=0.0, lo_open=True, unit="s")
        normal, turns = None, 1.0
        if kind == "velocity_ramp":
            delta = m.vector("velocity", unit="m/s or rad/s") * duration
        elif kind == "circle":
            delta = m.vector("center", size=3, unit="m")
            normal = m.vector("normal", [0.0, 0.0, 1.0], size=3, unit_norm=True)
            turns = m.float("turns", 1.0)
        else:
            delta = m.vector("delta", unit="m or rad")
        moves.append(Move(delta, m.float("start", 0.0, lo=0.0, unit="s"), duration, kind,
                          m.float("accel_fraction", 0.1, lo=0.0, lo_open=True, hi=0.5), normal, turns))
        m.finish()
    sizes = {len(mv.delta) for mv in moves} | ({len(start)} if start is not None else set())
    if len(sizes) > 1:
        raise r.error("moves", "start and every move of the same dimension", sorted(sizes))
    if body != "ground" and sizes - {3}:
        raise r.error("moves", "3-vectors (a task reference on a body)", sorted(sizes))
    r.finish()
    return ReferenceSpec(space, start, tuple(moves), body)


def _read_force(r: Reader, contacts: dict[str, ContactSpec]) -> ForceSpec:
    contact = r.str("contact", next(iter(contacts), ""), choices=list(contacts))
    ramp = Ramp(
        value=r.float("value", unit="N"),
        start=r.float("start", 0.0, lo=0.0, unit="s"),
        duration=r.float("duration", 0.1, lo=0.0, lo_open=True, unit="s"),
        kind=r.str("kind", "linear", choices=list(RAMP_KINDS)),
        initial=r.float("initial", 0.0, unit="N"),
    )
    if contacts[contact].frame_point is not None:
        raise r.error("contact", f"a contact the robot touches (contact {contact!r}'s touching side is body "
                      f"{contacts[contact].frame!r}: no controller sets its force)", contact)
    if contacts[contact].surface_frame is not None:
        raise r.error("contact", f"a contact whose surface does not turn (contact {contact!r}'s turns with robot "
                      f"frame {contacts[contact].surface_frame!r}: a set-point along it is not supported yet)", contact)
    direction = r.str("direction", "n", choices=["n", "t1", "t2"])
    if direction != "n" and int(direction[1]) > len(contacts[contact].tangents):
        raise r.error("direction", f"'n' or one of contact {contact!r}'s {len(contacts[contact].tangents)} "
                      "tangent directions (t1, t2)", direction)
    if direction != "n" and contacts[contact].tangent_model != "chain":
        raise r.error("direction", f"'n' (a set-point along a tangent reads that tangent's chain force: contact "
                      f"{contact!r} has tangent.model = {contacts[contact].tangent_model!r}, not 'chain')", direction)
    r.finish()
    return ForceSpec(contact, ramp, direction)
