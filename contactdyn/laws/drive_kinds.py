"""Drive kinds: how a command on one generalized coordinate becomes generalized forces, one declared class each.

A drive acts on one coordinate Q (a robot joint, or an active body such as a cart). Its kind
is a class registered by name (:func:`register_drive_kind`, the ``kind`` of a scene's drive
table) that declares its parameters once (:class:`~contactdyn.laws.params.Param`: the scene
reads and checks them from there, the key reference documents them), its properties and its
law. Its properties decide the physics, never its name:

- ``motorized``: a law stands between the command and the coordinate (its ``force``); False:
  an ideal source, whose commanded generalized force acts as it is;
- ``motor_coordinate``: the kind owns a second-order coordinate, the motor angle θ (the
  elastic transmission), with inertia ``motor_inertia``;
- ``has_voltage``: the kind takes a voltage command and reports its voltage u [V], clipped to
  ±``voltage_limit`` (a ``voltage`` controller drives it; ``u`` channels record it);

The built-in kinds:

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
model). A motor inverts eq. 51 in the rigid model, u = R τ_d / (n_t C_M) + C_E n_s Q̇
(:meth:`DriveKind.voltage`); the drives clip it to ±u_max, and the clipped voltage is what acts
(:meth:`DriveKind.force`). Unclipped, a rigid drive then delivers exactly τ_d. An elastic one
delivers M = τ_d / n_t + (C_M C_E / R)(n_s Q̇ − θ̇) at the motor: the controller ignores the
elasticity, so it knows the speed of its coordinate only, and the back-EMF keeps damping the
twist rate. (Inverting at the measured θ̇ instead would cancel the back-EMF damping, nearly all
the damping the torsional mode has: case 3's transmission would keep ζ ≈ 1e-4 of its 0.14, and
a stiff PD approach then goes unstable.)
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, ClassVar

from .params import Param, check_declaration, claim_name, departs

if TYPE_CHECKING:
    from .drives import DriveSpec

__all__ = ["DriveKind", "DRIVE_KINDS", "register_drive_kind", "Torque", "DcMotor", "Elastic", "MOTOR_PARAMS",
           "TORQUE_RATIO", "TUBE_PARAMS", "not_affine_in_tau", "gain_disagrees"]

#: the motor of eq. 51 behind a gear (dc_motor and elastic)
MOTOR_PARAMS = (
    Param("R", "Ω", "armature resistance", lo=0.0, lo_open=True),
    Param("C_M", "N·m/A", "motor torque constant", lo=0.0, lo_open=True),
    Param("C_E", "V·s/rad", "back-EMF constant (default: C_M, SI)", lo=0.0, lo_open=True, same_as="C_M"),
    Param("J", "kg·m²", "rotor inertia", lo=0.0),
    Param("N", "-", "speed ratio, motor speed / output speed", 1.0, lo=0.0, lo_open=True),
    Param("wheel_radius", "m", "radius of a wheel turning rotation into translation (0: rotary output)", 0.0,
          lo=0.0, lo_open=True, example=0.1),
    Param("u_max", "V", "voltage limit (commands are clipped to +-u_max)", math.inf, lo=0.0, lo_open=True),
)
TORQUE_RATIO = Param("N_star", "-", "torque ratio, output torque / motor torque (default: N; N* < N is a lossy gear)",
                     lo=0.0, lo_open=True, same_as="N")
#: the harmonic drive's tube and its inertias (elastic)
TUBE_PARAMS = (
    Param("c", "N·m/rad", "stiffness of the transmission tube", lo=0.0, lo_open=True),
    Param("d", "N·m·s/rad", "damping of the transmission tube", 0.0, lo=0.0),
    Param("I1", "kg·m²", "I', wave generator inertia on the motor shaft", 0.0, lo=0.0),
    Param("I2", "kg·m²", "I'', flexspline inertia on the output side (enters as I''/N^2)", 0.0, lo=0.0),
    Param("twist_damping", "N·m·s/rad", "active damping of the twist rate on the motor side", 0.0, lo=0.0),
)


class DriveKind:
    """A drive kind: its parameters, its properties and its law on one coordinate; every method takes the drive's
    :class:`~contactdyn.laws.drives.DriveSpec` (its parameters as attributes, ``spec.R``). The defaults are the ideal
    source's."""

    name: ClassVar[str] = ""
    meaning: ClassVar[str] = ""  #: one line for the key reference (``drive.kind``)
    params: ClassVar[tuple[Param, ...]] = ()  #: the kind's parameters, read from the scene's drive table
    motorized: ClassVar[bool] = False  #: a law between command and coordinate (False: an ideal source)
    motor_coordinate: ClassVar[bool] = False  #: owns a motor angle θ, a second-order coordinate
    has_voltage: ClassVar[bool] = False  #: takes a voltage command, reports u [V], clips it to ±voltage_limit
    refuses: ClassVar[dict[str, str]] = {}  #: another kind's key this kind refuses -> what the error says instead

    # ---- the transmission, once per drive (DriveSpec holds the values) ----------------------------------------
    @staticmethod
    def n_speed(spec: DriveSpec) -> float:
        """θ̇ / Q̇, the motor speed per coordinate speed [rad/rad or rad/m]."""
        return 1.0

    @staticmethod
    def n_torque(spec: DriveSpec) -> float:
        """Generalized force per motor torque [1 or 1/m]."""
        return 1.0

    @staticmethod
    def motor_inertia(spec: DriveSpec) -> float:
        """Inertia on the motor shaft [kg·m²]."""
        return 0.0

    @classmethod
    def reflected_inertia(cls, spec: DriveSpec) -> float:
        """Rigid-model inertia the motor adds to its coordinate, n_s n_t J_m [kg·m² or kg] (0: not motorized)."""
        return cls.n_speed(spec) * cls.n_torque(spec) * cls.motor_inertia(spec) if cls.motorized else 0.0

    @staticmethod
    def natural_frequency(spec: DriveSpec) -> float:
        """Torsional frequency of the transmission with the output clamped [rad/s] (inf: rigid)."""
        return math.inf

    @staticmethod
    def command_gain(spec: DriveSpec) -> float:
        """Force on the drive's target coordinate (its motor coordinate if it owns one) per unit force command, below
        the voltage limit [1, or 1/n_t on a motor]: where a force-reading controller's command is folded (checked
        against the kind's law at each drive's values: :func:`gain_disagrees`)."""
        return 1.0

    @staticmethod
    def voltage_limit(spec: DriveSpec) -> float:
        """|u| ≤ this [V] (inf: no limit; kinds with a voltage)."""
        return math.inf

    # ---- the law, on every call -------------------------------------------------------------------------------
    @staticmethod
    def voltage(spec: DriveSpec, tau: float, qd: float, omega: float) -> float:
        """The voltage [V] that asks for the generalized force ``tau`` [N·m or N] at coordinate speed ``qd`` and motor
        speed ``omega`` [rad/s] (kinds with a voltage; affine in ``tau``: checked for each drive,
        :func:`not_affine_in_tau`)."""
        raise NotImplementedError(f"drive kind {spec.kind!r} has no voltage")

    @staticmethod
    def force(spec: DriveSpec, command: float, q: float, qd: float, theta: float,
              omega: float) -> tuple[float, float, float, float]:
        """(force on the coordinate [N·m or N], torque on the motor coordinate [N·m], mechanical power delivered [W],
        power dissipated inside the drive [W]) at ``command`` (the voltage [V] for a kind with a voltage, else the
        commanded force), the coordinate's position and speed (q, qd) and the motor's angle and speed (theta, omega:
        NaN without a motor coordinate). The ideal source's: the command acts as it is."""
        return command, 0.0, command * qd, 0.0

    @staticmethod
    def potential(spec: DriveSpec, q, theta):
        """Energy [J] stored in the transmission at coordinate q and motor angle θ (floats or arrays; kinds with a
        motor coordinate), for the energy audit."""
        return 0.0


