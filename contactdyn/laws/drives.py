"""Drives: ideal torque sources, DC motors through rigid gears or wheels, elastic transmissions.

A drive acts on one generalized coordinate Q (a robot joint, or an active body such as a
cart). Kinds:

- ``torque``: an ideal source; the commanded generalized force acts as it is.
- ``dc_motor``: a DC motor without inductance (eq. 51), M = (C_M/R) u − (C_M C_E/R) θ̇,
  through a rigid gear of speed ratio N and torque ratio N*, optionally ending on a wheel
  of radius r that turns rotation into translation (the cart). No state of its own.
- ``elastic``: the same motor through a harmonic drive with tube stiffness c and damping d
  (eqs 50–54); the motor angle θ is a second-order coordinate of its own with inertia
  J + I′ + I″/N² (eq. 53).

Rigid gear, derivation (one coordinate, motor angle θ, output Q; r = 1 for a rotary output):

    kinematics   θ = (N/r) Q                       speed ratio n_s = N/r   [rad per rad or per m]
    rotor        J θ̈ = M − M_L                     M_L: torque the gear input takes [N·m]
    gear         Q-force = (N*/r) M_L              torque ratio n_t = N*/r [1 or 1/m]

so the coordinate receives n_t M − n_t n_s J Q̈: the rotor inertia reflects as n_s n_t J
(N N* J, or N N* J / r² through a wheel), added to the diagonal of the inertia matrix, and
the back-EMF reflects as a damping n_t n_s C_M C_E / R. With N* = N the gear is ideal and
these are the familiar N² J and N² C_M C_E / R. With N* < N (case 2: N = 160, N* = 65.12)
the gear passes a fraction η = N*/N = 0.407 of the power: the output speed follows N, the
output torque follows N*, and both ratios enter the reflection through their product (not
N² and not N*²). The lossy gear is a constant-efficiency model in both directions of power
flow, so the reflected "kinetic energy" ½ n_s n_t J Q̇² is not the rotor's ½ J θ̇²; the energy
audit counts the work n_t M Q̇ that reaches the coordinate.

Elastic transmission (eqs 53–54, N* = N): tube twist φ = θ/N − Q/r, tube torque
T = c φ + d φ̇; the motor side feels T/N, the coordinate T/r. As c → ∞ it tends to the rigid
gear with N* = N and rotor inertia J + I′ + I″/N².

Commands: a controller asks for a generalized force τ_d on each coordinate (the rigid model:
the force of the motor through its gear, rotor inertia on the controller's side of the
model). The drive inverts eq. 51 in the rigid model, u = R τ_d / (n_t C_M) + C_E n_s Q̇,
clips it to ±u_max, and the clipped voltage is what acts. Unclipped, a rigid drive then
delivers exactly τ_d. An elastic one delivers M = τ_d / n_t + (C_M C_E / R)(n_s Q̇ − θ̇) at
the motor: the controller ignores the elasticity, so it knows the speed of its coordinate
only, and the back-EMF keeps damping the twist rate. (Inverting at the measured θ̇ instead
would cancel the back-EMF damping, nearly all the damping the torsional mode has: case 3's
transmission would keep ζ ≈ 1e-4 of its 0.14, and a stiff PD approach then goes unstable.)
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from ..errors import SceneError
from ..scene.reader import Reader

__all__ = ["DRIVE_KINDS", "DriveSpec", "DriveTable", "read_drive_table", "Drives", "DriveOutput", "drive_channels"]

DRIVE_KINDS = ("torque", "dc_motor", "elastic")

#: parameter: (unit, lower bound, bound open, default); default None: required; a name: that parameter
_MOTOR = {
    "R": ("Ω", 0.0, True, None),
    "C_M": ("N·m/A", 0.0, True, None),
    "C_E": ("V·s/rad", 0.0, True, "C_M"),  # SI: the back-EMF constant equals the torque constant
    "J": ("kg·m²", 0.0, False, None),
    "N": ("-", 0.0, True, 1.0),
    "wheel_radius": ("m", 0.0, True, 0.0),  # 0: rotary output (no wheel)
    "u_max": ("V", 0.0, True, math.inf),
}
_PARAMS = {
    "torque": {},
    "dc_motor": {**_MOTOR, "N_star": ("-", 0.0, True, "N")},
    "elastic": {**_MOTOR, "c": ("N·m/rad", 0.0, True, None), "d": ("N·m·s/rad", 0.0, False, 0.0),
                "I1": ("kg·m²", 0.0, False, 0.0), "I2": ("kg·m²", 0.0, False, 0.0),
                "twist_damping": ("N·m·s/rad", 0.0, False, 0.0)},
}


@dataclass(frozen=True)
class DriveSpec:
    """One coordinate's drive (see the module docstring for the equations)."""

    kind: str = "torque"
    R: float = 0.0  #: armature resistance [Ω]
    C_M: float = 0.0  #: torque constant [N·m/A]
    C_E: float = 0.0  #: back-EMF constant [V·s/rad]
    J: float = 0.0  #: rotor inertia [kg·m²]
    N: float = 1.0  #: speed ratio, motor speed / gear output speed [-]
    N_star: float = 1.0  #: torque ratio, gear output torque / input torque [-] (elastic: = N)
    wheel_radius: float = 0.0  #: [m] wheel turning the output rotation into translation; 0: none
    u_max: float = math.inf  #: voltage limit [V]
    c: float = 0.0  #: tube stiffness [N·m/rad] (elastic)
    d: float = 0.0  #: tube damping [N·m·s/rad] (elastic)
    I1: float = 0.0  #: I′, wave generator inertia on the motor shaft [kg·m²] (elastic)
    I2: float = 0.0  #: I″, flexspline inertia on the output side [kg·m²] (elastic, enters as I″/N²)
    #: g, active damping of the twist rate on the motor side, M −= g (θ̇ − n_s Q̇) [N·m·s/rad] (elastic; 0: none)
    twist_damping: float = 0.0

    @property
    def motorized(self) -> bool:
        return self.kind != "torque"

    @property
    def r(self) -> float:
        """Output lever [m or 1]: the wheel radius, 1 for a rotary output."""
        return self.wheel_radius if self.wheel_radius > 0.0 else 1.0

    @property
    def n_speed(self) -> float:
        """θ̇ / Q̇ = N/r [rad/rad or rad/m]."""
        return self.N / self.r

    @property
    def n_torque(self) -> float:
        """Generalized force per motor torque = N*/r [1 or 1/m] (elastic: N/r)."""
        return (self.N_star if self.kind == "dc_motor" else self.N) / self.r

    @property
    def motor_inertia(self) -> float:
        """Inertia on the motor shaft [kg·m²]: J, or J + I′ + I″/N² (eq. 53)."""
        return self.J + self.I1 + self.I2 / self.N**2 if self.kind == "elastic" else self.J

    @property
    def reflected_inertia(self) -> float:
        """Rigid-model inertia the motor adds to its coordinate, n_s n_t J_m [kg·m² or kg]."""
        return self.n_speed * self.n_torque * self.motor_inertia if self.motorized else 0.0

    @property
    def natural_frequency(self) -> float:
        """Torsional frequency of the transmission with the output clamped, √(c / (N² J_m)) [rad/s]."""
        return math.sqrt(self.c / (self.N**2 * self.motor_inertia)) if self.kind == "elastic" else math.inf


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
            if kind == "torque":
                specs.append(DriveSpec())
                continue
            params = {}
            for key, (_, _, _, default) in _PARAMS[kind].items():
                params[key] = pick(key, self.values[key], i) if key in self.values else default
            for key, value in params.items():  # defaults naming another parameter (C_E = C_M, N_star = N)
                if isinstance(value, str):
                    params[key] = params[value]
            specs.append(DriveSpec(kind=kind, **params))
        return specs


