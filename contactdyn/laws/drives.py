"""Drives: one per driven coordinate, each of a registered kind; the scene's drive tables, and the drives' forces.

A drive acts on one generalized coordinate Q (a robot joint, or an active body such as a
cart). What it does is its kind's (:mod:`contactdyn.laws.drive_kinds`: ``torque``, ``dc_motor``,
``elastic``, and a user's own, registered by :func:`~contactdyn.laws.drive_kinds.register_drive_kind`).
This module holds what every kind shares:

- :class:`DriveSpec`: one coordinate's drive, its kind's parameters as attributes;
- :func:`read_drive_table` and :class:`DriveTable`: a scene's ``robot.drive`` or
  ``body.<b>.drive`` table, read from the kinds' declarations (a value or one per joint);
- :class:`Drives`: a system's drives, their coordinates and inertias. The call turns the commands into generalized
  forces by each kind's law (:mod:`contactdyn.model.pipeline.drives`): a kind with a voltage inverts the commanded
  force to a voltage (:meth:`~contactdyn.laws.drive_kinds.DriveKind.voltage`), the voltage is clipped to its
  limit there, once for all kinds, and the kind's ``force`` gives the forces at the voltage that acts.
  Kinds with a motor coordinate get its place in the state (after the system's other
  coordinates) and their motor's inertia on the mass matrix's diagonal; rigid motors reflect
  their rotor's inertia onto their coordinate.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from ..errors import SceneError
from ..scene.reader import Reader
from .drive_kinds import DRIVE_KINDS, DriveKind, gain_disagrees, not_affine_in_tau
from .failures import LawError, law_error, law_file
from .params import Param, with_defaults

__all__ = ["DRIVE_KINDS", "DriveSpec", "DriveTable", "DriveFigureError", "read_drive_table", "Drives", "drive_channels"]


def kind_of(name: str) -> type[DriveKind]:
    """The registered kind ``name``; ValueError naming the registered kinds."""
    try:
        return DRIVE_KINDS[name]
    except KeyError:
        raise ValueError(f"no drive kind {name!r} (registered: {list(DRIVE_KINDS)})") from None


class DriveSpec:
    """One coordinate's drive: its kind (a name in ``DRIVE_KINDS``) and the kind's parameters, each an attribute
    (``spec.R``); the kind's transmission figures are computed once, as attributes too (see :data:`DERIVED`).
    ``DriveSpec("dc_motor", R=0.272, C_M=0.061, J=4.5e-4)``: the parameters not given take their declared defaults.
    Immutable."""

    #: the kind's transmission figures, each computed once by the kind's method of that name (DriveKind)
    DERIVED = ("n_speed", "n_torque", "motor_inertia", "reflected_inertia", "natural_frequency")

    kind: str
    params: tuple[float, ...]  #: the kind's parameters' values, in its declared order
    n_speed: float  #: θ̇ / Q̇ [rad/rad or rad/m]
    n_torque: float  #: generalized force per motor torque [1 or 1/m]
    motor_inertia: float  #: inertia on the motor shaft [kg·m²]
    reflected_inertia: float  #: rigid-model inertia the motor adds to its coordinate [kg·m² or kg]
    natural_frequency: float  #: torsional frequency with the output clamped [rad/s] (inf: rigid)

    def __init__(self, kind: str = "torque", **values: float):
        law = kind_of(kind)
        declared = [p.name for p in law.params]
        unknown = sorted(set(values) - set(declared))
        if unknown:
            raise TypeError(f"drive kind {kind!r} has no parameter {unknown} (it declares {declared})")
        try:
            full = with_defaults(law.params, values)
        except KeyError as exc:
            raise TypeError(f"drive kind {kind!r} needs a value of {exc.args[0]!r}") from None
        put = object.__setattr__
        put(self, "kind", kind)
        put(self, "params", tuple(full.values()))
        for name, value in full.items():
            put(self, name, value)
        for name in self.DERIVED:
            put(self, name, _figure(law, name, self))
        if law.has_voltage:
            _figure(law, "voltage_limit", self)  # (checked: > 0, inf for none)
        problem = (not_affine_in_tau(law, self) if law.has_voltage else "") or \
            (gain_disagrees(law, self) if law.motorized else "")
        if problem:  # (the kind's law fails its declaration: its LawError)
            raise LawError("drive kind", law.name, law_file(law), problem)

    @property
    def law(self) -> type[DriveKind]:
        """The kind's class."""
        return DRIVE_KINDS[self.kind]

    @property
    def motorized(self) -> bool:
        return self.law.motorized

    def __setattr__(self, name, value):
        raise AttributeError(f"a DriveSpec is immutable (setting {name!r})")

    def __eq__(self, other) -> bool:
        return isinstance(other, DriveSpec) and (self.kind, self.params) == (other.kind, other.params)

    def __hash__(self) -> int:
        return hash((self.kind, self.params))

    def __repr__(self) -> str:
        values = ", ".join(f"{p.name}={getattr(self, p.name)!r}" for p in self.law.params)
        return f"DriveSpec({self.kind!r}{', ' if values else ''}{values})"