DRIVE_KINDS: dict[str, type[DriveKind]] = {}  #: name -> kind, the ``kind`` values a scene's drive table accepts

_SPEC_NAMES = ("kind", "params", "law", "motorized", "n_speed", "n_torque", "motor_inertia", "reflected_inertia",
               "natural_frequency")  #: DriveSpec's own attributes, no parameter's name


def register_drive_kind(cls: type[DriveKind]) -> type[DriveKind]:
    """Make ``cls`` a kind scenes can name (``kind = cls.name`` in ``robot.drive`` or ``body.<b>.drive``).

    A parameter another kind declares too must be declared the same (one drive table may mix kinds); a kind that is
    not motorized is an ideal source and keeps the base law; a voltage or a motor coordinate needs a motor."""
    check_declaration(cls, "drive kind", DriveKind, _SPEC_NAMES, read_defaults=False)
    if (cls.has_voltage or cls.motor_coordinate or cls.force is not DriveKind.force) and not cls.motorized:
        raise ValueError(f"drive kind {cls.name!r}: a voltage, a motor coordinate or a law of its own needs "
                         "motorized = True (a kind that is not motorized is an ideal source)")
    for other in DRIVE_KINDS.values():
        shared = {p.name: p for p in other.params}
        for p in cls.params:
            if other.name != cls.name and p.name in shared and _declared(p) != _declared(shared[p.name]):
                raise ValueError(f"drive kind {cls.name!r}: parameter {p.name!r} is declared otherwise by kind "
                                 f"{other.name!r} ({shared[p.name]})")
    claim_name(DRIVE_KINDS, cls, "drive kind")
    return cls


