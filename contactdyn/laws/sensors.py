"""Sensor models of a sampled controller: what it measures at a sample instant, not what the model knows; and
when it samples (:class:`Sampling`: rate, delay, sensors, the keys every controller table may carry).

A sampled controller (:mod:`contactdyn.laws.controllers.sampled`) reads its inputs once per sample period
T [s] through these models:

- force/torque sensor, on every measured contact force (``ControlInput.forces``: each contact's normal force
  and tangential chain's force [N]): reading = F + bias + noise, noise ~ N(0, σ²) drawn from a
  ``numpy.random.Generator`` seeded by the scene (the same seed gives the same draws), then a first-order
  low-pass y' = (u − y)/τ, τ = 1/(2π f_c), discretised exactly for an input that runs linearly from one reading to
  the next (the force is continuous, and known at the samples):

      y_k = a y_{k−1} + (1 − a) u_{k−1} + b (u_k − u_{k−1}),  a = exp(−T/τ),  b = 1 − (τ/T)(1 − a)

  (so a ramp u = c t from y = 0 reads c (t_k − τ (1 − exp(−t_k/τ))) at t_k: the continuous filter's response; as
  f_c grows the reading tends to u_k, with no lag left). The filter starts at the first reading (no start
  transient). The generalized contact force on the joints
  (``ControlInput.tau_contact``) is passed through unfiltered and without noise.
- joint encoders, on the joint positions q [rad or m]: quantised to their resolution r, q = r·round(q/r)
  (the controller's kinematics — tip position, Jacobian, H — are then computed at the quantised q; joint
  velocities are read exactly).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

__all__ = ["SensorSpec", "ForceSensor", "quantise", "read_sensor", "Sampling", "read_sampling", "MAX_SAMPLE_RATE",
           "MIN_SAMPLE_RATE", "MIN_RESOLUTION", "MIN_CUTOFF", "MAX_DELAY", "HOLDS"]


@dataclass(frozen=True)
class SensorSpec:
    """A sampled controller's sensors (``[controller.sensor]``); the defaults measure exactly."""

    force_noise: float = 0.0  #: [N] standard deviation of the force reading's Gaussian noise
    force_bias: float = 0.0  #: [N] constant offset of every force reading
    force_cutoff: float = math.inf  #: [Hz] first-order low-pass cut-off (inf: no filter)
    encoder_resolution: float = 0.0  #: [rad or m] joint position quantum (0: exact)
    seed: int = 0  #: seed of the noise's random generator

    @property
    def exact_forces(self) -> bool:
        return self.force_noise == 0.0 and self.force_bias == 0.0 and math.isinf(self.force_cutoff)


def read_sensor(r) -> SensorSpec:
    """The ``sensor`` table of a controller (``r``: its Reader)."""
    spec = SensorSpec(
        force_noise=r.float("force_noise", 0.0, lo=0.0, unit="N"),
        force_bias=r.float("force_bias", 0.0, unit="N"),
        force_cutoff=r.float("force_cutoff", math.inf, lo=0.0, lo_open=True, unit="Hz"),
        encoder_resolution=r.float("encoder_resolution", 0.0, lo=0.0, unit="rad or m"),
        seed=r.int("seed", 0, lo=0),
    )
    if 0.0 < spec.encoder_resolution < MIN_RESOLUTION:  # (q / resolution would overflow)
        raise r.error("encoder_resolution", f"0 (exact) or a resolution >= {MIN_RESOLUTION:g} [rad or m]",
                      spec.encoder_resolution)
    if spec.force_cutoff < MIN_CUTOFF:  # (τ/T = 1/(2π f_c T) would overflow: a filter of NaN readings)
        raise r.error("force_cutoff", f"a cut-off >= {MIN_CUTOFF:g} Hz (or none: no filter)", spec.force_cutoff)
    r.finish()
    return spec


def quantise(q: np.ndarray, resolution: float) -> np.ndarray:
    """q [rad or m] as an encoder of ``resolution`` reads it (the nearest multiple; 0: exact)."""
    return resolution * np.round(q / resolution) if resolution > 0.0 else q