#: what each transmission figure must be (the error of parameters that give none)
FIGURES = {"n_speed": "finite speed ratio θ̇/Q̇", "n_torque": "finite torque ratio (generalized force per motor torque)",
           "motor_inertia": "finite inertia >= 0 on the motor shaft",
           "reflected_inertia": "finite reflected rotor inertia >= 0",
           "natural_frequency": "finite torsional frequency (its motor coordinate needs a motor inertia > 0)",
           "voltage_limit": "voltage limit > 0 (inf: none)"}
NON_NEGATIVE = ("motor_inertia", "reflected_inertia", "natural_frequency", "voltage_limit")  #: (of FIGURES)


class DriveFigureError(ValueError):
    """Parameters that give a drive no valid transmission figure (a division by 0, an overflow, a negative inertia)."""

    def __init__(self, spec: DriveSpec, figure: str, value: float | str):
        self.figure, self.value = figure, value
        self.values = {p.name: getattr(spec, p.name) for p in spec.law.params}
        params = ", ".join(f"{k} = {v:g}" for k, v in self.values.items())
        self.found = f"{figure} = {value if isinstance(value, str) else f'{value:g}'} at {params}"
        super().__init__(f"drive kind {spec.kind!r}: expected parameters that give a {FIGURES[figure]}, "
                         f"found {self.found}")


def _figure(law: type[DriveKind], name: str, spec: DriveSpec) -> float:
    """One transmission figure of ``spec`` (:data:`DriveSpec.DERIVED`, or its ``voltage_limit``); DriveFigureError
    where its parameters give none (:data:`FIGURES`): ``wheel_radius = 1e-300`` (an inertia of inf), an elastic motor
    without inertia (a frequency of 1/0); a user's kind raising, or returning no number: its LawError."""
    try:
        raw = getattr(law, name)(spec)
    except ArithmeticError as exc:
        raise DriveFigureError(spec, name, "x / 0" if isinstance(exc, ZeroDivisionError) else "an overflow") from None
    except Exception as exc:
        error = law_error(exc, None, ("drive kind", law))
        if error is None:
            raise
        raise error.adding(f"in its {name}") from exc
    if isinstance(raw, bool) or not isinstance(raw, int | float | np.integer | np.floating):
        raise LawError("drive kind", law.name, law_file(law), f"returned {raw!r} as its {name}: expected a number")
    value = float(raw)
    unbounded = value == math.inf and (name == "voltage_limit" or (name == "natural_frequency"
                                                                   and not law.motor_coordinate))
    if not (math.isfinite(value) or unbounded) or (name in NON_NEGATIVE and value < 0.0) or \
            (name == "voltage_limit" and value == 0.0):
        raise DriveFigureError(spec, name, value)
    return value


@dataclass(frozen=True)
class DriveTable:
    """A validated ``drive`` table: a kind (or one per joint) and parameters (scalars or per-joint lists)."""

    kind: str | tuple[str, ...] = "torque"
    values: dict[str, float | tuple[float, ...]] = field(default_factory=dict)
    path: str = "drive"
    file: str | None = None

    def expand(self, n: int, names: list[str]) -> list[DriveSpec]:
        """One :class:`DriveSpec` per coordinate; lists must have ``n`` entries."""
        def pick(key: str, value, i: int):
            if isinstance(value, tuple):
                if len(value) != n:
                    raise SceneError(f"{self.path}.{key}", f"one value or {n} (one per joint {names})",
                                     list(value), self.file)
                return value[i]
            return value

        specs = []
        for i in range(n):
            kind = pick("kind", self.kind, i)
            given = {p.name: pick(p.name, self.values[p.name], i) for p in DRIVE_KINDS[kind].params
                     if p.name in self.values}
            try:
                specs.append(DriveSpec(kind, **given))
            except DriveFigureError as exc:
                joint = f" of joint {names[i]!r}" if n > 1 or isinstance(self.kind, tuple) else ""
                raise SceneError(self.path, f"parameters that give the drive{joint} (kind {kind!r}) a "
                                 f"{FIGURES[exc.figure]}", exc.found, self.file) from None
        return specs


def read_drive_table(r: Reader, per_joint: bool) -> DriveTable:
    """Validate a ``robot.drive`` (``per_joint``: lists allowed) or ``body.<b>.drive`` table: its kind(s), then the
    parameters the kinds present declare (:class:`~contactdyn.laws.params.Param`: unit, bounds, default)."""
    raw_kind = r.raw("kind", "torque")
    if isinstance(raw_kind, list) and per_joint:
        if not raw_kind or not all(isinstance(k, str) for k in raw_kind):
            raise r.error("kind", f"one of {list(DRIVE_KINDS)} or a list of them (one per joint)", raw_kind)
        for k in raw_kind:
            Reader({"kind": k}, r.path, r.file).str("kind", choices=DRIVE_KINDS)
        kinds: str | tuple[str, ...] = tuple(raw_kind)
    else:
        kinds = r.str("kind", "torque", choices=DRIVE_KINDS)
    present = [k for k in DRIVE_KINDS if k in (kinds if isinstance(kinds, tuple) else (kinds,))]
    allowed: dict[str, Param] = {}
    for k in present:
        for p in DRIVE_KINDS[k].params:
            allowed.setdefault(p.name, p)
    values: dict[str, float | tuple[float, ...]] = {}
    for key, p in allowed.items():
        if not r.has(key):
            if p.default is None and p.same_as is None:
                raise r.error(key, f"a value [{p.unit}] (required by kind {sorted(present)})", "nothing")
            continue
        values[key] = _read_value(r, p, per_joint)
    for k in present:
        for key, why in DRIVE_KINDS[k].refuses.items():
            if key in r.data and key not in allowed:
                raise r.error(key, why, r.data[key])
    r.finish()
    return DriveTable(kinds, values, r.path, r.file)