#: (q̇ [rad/s or m/s], ω [rad/s]) and the forces τ [N·m or N] at which a voltage's affinity in τ is tried (ω: a kind
#: with a motor coordinate's; NaN for another, as the call gives it)
_TRIED_SPEEDS, _TRIED_TAU = ((0.0, 0.0), (0.7, -40.0)), (-2.5, 0.3, 40.0)


def not_affine_in_tau(cls: type[DriveKind], spec: DriveSpec) -> str:
    """Where kind ``cls``'s voltage u(τ) [V] at the drive ``spec``'s values is not u(0) + τ (u(1) − u(0)) (τ [N·m or
    N]), at the speeds tried, or "" (also where a call raises or gives no finite number: what cannot be tried is not
    refused; the run names the kind if it fails there). The solve folds a force-reading controller's command through
    the voltage by its slope (``command_gain``)."""
    for qd, omega in _TRIED_SPEEDS:
        omega = omega if cls.motor_coordinate else math.nan
        got = _tried(lambda qd=qd, w=omega: (cls.voltage(spec, tau, qd, w) for tau in (0.0, 1.0, *_TRIED_TAU)))
        if got is None:
            return ""
        u0, u1, *tried = got
        for tau, u in zip(_TRIED_TAU, tried, strict=True):
            affine = u0 + tau * (u1 - u0)
            if departs(u, affine, abs(u0) + abs(tau * (u1 - u0))):
                motor = f", ω = {omega:g} rad/s" if cls.motor_coordinate else ""
                at = ", ".join(f"{p.name} = {getattr(spec, p.name):g}" for p in cls.params)
                return (f"gives u = {u:g} V at τ = {tau:g} N·m or N, q̇ = {qd:g}{motor}{f' ({at})' if at else ''}, "
                        f"not u(0) + τ (u(1) − u(0)) = {affine:g} V: expected a voltage affine in τ (has_voltage: the "
                        "solve folds a force-reading controller's command through it)")
    return ""


#: [N·m or N] the commands ±this, at rest, whose forces give a drive's slope (gain_disagrees)
_TRIED_STEP = 1e-3


def gain_disagrees(cls: type[DriveKind], spec: DriveSpec) -> str:
    """Where kind ``cls``'s own law, at rest and the drive ``spec``'s values, gives a force on its target coordinate
    (its motor coordinate if it owns one) per unit force command other than its ``command_gain``, what it gives, or
    "" (also where a call raises or gives no finite number: the run names the kind if it fails there). The command
    goes through its voltage where it has one. The solve folds a force-reading controller's command by that gain."""
    omega = 0.0 if cls.motor_coordinate else math.nan
    target = 1 if cls.motor_coordinate else 0

    def force(tau: float) -> float:  # [N·m or N] on the target at the force command tau, at rest
        command = cls.voltage(spec, tau, 0.0, omega) if cls.has_voltage else tau
        return cls.force(spec, command, 0.0, 0.0, omega, omega)[target]

    got = _tried(lambda: (force(-_TRIED_STEP), force(_TRIED_STEP), cls.command_gain(spec)))
    if got is None:
        return ""
    lo, hi, gain = got
    slope = (hi - lo) / (2.0 * _TRIED_STEP)
    if not departs(slope, gain, abs(gain) + (abs(hi) + abs(lo)) / (2.0 * _TRIED_STEP)):
        return ""
    on = "motor coordinate" if cls.motor_coordinate else "coordinate"
    return (f"gives {slope:g} of force on its {on} per unit force command (at rest, τ = ±{_TRIED_STEP:g} N·m or N"
            f"{' through its voltage' if cls.has_voltage else ''}), not its command_gain {gain:g}: declare "
            "command_gain as its law's slope (the solve folds a force-reading controller's command by it)")


