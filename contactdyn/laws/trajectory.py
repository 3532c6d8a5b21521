"""Reference trajectories: motion profiles, straight moves and force ramps.

A :class:`Move` displaces a reference by a vector along a normalised profile
σ(τ) ∈ [0, 1]; a reference is its start point plus the sum of its moves, so a straight
Cartesian line is one move and case 1's "accelerate horizontally, descend vertically"
is two overlapping moves. A :class:`Ramp` shapes a force set-point. SI units.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import NamedTuple

import numpy as np

from ..numerics.compile_cache import njit
from ..numerics.twins import current

__all__ = ["CIRCLE_W", "add_circle", "Corner", "Move", "Ramp", "Reference", "profile", "profile_corners",
           "merge_corners", "min_span", "move_rows", "move_table", "ramp_rows", "ramp_table", "RAMP_KINDS"]

PROFILES = ("trapezoid", "triangle", "velocity_ramp", "constant_velocity", "step", "circle", "exponential")


_PROFILE_CODE = {kind: i for i, kind in enumerate(PROFILES)}  #: a profile's kind as the compiled code reads it
_TRAPEZOID, _TRIANGLE, _VELOCITY_RAMP, _CONSTANT_VELOCITY, _STEP, _CIRCLE, _EXPONENTIAL = range(len(PROFILES))
RAMP_KINDS = ("linear", "exponential", "step")
_RAMP_CODE = {kind: i for i, kind in enumerate(RAMP_KINDS)}
_LINEAR_RAMP, _EXPONENTIAL_RAMP, _STEP_RAMP = range(len(RAMP_KINDS))


def profile(kind: str, tau: float, accel_fraction: float = 0.1) -> tuple[float, float, float]:
    """Normalised profile σ, dσ/dτ, d²σ/dτ² at τ ∈ [0, 1] (clamped outside).

    ``trapezoid``: velocity rises over ``accel_fraction`` of the move, holds, falls.
    ``triangle``: the trapezoid with ``accel_fraction = 0.5``.
    ``constant_velocity``: σ = τ. ``step``: σ = 1 from τ = 0.
    ``velocity_ramp``: velocity rises linearly over the move and then holds: σ = τ²/2
    for τ ≤ 1, then τ − 1/2 (the move's displacement is then a velocity × duration).
    ``exponential``: σ = 1 − e^(−τ), the duration being the time constant (never clamped;
    case 1's position-based push follows its exponential force ramps this way).
    Every piece holds from its corner (:func:`profile_corners`) on: at a corner the profile
    takes its right-hand limit. (Computed by :func:`_profile`, which compiled time parts call too.)
    """
    return current(_profile)(_profile_code(kind), tau, accel_fraction)  # (an interpreted run: its twin)


def _profile_code(kind: str) -> int:
    """The code :func:`_profile` reads for a profile's kind (a kind it does not know: the step's branch, as a
    circle's own angle is computed by :func:`circle_reference`)."""
    return _PROFILE_CODE.get(kind, _STEP)


@njit(cache=True)
def _profile(code: int, tau: float, accel_fraction: float) -> tuple[float, float, float]:
    """:func:`profile` of the kind PROFILES[code] (a circle's own angle: :func:`circle_reference`)."""
    if code == _EXPONENTIAL:
        if tau < 0.0:
            return 0.0, 0.0, 0.0
        e = math.exp(-tau)
        return 1.0 - e, e, -e
    if code == _VELOCITY_RAMP:
        if tau < 0.0:
            return 0.0, 0.0, 0.0
        if tau < 1.0:
            return 0.5 * tau * tau, tau, 1.0
        return tau - 0.5, 1.0, 0.0
    if code == _TRAPEZOID or code == _TRIANGLE:
        return _trapezoid(tau, 0.5 if code == _TRIANGLE else accel_fraction)
    if tau < 0.0:  # at τ = 0 and τ = 1 the profile takes its right-hand limit
        return 0.0, 0.0, 0.0
    if tau >= 1.0:
        return 1.0, 0.0, 0.0
    if code == _CONSTANT_VELOCITY:
        return tau, 1.0, 0.0
    return 1.0, 0.0, 0.0  # step


@njit(cache=True)
def move_rows(t: float, moves: np.ndarray, w: np.ndarray) -> None:
    """w[3k:3k + 3] = σ, σ'/T, σ''/T² [1, 1/s, 1/s²] at t [s] of each move k, a row (kind's code, start [s],
    duration T [s], accel fraction) of ``moves`` (:func:`move_table`): a reference is start + Σ_k w ⊗ Δ_k."""
    for k in range(moves.shape[0]):
        duration = moves[k, 2]
        s, ds, dds = _profile(int(moves[k, 0]), (t - moves[k, 1]) / duration, moves[k, 3])
        w[3 * k] = s
        w[3 * k + 1] = ds / duration
        w[3 * k + 2] = dds / duration**2


def move_table(moves) -> np.ndarray:
    """(K, 4): per move its kind's code, start [s], duration [s] and accel fraction, as :func:`move_rows` reads."""
    return np.array([(_profile_code(m.kind), m.start, m.duration, m.accel_fraction) for m in moves],
                    dtype=float).reshape(len(moves), 4)


@njit(cache=True)
def _trapezoid(tau: float, a: float) -> tuple[float, float, float]:
    """:func:`profile`'s trapezoid (compiled: the circle's angle runs on it too): σ, σ', σ'' with the fraction a
    of the move accelerating, a = 0.5 the triangle; clamped outside [0, 1) (right-hand limits at 0 and 1)."""
    if tau < 0.0:
        return 0.0, 0.0, 0.0
    if tau >= 1.0:
        return 1.0, 0.0, 0.0
    vmax = 1.0 / (1.0 - a)  # peak of dσ/dτ so that σ(1) = 1
    acc = vmax / a
    if tau < a:
        return 0.5 * acc * tau * tau, acc * tau, acc
    if tau < 1.0 - a:
        return 0.5 * acc * a * a + vmax * (tau - a), vmax, 0.0
    r = 1.0 - tau
    return 1.0 - 0.5 * acc * r * r, acc * r, -acc


def profile_corners(kind: str, accel_fraction: float = 0.1) -> tuple[float, ...]:
    """The τ at which ``profile``'s pieces meet (σ or one of its derivatives jumps), as ``profile`` compares."""
    if kind in ("exponential", "step"):
        return (0.0,)
    if kind in ("velocity_ramp", "constant_velocity"):
        return (0.0, 1.0)
    a = 0.5 if kind == "triangle" else accel_fraction
    return tuple(sorted({0.0, a, 1.0 - a, 1.0}))


class Corner(NamedTuple):
    """A set-point's corner: ``before`` [s], the last time on the piece before it, and ``after`` [s],
    the first on the piece after (the next float; a few ulps apart where corners are merged).

    An integration segment ends at ``before`` and the next starts at ``after`` with the same
    state, so no step ever straddles a jump of the reference's acceleration (or of a force
    set-point's rate), and no Runge–Kutta stage sees the other piece.
    """

    before: float
    after: float


def _corner(tau_of: Callable[[float], float], t: float, tau_c: float) -> Corner:
    """The corner where ``tau_of`` (monotone, as the profile computes it) reaches tau_c, from t within ulps."""
    for _ in range(256):  # the rounding of start + τ_c · duration puts t a few ulps off
        if tau_of(t) >= tau_c:
            t = math.nextafter(t, -math.inf)
            continue
        after = math.nextafter(t, math.inf)
        if tau_of(after) >= tau_c:
            return Corner(t, after)
        t = after
    raise ArithmeticError(f"no corner at τ = {tau_c} near t = {t} s")  # unreachable for a monotone tau_of


def min_span(t: float) -> float:
    """The shortest segment [s] worth integrating near t [s] (64 ulps; the integrators' floor is 10):
    closer corners merge, and a segment that would end this close after its start starts past the corner."""
    return 64.0 * math.ulp(max(1.0, abs(t)))


def merge_corners(corners) -> tuple[Corner, ...]:
    """Corners in time order, those within :func:`min_span` of each other (or overlapping) made one."""
    out: list[Corner] = []
    for c in sorted(corners):
        if out and c.before - out[-1].after <= min_span(c.before):
            out[-1] = Corner(min(out[-1].before, c.before), max(out[-1].after, c.after))
        else:
            out.append(c)
    return tuple(out)


@njit(cache=True)
def _profile_values(code: int, taus: np.ndarray, accel_fraction: float) -> np.ndarray:
    """σ of :func:`profile` (kind PROFILES[code]) at each τ of ``taus``."""
    out = np.empty(taus.size)
    for k in range(taus.size):
        out[k] = _profile(code, taus[k], accel_fraction)[0]
    return out


@dataclass(frozen=True)
class Move:
    """Displace the reference by ``delta`` over [start, start + duration] along a profile.

    For ``velocity_ramp`` ``delta`` is the final velocity [m/s or rad/s] times the ramp
    duration, i.e. give ``velocity`` and the move keeps that velocity after the ramp.
    For ``circle`` ``delta`` is the vector from the start point to the circle's centre;
    the point turns ``turns`` times about ``normal`` along a trapezoidal angle profile.
    """

    delta: np.ndarray  #: displacement [m or rad], or velocity × duration for velocity_ramp
    start: float  #: [s]
    duration: float  #: [s], > 0
    kind: str = "trapezoid"
    accel_fraction: float = 0.1  #: fraction of the duration spent accelerating (trapezoid)
    normal: np.ndarray | None = None  #: circle only: rotation axis (unit)
    turns: float = 1.0  #: circle only: number of turns (negative: clockwise about normal)

    def tau(self, t: float) -> float:
        """Normalised time τ = (t − start)/duration [-] (the profile's argument)."""
        return (t - self.start) / self.duration

    def at(self, t: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        rows = self.rows(t)
        return rows[0], rows[1], rows[2]

    def rows(self, t: float) -> np.ndarray:
        """(3, n): the move's displacement, velocity and acceleration at t (``delta``'s unit, per s, per s²)."""
        if self.kind == "circle":
            return self.circle_rows(t)
        s, ds, dds = profile(self.kind, self.tau(t), self.accel_fraction)
        return np.multiply.outer((s, ds / self.duration, dds / self.duration**2), self.delta)

    def displacements(self, ts: np.ndarray) -> np.ndarray:
        """(len(ts), n): the move's displacement at each time of ``ts``, ``rows``' first row elementwise over them."""
        if self.kind == "circle":
            return np.array([self.circle_rows(t)[0] for t in ts]).reshape(len(ts), len(self.delta))
        s = current(_profile_values)(_profile_code(self.kind), (np.asarray(ts, float) - self.start) / self.duration,
                                     self.accel_fraction)
        return np.multiply.outer(s, self.delta)

    def corners(self) -> tuple[Corner, ...]:
        """Where the move's acceleration (or, for ``step``, its position) jumps."""
        kind = "trapezoid" if self.kind == "circle" else self.kind
        return tuple(_corner(self.tau, self.start + tc * self.duration, tc)
                     for tc in profile_corners(kind, self.accel_fraction))

    def circle_rows(self, t: float) -> np.ndarray:
        """(3, 3): the circle's displacement [m], velocity [m/s] and acceleration [m/s²] at t (compiled,
        :func:`circle_reference`: nine 3-vector numpy operations cost ~8 µs, Python floats ~2, this ~1.2)."""
        return circle_reference(t, self.start, self.duration, self.accel_fraction, 2.0 * math.pi * self.turns,
                                self._circle_terms, _NO_START).reshape(3, 3)

    @functools.cached_property
    def _circle_terms(self) -> np.ndarray:
        """(3, 4): per component (c, u, w, p): c, u = n × c, w = n × u, p = n (n·c), whose combinations are r(θ)
        and its cross products with n in closed form (three np.cross calls cost ~40 µs per reference evaluation)."""
        n, c = self.normal, self.delta
        u = np.cross(n, c)
        return np.ascontiguousarray(np.array((c, u, np.cross(n, u), n * (n @ c)), dtype=float).T)


_NO_START = np.zeros(0)


@njit(cache=True)
def circle_reference(t, t0, duration, accel_fraction, span, terms, start):
    """[displacement [m], velocity [m/s], acceleration [m/s²]] (9,) at t of a circle move starting at t0 [s]
    over ``duration`` [s] (its angle on the trapezoid, τ = (t − t0)/duration, ``span`` [rad] the turns'
    angle), ``terms`` (3, 4) per component (c, u, w, p) of :meth:`Move._circle_terms`; the point is
    start + c − r(θ), r(θ) = R(n, θ) c = c cos θ + u sin θ + p (1 − cos θ), n × r = u cos θ + w sin θ,
    n × (n × r) = w cos θ − u sin θ. ``start`` [m] (empty: none) is added to the displacement, as
    Reference.at adds a one-move reference's start."""
    s, ds, dds = _trapezoid((t - t0) / duration, accel_fraction)
    th, dth, ddth = span * s, span * ds / duration, span * dds / duration**2
    cos, sin = math.cos(th), math.sin(th)
    out = np.empty(9)
    for i in range(3):
        c, u, w, p = terms[i, 0], terms[i, 1], terms[i, 2], terms[i, 3]
        r = c * cos + u * sin + p * (1.0 - cos)
        nr = u * cos + w * sin
        out[i] = c - r if start.size == 0 else (c - r) + start[i]
        out[3 + i] = -nr * dth
        out[6 + i] = -nr * ddth - (w * cos - u * sin) * dth * dth
    return out


@dataclass(frozen=True)
class Reference:
    """Start point plus moves: position, velocity and acceleration at time t."""

    start: np.ndarray  #: [m] (task space) or [rad or m] (joint space)
    moves: tuple[Move, ...] = field(default_factory=tuple)

    def at(self, t: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        n = len(self.start)
        if not self.moves:
            return self.start.copy(), np.zeros(n), np.zeros(n)
        if len(self.moves) == 1:  # the start plus one move's rows, without the zero rows' copy and sum
            out = self.moves[0].rows(t)
            out[0] += self.start
            return out[0], out[1], out[2]
        out = self._at_rest.copy()  # x, v, a
        for move in self.moves:
            out += move.rows(t)
        return out[0], out[1], out[2]

    def positions(self, ts: np.ndarray) -> np.ndarray:
        """(len(ts), n): the position at each time of ``ts``, ``at``'s first row elementwise over them."""
        out = np.tile(self.start, (len(ts), 1))
        for move in self.moves:
            out += move.displacements(ts)
        return out

    @functools.cached_property
    def _at_rest(self) -> np.ndarray:
        """(3, n): the start point, zero velocity and acceleration."""
        out = np.zeros((3, len(self.start)))
        out[0] = self.start
        return out

    def corners(self) -> tuple[Corner, ...]:
        """The moves' corners, in time order."""
        return merge_corners(c for move in self.moves for c in move.corners())


@dataclass(frozen=True)
class Ramp:
    """A force set-point [N]: ``value`` reached from ``initial`` starting at ``start``.

    ``linear``: straight over ``duration``; ``exponential``: 1 − exp(−(t − start)/duration);
    ``step``: at once.
    """

    value: float  #: final set-point [N]
    start: float = 0.0  #: [s]
    duration: float = 0.1  #: rise time (linear) or time constant (exponential) [s], > 0
    kind: str = "linear"
    initial: float = 0.0  #: set-point before ``start`` [N]

    def at(self, t: float) -> tuple[float, float]:
        """Set-point and its rate [N, N/s] at time t (:func:`_ramp`)."""
        return _ramp(_RAMP_CODE[self.kind], self.value, self.initial, self.start, self.duration, t)

    def values(self, ts: np.ndarray) -> np.ndarray:
        """The set-point [N] at each time of ``ts`` [s] (``at``'s first value, elementwise)."""
        return _ramp_values(_RAMP_CODE[self.kind], self.value, self.initial, self.start, self.duration,
                            np.asarray(ts, float))

    def corners(self) -> tuple[Corner, ...]:
        """Where the set-point (step) or its rate (linear, exponential) jumps: its start, a linear ramp's end."""
        def since(t: float) -> float:  # ``at``'s τ [s]
            return t - self.start

        ends = (0.0, self.duration) if self.kind == "linear" else (0.0,)
        return tuple(_corner(since, self.start + tc, tc) for tc in ends)


@njit(cache=True)
def _ramp(code: int, value: float, initial: float, start: float, duration: float, t: float) -> tuple[float, float]:
    """:meth:`Ramp.at` of a ramp of kind RAMP_KINDS[code]: set-point [N] and rate [N/s] at t [s]."""
    span = value - initial
    tau = t - start
    if tau < 0.0:
        return initial, 0.0
    if code == _STEP_RAMP:
        return value, 0.0
    if code == _EXPONENTIAL_RAMP:
        e = math.exp(-tau / duration)
        return initial + span * (1.0 - e), span * e / duration
    if tau >= duration:
        return value, 0.0
    return initial + span * tau / duration, span / duration


@njit(cache=True)
def _ramp_values(code: int, value: float, initial: float, start: float, duration: float, ts: np.ndarray) -> np.ndarray:
    """:func:`_ramp`'s set-point [N] at each time of ``ts`` [s]."""
    out = np.empty(ts.size)
    for k in range(ts.size):
        out[k] = _ramp(code, value, initial, start, duration, ts[k])[0]
    return out


@njit(cache=True)
def ramp_rows(t: float, ramps: np.ndarray, w: np.ndarray) -> None:
    """w[2j:2j + 2] = F_d [N], Ḟ_d [N/s] at t [s] of each ramp j, a row (kind's code, value, initial, start,
    duration) of ``ramps`` (:func:`ramp_table`)."""
    for j in range(ramps.shape[0]):
        w[2 * j], w[2 * j + 1] = _ramp(int(ramps[j, 0]), ramps[j, 1], ramps[j, 2], ramps[j, 3], ramps[j, 4], t)


def ramp_table(ramps) -> np.ndarray:
    """(J, 5): per ramp its kind's code, value [N], initial [N], start [s] and duration [s] (:func:`ramp_rows`)."""
    return np.array([(_RAMP_CODE[r.kind], r.value, r.initial, r.start, r.duration) for r in ramps],
                    dtype=float).reshape(len(ramps), 5)


CIRCLE_W = 14  #: a circle move's packed reals (the pipeline's circle section): flag, span [rad], terms (3 × 4 by rows)


@njit(cache=True)
def add_circle(t, move, circle, x_d, v_d, a_d):
    """A packed circle move's displacement [m], velocity [m/s] and acceleration [m/s²] at t [s] added to (x_d, v_d,
    a_d), from :func:`circle_reference`: ``move`` its row of the move table (code, start [s], duration [s], accel
    fraction), ``circle`` its packed reals (a flag, 1 a circle; the turns' angle [rad]; the (c, u, w, p) terms,
    ``Move._circle_terms``)."""
    out = circle_reference(t, move[1], move[2], move[3], circle[1], circle[2:CIRCLE_W].reshape((3, 4)),
                           np.zeros(0))
    for i in range(3):
        x_d[i] += out[i]
        v_d[i] += out[3 + i]
        a_d[i] += out[6 + i]