class ForceSensor:
    """The force/torque sensor of one run of a sampled phase: its noise generator and filter state."""

    def __init__(self, spec: SensorSpec, period: float, stream: int = 0):
        self.spec = spec
        self.filtered = math.isfinite(spec.force_cutoff)  #: a low-pass on the readings
        tau_over_T = 1.0 / (2.0 * math.pi * spec.force_cutoff * period) if self.filtered else 0.0  # [-] τ / T
        self.a = math.exp(-1.0 / tau_over_T) if self.filtered else 0.0  #: the low-pass's decay over one period T [s]
        self.b = 1.0 - tau_over_T * (1.0 - self.a)  #: its weight on the last period's change of the reading
        self.rng = np.random.default_rng([spec.seed, stream])  #: one stream per phase, seeded by the scene
        self.state: dict[str, float] | None = None  #: filter output y_{k-1} [N] per force key
        self.last: dict[str, float] | None = None  #: raw reading u_{k-1} [N] per force key

    def read(self, forces: dict[str, float]) -> dict[str, float]:
        """The readings [N] of the true ``forces`` [N] at this sample (keys in a fixed order: the draws too)."""
        if self.spec.exact_forces:
            return forces
        keys = sorted(forces)
        noise = self.rng.normal(0.0, self.spec.force_noise, len(keys)) if self.spec.force_noise > 0.0 \
            else np.zeros(len(keys))
        raw = {k: forces[k] + self.spec.force_bias + float(n) for k, n in zip(keys, noise, strict=True)}
        if not self.filtered:
            return raw
        if self.state is None:  # the filter starts at the first reading
            self.state, self.last = dict(raw), dict(raw)
            return dict(raw)
        a, b, state = self.a, self.b, {}
        for k in keys:  # (a key first read now starts from its reading: y = u_{k−1} = u_k)
            y, u0 = self.state.get(k, raw[k]), self.last.get(k, raw[k])
            state[k] = a * y + (1.0 - a) * u0 + b * (raw[k] - u0)
        self.state, self.last = state, raw
        return dict(state)


MAX_SAMPLE_RATE = 1e6  #: [Hz] sample_rate at most
MIN_SAMPLE_RATE = 1e-6  #: [Hz] a positive sample_rate at least (a period of 11.6 days; 1 / 5e-324 is inf)
MIN_RESOLUTION = 1e-12  #: [rad or m] a positive encoder_resolution at least
MIN_CUTOFF = 1e-6  #: [Hz] force_cutoff at least (with a period >= 1 / MAX_SAMPLE_RATE: τ/T <= 1.6e11, finite)
MAX_DELAY = 10_000  #: [samples] delay at most
#: what the zero-order hold keeps between samples: the law's command as it gives it (torques, or a voltage law's
#: voltages), or a torque law's command turned into its motors' voltages at the sample (a drive with no current loop)
HOLDS = ("command", "voltage")


@dataclass(frozen=True)
class Sampling:
    """How a phase's controller is sampled (beside the kind's own config: ``PhaseSpec.sampling``)."""

    rate: float  #: [Hz] samples per second
    delay: int = 0  #: [samples] measurement delay
    sensor: SensorSpec = field(default_factory=SensorSpec)
    hold: str = "command"  #: what the hold keeps (:data:`HOLDS`)

    @property
    def period(self) -> float:
        """[s] T = 1 / rate."""
        return 1.0 / self.rate


def read_sampling(r) -> Sampling | None:
    """``sample_rate``, ``delay``, ``hold`` and the ``sensor`` table of a controller table (``r``: its Reader), read
    before the kind's own keys; None for a continuous controller. ``sample_rate = 0`` turns a scene's sampled loop off
    (one override, ``--set controller.sample_rate=0``: its delay and sensors are still checked, and unused)."""
    rate = r.float("sample_rate", None, lo=0.0, hi=MAX_SAMPLE_RATE, unit="Hz")
    delay = r.int("delay", 0, lo=0, hi=MAX_DELAY, unit="samples")
    hold = r.str("hold", HOLDS[0], choices=HOLDS)
    has_sensor = r.has("sensor")
    sensor = read_sensor(r.sub("sensor", {}))
    if rate == 0.0:
        return None
    if rate is not None and rate < MIN_SAMPLE_RATE:
        raise r.error("sample_rate", f"0 (continuous) or a rate >= {MIN_SAMPLE_RATE:g} Hz", rate)
    if rate is None:
        if delay:
            raise r.error("delay", "no delay for a continuous controller (a delay counts samples: set sample_rate)",
                          delay)
        if has_sensor:
            raise r.error("sensor", "no sensor table for a continuous controller (sensors are read at the samples: "
                          "set sample_rate)", r.data["sensor"])
        if r.has("hold"):
            raise r.error("hold", "no hold for a continuous controller (it holds between samples: set sample_rate)",
                          hold)
        return None
    return Sampling(rate, delay, sensor, hold)