def _tried(values) -> list[float] | None:
    """The numbers a kind's law gives (``values()``: its calls), or None where a call raises or one is not finite: what
    cannot be tried is not refused (the run names the kind if it fails there)."""
    try:
        out = [float(v) for v in values()]
    except Exception:  # noqa: BLE001 (a user's law: whatever it raises, the check gives up)
        return None
    return out if all(map(math.isfinite, out)) else None


def _declared(p: Param) -> tuple:
    """What a parameter shared by kinds must agree on: all but its meaning and example."""
    return p.unit, p.default, p.lo, p.hi, p.lo_open, p.same_as


def _lever(spec: DriveSpec) -> float:
    """Output lever [m or 1]: the wheel radius, 1 for a rotary output."""
    return spec.wheel_radius if spec.wheel_radius > 0.0 else 1.0


@register_drive_kind
class Torque(DriveKind):
    name = "torque"
    meaning = "ideal torque source"


class _GearedMotor(DriveKind):
    """The DC motor of eq. 51 behind a gear of speed ratio N, optionally on a wheel."""

    motorized = has_voltage = True

    @staticmethod
    def n_speed(spec: DriveSpec) -> float:
        return spec.N / _lever(spec)

    @staticmethod
    def motor_inertia(spec: DriveSpec) -> float:
        return spec.J

    @staticmethod
    def voltage_limit(spec: DriveSpec) -> float:
        return spec.u_max

    @staticmethod
    def voltage(spec: DriveSpec, tau: float, qd: float, omega: float) -> float:
        """Eq. 51 inverted at the rigid model's motor speed n_s Q̇."""
        return spec.R * (tau / spec.n_torque) / spec.C_M + spec.C_E * (spec.n_speed * qd)


@register_drive_kind
class DcMotor(_GearedMotor):
    name = "dc_motor"
    meaning = "motor through a rigid gear (eq. 51)"
    params = (*MOTOR_PARAMS, TORQUE_RATIO)

    @staticmethod
    def n_torque(spec: DriveSpec) -> float:
        return spec.N_star / _lever(spec)

    @staticmethod
    def force(spec: DriveSpec, command: float, q: float, qd: float, theta: float,
              omega: float) -> tuple[float, float, float, float]:
        M = spec.C_M / spec.R * (command - spec.C_E * (spec.n_speed * qd))  # eq. 51 [N·m]
        applied = spec.n_torque * M
        return applied, 0.0, applied * qd, 0.0


@register_drive_kind
class Elastic(_GearedMotor):
    name = "elastic"
    meaning = "through an elastic transmission (eqs 53-54)"
    params = (*MOTOR_PARAMS, *TUBE_PARAMS)
    motor_coordinate = True
    refuses = {"N_star": "no N_star with an elastic transmission (eq. 53 has one ratio N)"}

    @staticmethod
    def n_torque(spec: DriveSpec) -> float:
        return spec.N / _lever(spec)

    @staticmethod
    def motor_inertia(spec: DriveSpec) -> float:
        """J + I′ + I″/N² (eq. 53)."""
        return spec.J + spec.I1 + spec.I2 / spec.N**2

    @staticmethod
    def natural_frequency(spec: DriveSpec) -> float:
        """√(c / (N² J_m))."""
        return math.sqrt(spec.c / (spec.N**2 * spec.motor_inertia))

    @staticmethod
    def command_gain(spec: DriveSpec) -> float:
        return 1.0 / spec.n_torque

    @staticmethod
    def voltage(spec: DriveSpec, tau: float, qd: float, omega: float) -> float:
        """Eq. 51 inverted at the rigid model's speed; twist_damping g damps the twist rate, M −= g (θ̇ − n_s Q̇)."""
        w_model = spec.n_speed * qd
        M_fast = -spec.twist_damping * (omega - w_model)  # composite control [N·m]
        return spec.R * (tau / spec.n_torque + M_fast) / spec.C_M + spec.C_E * w_model

    @staticmethod
    def force(spec: DriveSpec, command: float, q: float, qd: float, theta: float,
              omega: float) -> tuple[float, float, float, float]:
        M = spec.C_M / spec.R * (command - spec.C_E * omega)  # eq. 51 [N·m]
        r, N = _lever(spec), spec.N
        twist_rate = omega / N - qd / r
        T = spec.c * (theta / N - q / r) + spec.d * twist_rate  # tube torque, eqs 53-54 [N·m]
        return T / r, M - T / N, M * omega, spec.d * twist_rate * twist_rate

    @staticmethod
    def potential(spec: DriveSpec, q, theta):
        """½ c φ², φ = θ/N − Q/r."""
        twist = theta / spec.N - q / _lever(spec)
        return 0.5 * spec.c * twist * twist