def read_drive_table(r: Reader, per_joint: bool) -> DriveTable:
    """Validate a ``robot.drive`` (``per_joint``: lists allowed) or ``body.<b>.drive`` table."""
    raw_kind = r.raw("kind", "torque")
    if isinstance(raw_kind, list) and per_joint:
        if not raw_kind or not all(isinstance(k, str) for k in raw_kind):
            raise r.error("kind", f"one of {list(DRIVE_KINDS)} or a list of them (one per joint)", raw_kind)
        for k in raw_kind:
            Reader({"kind": k}, r.path, r.file).str("kind", choices=DRIVE_KINDS)
        kinds: str | tuple[str, ...] = tuple(raw_kind)
    else:
        kinds = r.str("kind", "torque", choices=DRIVE_KINDS)
    present = set(kinds) if isinstance(kinds, tuple) else {kinds}
    allowed: dict[str, tuple] = {}
    for k in present:
        allowed.update(_PARAMS[k])
    values: dict[str, float | tuple[float, ...]] = {}
    for key, (unit, lo, lo_open, default) in allowed.items():
        if not r.has(key):
            if default is None:
                raise r.error(key, f"a value [{unit}] (required by kind {sorted(present)})", "nothing")
            continue
        raw = r.raw(key)
        if isinstance(raw, list) and per_joint:
            arr = r.vector(key, unit=unit)
            for x in arr:
                Reader({key: float(x)}, r.path, r.file).float(key, lo=lo, lo_open=lo_open, unit=unit)
            values[key] = tuple(float(x) for x in arr)
        else:
            values[key] = r.float(key, lo=lo, lo_open=lo_open, unit=unit)
    if "N_star" in r.data and "N_star" not in allowed:
        raise r.error("N_star", "no N_star with an elastic transmission (eq. 53 has one ratio N)", r.data["N_star"])
    r.finish()
    return DriveTable(kinds, values, r.path, r.file)