def _read_value(r: Reader, p: Param, per_joint: bool) -> float | tuple[float, ...]:
    """One declared parameter's value from a drive table: a number, or one per joint (``per_joint``), in bounds."""
    if isinstance(r.raw(p.name), list | tuple | np.ndarray) and per_joint:  # (tuple, array: the Python API's)
        arr = r.vector(p.name, unit=p.unit)
        for x in arr:
            Reader({p.name: float(x)}, r.path, r.file).float(p.name, lo=p.lo, hi=p.hi, lo_open=p.lo_open, unit=p.unit)
        return tuple(float(x) for x in arr)
    return r.float(p.name, lo=p.lo, hi=p.hi, lo_open=p.lo_open, unit=p.unit, meaning=p.meaning)


class Drives:
    """The drives of a system's coordinates: ``coords[i]`` is driven by ``specs[i]``, by the law of its kind.

    Kinds with a motor coordinate (the elastic transmission) own one each (``motor_coords[i]``,
    -1 otherwise), placed by the system after its other coordinates.
    """

    def __init__(self, specs: list[DriveSpec], coords: list[int], names: list[str], first_motor_coord: int):
        self.specs, self.coords, self.names = specs, np.asarray(coords, int), names
        kinds = [s.law for s in specs]
        self.motor_coords = np.full(len(specs), -1, int)
        k = first_motor_coord
        for i, kind in enumerate(kinds):
            if kind.motor_coordinate:
                self.motor_coords[i] = k
                k += 1
        self.n_motor_coords = k - first_motor_coord
        self.motor_inertias = [s.motor_inertia for s, kind in zip(specs, kinds, strict=True) if kind.motor_coordinate]
        self.motorized = np.array([kind.motorized for kind in kinds], bool)  #: a law between command and coordinate
        self.has_voltage = np.array([kind.has_voltage for kind in kinds], bool)  #: takes and reports a voltage
        self.any_motor = bool(self.motorized.any())  #: False: ideal sources only
        self.u_max = np.array([kind.voltage_limit(s) for s, kind in zip(specs, kinds, strict=True)])  #: [V] inf: none
        #: rigid motors: inertia added to the true system's diagonal [kg·m² or kg] (a motor coordinate carries its own)
        self.reflected = np.array([0.0 if kind.motor_coordinate else s.reflected_inertia
                                   for s, kind in zip(specs, kinds, strict=True)])
        #: rigid-model inertia the controller adds (every motor)
        self.model_reflected = np.array([s.reflected_inertia for s in specs])
        #: the gain a commanded force lands with (folding of measured forces)
        self.gains = np.array([kind.command_gain(s) for s, kind in zip(specs, kinds, strict=True)])
        if not np.array_equal(self.coords, np.arange(len(specs))):
            raise ValueError("drives: coordinates must be the system's first ones, in order")

    def initial(self, x: np.ndarray, nQ: int) -> None:
        """Untwisted transmissions: θ = n_s Q, θ̇ = n_s Q̇ (n_s = N/r)."""
        for i, s in enumerate(self.specs):
            m = self.motor_coords[i]
            if m >= 0:
                x[m] = s.n_speed * x[self.coords[i]]
                x[nQ + m] = s.n_speed * x[nQ + self.coords[i]]


def drive_channels(system, xs: np.ndarray, samples) -> dict[str, np.ndarray]:
    """Result channels of the drives: voltages, commands and motor angles (only what the scene has)."""
    ch: dict[str, np.ndarray] = {}
    drives = system.drives
    if not drives.any_motor:
        return ch
    nv, nQ = system.nv, system.nQ
    ch["tau_cmd"] = samples.tau_cmd
    u = samples.u
    if drives.has_voltage[:nv].any():
        ch["u"] = u[:, :nv]
    for k, (name, _) in enumerate(system.body_channels):
        if drives.has_voltage[nv + k]:
            ch[f"body.{name}.u"] = u[:, nv + k]
    for i, m in enumerate(drives.motor_coords):
        if m >= 0:
            ch[f"drive.{drives.names[i]}.theta"] = xs[:, m]
            ch[f"drive.{drives.names[i]}.omega"] = xs[:, nQ + m]
    return ch