@dataclass
class DriveOutput:
    """What the drives did at one evaluation."""

    applied: np.ndarray  #: generalized force reaching each driven coordinate [N·m or N]
    u: np.ndarray  #: voltage per drive [V] (NaN for ideal torque drives)
    saturated: np.ndarray  #: bool per drive: the voltage was clipped
    power: float  #: mechanical power the drives deliver [W] (motors: M θ̇ for elastic, applied·Q̇ rigid)
    dissipation: float  #: tube damper power d φ̇² [W]


class Drives:
    """The drives of a system's coordinates: ``coords[i]`` is driven by ``specs[i]``.

    Elastic drives own a motor coordinate each (``motor_coords[i]``, -1 otherwise), placed
    by the system after its other coordinates.
    """

    def __init__(self, specs: list[DriveSpec], coords: list[int], names: list[str], first_motor_coord: int):
        self.specs, self.coords, self.names = specs, np.asarray(coords, int), names
        self.motor_coords = np.full(len(specs), -1, int)
        k = first_motor_coord
        for i, s in enumerate(specs):
            if s.kind == "elastic":
                self.motor_coords[i] = k
                k += 1
        self.n_motor_coords = k - first_motor_coord
        self.motor_inertias = [s.motor_inertia for s in specs if s.kind == "elastic"]
        self.motorized = np.array([s.motorized for s in specs], bool)
        self.any_motor = bool(self.motorized.any())
        #: rigid gears: inertia added to the true system's diagonal [kg·m² or kg]
        self.reflected = np.array([s.reflected_inertia if s.kind == "dc_motor" else 0.0 for s in specs])
        #: rigid-model inertia the controller adds (rigid and elastic drives)
        self.model_reflected = np.array([s.reflected_inertia for s in specs])
        #: where a commanded force lands and with what gain (folding of measured forces)
        self.targets = np.where(self.motor_coords >= 0, self.motor_coords, self.coords)
        if not np.array_equal(self.coords, np.arange(len(specs))):
            raise ValueError("drives: coordinates must be the system's first ones, in order")
        self._no_u, self._no_sat = np.full(len(specs), np.nan), np.zeros(len(specs), bool)  # shared, read-only
        self.gains = np.array([1.0 / s.n_torque if s.kind == "elastic" else 1.0 for s in specs])
        self._consts = [(DRIVE_KINDS.index(s.kind), int(self.coords[i]), int(self.motor_coords[i]), s.n_speed,
                         s.n_torque, s.R, s.C_M, s.C_E, s.u_max, s.N, s.r, s.c, s.d, s.twist_damping)
                        for i, s in enumerate(specs)]

    def omega(self, i: int, x: np.ndarray, nQ: int) -> float:
        """Motor speed θ̇ of drive i [rad/s]."""
        s, m = self.specs[i], self.motor_coords[i]
        return x[nQ + m] if m >= 0 else s.n_speed * x[nQ + self.coords[i]]

    def initial(self, x: np.ndarray, nQ: int) -> None:
        """Untwisted transmissions: θ = (N/r) Q, θ̇ = (N/r) Q̇."""
        for i, s in enumerate(self.specs):
            m = self.motor_coords[i]
            if m >= 0:
                x[m] = s.n_speed * x[self.coords[i]]
                x[nQ + m] = s.n_speed * x[nQ + self.coords[i]]

    def apply(self, cmd: np.ndarray, x: np.ndarray, nQ: int, f: np.ndarray, *, voltage: np.ndarray | None = None,
              sat_cmd: np.ndarray | None = None, clip: bool = True) -> DriveOutput:
        """Add the drives' generalized forces to ``f``; ``cmd`` holds a force per drive, or a voltage [V]
        where the mask ``voltage`` is true.

        ``sat_cmd`` (default ``cmd``) decides which voltages clip: the system passes the full
        command there while ``cmd`` lacks the part it folds into its linear solve. ``clip=False``:
        the law without the voltage limits, affine in (cmd, x) (the compiled plan probes it).
        """
        n = len(self.specs)
        if not self.any_motor:  # ideal sources only; the coordinates are 0 .. n−1 (joints, then bodies)
            f[:n] += cmd
            return DriveOutput(cmd, self._no_u, self._no_sat, float(cmd @ x[nQ:nQ + n]), 0.0)
        applied = np.empty(n)
        u = np.full(n, np.nan)
        saturated = np.zeros(n, bool)
        power = dissipation = 0.0
        sat_cmd = cmd if sat_cmd is None else sat_cmd
        for i, (kind, c, m, ns, nt, R, C_M, C_E, u_max, N, r, k, d, g) in enumerate(self._consts):
            qd = x[nQ + c]
            if kind == 0:  # ideal torque source
                applied[i] = cmd[i]
                f[c] += cmd[i]
                power += cmd[i] * qd
                continue
            w = x[nQ + m] if m >= 0 else ns * qd  # motor speed [rad/s]
            w_model = ns * qd  # the rigid model's motor speed, from the coordinate's own speed
            M_fast = -g * (w - w_model) if m >= 0 else 0.0  # composite control: damp the twist rate [N·m]
            if voltage is not None and voltage[i]:
                ui = cmd[i]
            else:  # eq. 51 inverted at the rigid model's speed
                ui = R * (sat_cmd[i] / nt + M_fast) / C_M + C_E * w_model
            saturated[i] = clip and abs(ui) > u_max
            if saturated[i]:
                ui = math.copysign(u_max, ui)
            elif sat_cmd is not cmd and not (voltage is not None and voltage[i]):
                ui = R * (cmd[i] / nt + M_fast) / C_M + C_E * w_model
            u[i] = ui
            M = C_M / R * (ui - C_E * w)  # eq. 51 [N·m]
            if m < 0:  # rigid gear
                applied[i] = nt * M
                f[c] += applied[i]
                power += applied[i] * qd
            else:  # elastic transmission, eqs 53-54
                twist_rate = x[nQ + m] / N - qd / r
                T = k * (x[m] / N - x[c] / r) + d * twist_rate  # tube torque [N·m]
                f[m] += M - T / N
                applied[i] = T / r
                f[c] += applied[i]
                power += M * w
                dissipation += d * twist_rate * twist_rate
        return DriveOutput(applied, u, saturated, power, dissipation)


def drive_channels(system, xs: np.ndarray, samples) -> dict[str, np.ndarray]:
    """Result channels of the drives: voltages, commands and motor angles (only what the scene has)."""
    ch: dict[str, np.ndarray] = {}
    drives = system.drives
    if not drives.any_motor:
        return ch
    nv, nQ = system.nv, system.nQ
    ch["tau_cmd"] = samples.tau_cmd
    u = samples.u
    if drives.motorized[:nv].any():
        ch["u"] = u[:, :nv]
    for k, name in enumerate(system.body_names):
        if drives.motorized[nv + k]:
            ch[f"body.{name}.u"] = u[:, nv + k]
    for i, m in enumerate(drives.motor_coords):
        if m >= 0:
            ch[f"drive.{drives.names[i]}.theta"] = xs[:, m]
            ch[f"drive.{drives.names[i]}.omega"] = xs[:, nQ + m]
    return ch
