"""Stability of a sampled, delayed contact loop: the z-domain poles of the simulator's own sampled control.

A sampled controller (``controller.sample_rate`` [Hz], ``controller.delay`` [samples];
:mod:`contactdyn.laws.controllers.sampled`) evaluates its law at the sample instants t_k = k h (h = 1 / rate [s])
on what it measured at t_{k−d} and holds the command until t_{k+1} (zero-order hold); the held command is
a slot of the state. About the contact phase's equilibrium (the continuous loop's,
:class:`~contactdyn.analysis.stability.ContactLoop`: the hold changes nothing at a fixed point) the loop is
linear time-invariant in the sample index, in three pieces, each read off the simulator's own functions (the
scene run sampled) by central differences:

- the plant with the command held, ẋ = A x + B u: the sampled phase's pipeline call, whose command is
  the held slots u of the state; A = ∂f/∂x, B = ∂f/∂u. Its states are the ones something depends on
  (accumulators, the held slots and the law's own states, constant between samples, drop out), as in
  :mod:`~contactdyn.analysis.stability`;
- the law at a sample: what it measures at t_k (:class:`~contactdyn.hybrid.sampled_law.SampledLaw`, as the
  hybrid loop takes a sample: the state, and the contact forces under the command held so far, u_{k−1}) through
  its own controller stage: (τ, ż) = G(m, z) with the measurement m = (x, u_prev); K = ∂τ/∂m, K_z = ∂τ/∂z and
  L = ∂ż/∂m, L_z = ∂ż/∂z. Its states advance once per sample, z_{k+1} = z_k + h ż (forward Euler, as
  ``Sampler.update``); a state nothing reads (A10's integral under a massless nominal) is left out;
- the exact zero-order-hold discretisation (:func:`zoh`): Φ = e^{Ah}, Γ = ∫₀ʰ e^{As} ds B from one
  matrix exponential of [[A, B], [0, 0]] h.

The delay is d blocks of the state, a shift register of past measurements (:func:`closed_loop`, the
sampler's delay line): ξ_k = [x_k, u_{k−1}, z_k, m_{k−1}, …, m_{k−d}], u_k = K m_{k−d} + K_z z_k,
x_{k+1} = Φ x_k + Γ u_k. The loop's z-domain poles are the eigenvalues of that map, without the bonds'
constraint-drift modes (e^{−ωh}, ω = ``stability.BAUMGARTE``: uncontrollable, they stay where Φ puts them); it
is stable when every |z| < 1, and σ = ln|z_max| / h [1/s] is its decay rate (negative: decays), comparable with
a continuous pole's real part and with a run's (:func:`measured_rate`). The pieces do not depend on the rate
or the delay, so one linearisation gives the whole map. The sensors must measure exactly (a filter or noise
is not in the model).
"""

from __future__ import annotations

import copy
from dataclasses import dataclass

import numpy as np
from scipy.linalg import expm

from ..errors import SimulationError
from ..hybrid.sampled_law import SampledLaw, sampled_slots
from ..laws.controllers.sampled import SampledController
from ..model.system import System
from ..output.result import Result
from ..scene.scene_file import Scene, parse_scene
from ..simulate import run_system
from .stability import BAUMGARTE, ContactLoop, modal_poles

__all__ = ["SampledLinearization", "SampledLoop", "zoh", "closed_loop", "decay_rate", "measured_rate",
           "sampled_scene", "continuous_scene", "with_tip_velocity", "run_from",
           "linear_window"]

_FD_STEP = 1e-6  #: relative central-difference step (as stability.py's)
FIXED_POINT_ITERATIONS = 20  #: Newton steps for the held command's fixed point (the map is near-affine: 2–3 do)
_SAMPLING_KEYS = ("sample_rate", "delay", "sensor", "hold")


def continuous_scene(scene: Scene) -> Scene:
    """The scene with its controllers continuous (every table's ``sample_rate``, ``delay``, ``sensor`` and ``hold``
    gone)."""
    doc = copy.deepcopy(scene.document)
    for table in [doc.get("controller"), *(p.get("controller") for p in doc.get("phase", []))]:
        if isinstance(table, dict):
            for key in _SAMPLING_KEYS:
                table.pop(key, None)
    return parse_scene(doc, None, scene.file)


def sampled_scene(scene: Scene, rate: float, delay: int = 0) -> Scene:
    """The scene with its controller sampled at ``rate`` [Hz] with ``delay`` [samples] (the phases' own
    controller tables keep theirs)."""
    return parse_scene(scene.document, {"controller.sample_rate": float(rate), "controller.delay": int(delay)},
                       scene.file)


def zoh(A: np.ndarray, B: np.ndarray, h: float) -> tuple[np.ndarray, np.ndarray]:
    """Exact zero-order-hold discretisation at period h [s]: (Φ = e^{Ah}, Γ = ∫₀ʰ e^{As} ds B), from
    e^{M h} with M = [[A, B], [0, 0]] (its top row blocks are Φ and Γ)."""
    n, m = B.shape
    M = np.zeros((n + m, n + m))
    M[:n, :n], M[:n, n:] = A, B
    E = expm(M * h)
    return E[:n, :n], E[:n, n:]


def closed_loop(Phi: np.ndarray, Gamma: np.ndarray, K: np.ndarray, K_z: np.ndarray, L: np.ndarray,
                L_z: np.ndarray, h: float, delay: int) -> np.ndarray:
    """The sampled loop's transition matrix over one period h [s] with a delay of ``delay`` samples.

    State ξ_k = [x_k, u_{k−1}, z_k, m_{k−1}, …, m_{k−d}] with the measurement m_j = [x_j, u_{j−1}]
    (the plant's state at t_j and the command held when it was read); the controller reads m_{k−d}:
    u_k = K m_{k−d} + K_z z_k, z_{k+1} = z_k + h (L m_{k−d} + L_z z_k), x_{k+1} = Φ x_k + Γ u_k.
    Shapes: Φ (n, n), Γ (n, p), K (p, n + p), K_z (p, r), L (r, n + p), L_z (r, r)."""
    n, p = Gamma.shape
    r = K_z.shape[1]
    nm = n + p
    size = nm + r + delay * nm
    T = np.zeros((size, size))
    xs, us, zs = slice(0, n), slice(n, nm), slice(nm, nm + r)
    now = np.zeros((nm, size))  # m_k as a row map of ξ_k
    now[:, :nm] = np.eye(nm)
    read = now if delay == 0 else np.zeros((nm, size))  # m_{k−d}
    if delay:
        start = nm + r + (delay - 1) * nm
        read[:, start:start + nm] = np.eye(nm)
    U = K @ read  # u_k as a row map of ξ_k
    U[:, zs] += K_z
    T[xs, xs] = Phi
    T[xs] += Gamma @ U
    T[us] = U
    T[zs, zs] = np.eye(r) + h * L_z
    T[zs] += h * (L @ read)
    if delay:  # shift register: m_k enters the first block, the others move one down
        T[nm + r:nm + r + nm] = now
        for j in range(1, delay):
            a = nm + r + j * nm
            T[a:a + nm, a - nm:a] = np.eye(nm)
    return T


def decay_rate(z: complex, h: float) -> float:
    """σ = ln|z| / h [1/s] of a z-domain pole at period h [s] (negative: decays)."""
    return float(np.log(max(abs(z), 1e-300)) / h)


@dataclass(frozen=True)
class SampledLinearization:
    """The pieces of the sampled loop about the equilibrium (deviation variables)."""

    x: np.ndarray  #: equilibrium state of the sampled scene (all slots, the held command's too)
    u: np.ndarray  #: equilibrium command [N·m or N]
    plant: np.ndarray  #: indices of the plant's states (something depends on them)
    held: np.ndarray  #: indices of the held command's slots
    zs: np.ndarray  #: indices of the law's own states that it reads
    A: np.ndarray  #: ∂ẋ/∂x on the plant's states, command held [1/s...]
    B: np.ndarray  #: ∂ẋ/∂u
    K: np.ndarray  #: ∂τ/∂m, m = [x (plant), u_prev]
    K_z: np.ndarray  #: ∂τ/∂z
    L: np.ndarray  #: ∂ż/∂m
    L_z: np.ndarray  #: ∂ż/∂z
    n_drift: int  #: constraint-drift poles to drop (two per bond row)
    continuous: np.ndarray  #: the continuous loop's poles (stability.ContactLoop) [1/s]

    def transition(self, rate: float, delay: int) -> np.ndarray:
        """The loop's one-period map at ``rate`` [Hz] with ``delay`` [samples] (:func:`closed_loop`)."""
        h = 1.0 / rate
        Phi, Gamma = zoh(self.A, self.B, h)
        return closed_loop(Phi, Gamma, self.K, self.K_z, self.L, self.L_z, h, delay)

    def poles(self, rate: float, delay: int) -> np.ndarray:
        """z-domain poles at ``rate`` [Hz] and ``delay`` [samples], the constraint-drift ones dropped, largest
        modulus first."""
        z = np.linalg.eigvals(self.transition(rate, delay))
        drift = np.argsort(np.abs(z - np.exp(-BAUMGARTE / rate)))[: self.n_drift]
        z = np.delete(z, drift)
        return z[np.argsort(-np.abs(z), kind="stable")]

    def dominant(self, rate: float, delay: int) -> complex:
        """The pole of largest modulus."""
        return complex(self.poles(rate, delay)[0])

    def sigma(self, rate: float, delay: int) -> float:
        """Decay rate σ = ln|z_max| · rate [1/s] (negative: decays)."""
        return decay_rate(self.dominant(rate, delay), 1.0 / rate)

    def map(self, rates: np.ndarray, delays: np.ndarray) -> np.ndarray:
        """σ [1/s] over a grid: entry [i, j] at delays[i], rates[j]."""
        return np.array([[self.sigma(float(f), int(d)) for f in rates] for d in delays])


class SampledLoop:
    """A scene's contact phase (see :func:`~contactdyn.analysis.stability.contact_phase_scene`) run sampled,
    linearised as a sampled loop. The scene may be sampled or not: the pieces do not depend on the rate or the
    delay (a continuous scene is linearised at 1 kHz, its own controller's sensors)."""

    def __init__(self, scene: Scene, t_eq: float = 10.0):
        if scene.phases[-1].sampling is None:
            scene = sampled_scene(scene, 1000.0)
        sensor = scene.phases[-1].sampling.sensor
        if not sensor.exact_forces or sensor.encoder_resolution > 0.0:
            raise ValueError("SampledLoop: the sensors must measure exactly (no force noise, bias or filter, "
                             f"no encoder quantum): {sensor}")
        self.loop = ContactLoop(scene, t_eq)  #: the sampled phase (its state has the held command)
        self.continuous = ContactLoop(continuous_scene(scene), t_eq)  #: the same phase continuous
        self._law: SampledLaw | None = None  #: the law at a sample on the loop's mode (hybrid.sampled_law)
        assert isinstance(self.loop.phase.controller, SampledController)

    def equilibrium(self, x_guess: np.ndarray | None = None):
        """(the continuous loop's Linearization from ``x_guess`` (its layout), that equilibrium in the sampled
        layout with the held command its fixed point u = G(m(x, u)))."""
        lin = self.continuous.linearize(x_guess)
        system, phase = self.loop.system, self.loop.phase
        ctl = phase.controller
        at = 2 * system.nQ + self.continuous.phase.z_slice.start  # the held slots come first in the phase's states
        x = np.insert(lin.x, at, np.zeros(ctl.nv))
        assert len(x) == system.n and at == 2 * system.nQ + phase.z_slice.start
        held = np.arange(at, at + ctl.nv)
        x[held] = self._command(x)[0]
        for _ in range(FIXED_POINT_ITERATIONS):  # the forces measured under the command itself: Newton on u − G(u)
            residual = self._command(x)[0] - x[held]
            if np.max(np.abs(residual)) <= 1e-12 * max(1.0, float(np.max(np.abs(x[held])))):
                return lin, x
            slope = self._jacobian(lambda xv: self._command(xv)[0], x, held) - np.eye(len(held))
            x[held] -= np.linalg.solve(slope, residual)
        raise SimulationError(f"SampledLoop: the held command found no fixed point u = G(m(x, u)) in "
                              f"{FIXED_POINT_ITERATIONS} Newton steps (last residual {np.max(np.abs(residual)):.3g})")

    def linearize(self, x_guess: np.ndarray | None = None) -> SampledLinearization:
        """The pieces about the continuous loop's equilibrium (the hold keeps it), Newton from ``x_guess``
        (the continuous scene's layout)."""
        lin, x = self.equilibrium(x_guess)
        held, zs = (np.arange(part.start, part.stop) for part in sampled_slots(self.loop.system, self.loop.phase))
        A_full = self._jacobian(lambda xv: self.loop.rate(xv), x, np.arange(len(x)))
        plant = np.setdiff1d(np.flatnonzero(np.any(A_full != 0.0, axis=0)), np.concatenate([held, zs]))
        A, B = A_full[np.ix_(plant, plant)], A_full[np.ix_(plant, held)]
        read = np.concatenate([plant, held, zs])
        D_tau = self._jacobian(lambda xv: self._command(xv)[0], x, read)
        D_zdot = self._jacobian(lambda xv: self._command(xv)[1], x, read)
        m = len(plant) + len(held)
        K, K_z, L, L_z = D_tau[:, :m], D_tau[:, m:], D_zdot[:, :m], D_zdot[:, m:]
        used = np.flatnonzero(np.any(K_z != 0.0, axis=0) | np.any(L_z != 0.0, axis=0))  # states the law reads
        return SampledLinearization(x, x[held].copy(), plant, held, zs[used], A, B, K, K_z[:, used], L[used],
                                    L_z[np.ix_(used, used)], 2 * self.loop.n_bond_rows, lin.poles)

    def _command(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(τ, ż) of the sampled law on what it measures at (t_eq, x) (the held slots of x acting)."""
        loop = self.loop
        if self._law is None:  # (what the loop measures: the mode's call; the law's own stage on it)
            self._law = SampledLaw(loop.mode)
        x = np.array(x, float)
        tau, zdot = self._law.command(self._law.reading(loop.t_eq, x), x[self._law.states])
        return tau, zdot

    @staticmethod
    def _jacobian(fun, x: np.ndarray, columns: np.ndarray) -> np.ndarray:
        """∂fun/∂x[columns] by central differences."""
        out = None
        for c, i in enumerate(columns):
            step = _FD_STEP * max(1.0, abs(x[i]))
            xp, xm = x.copy(), x.copy()
            xp[i] += step
            xm[i] -= step
            col = (np.asarray(fun(xp)) - np.asarray(fun(xm))) / (2.0 * step)
            if out is None:
                out = np.empty((len(col), len(columns)))
            out[:, c] = col
        return out


def measured_rate(t: np.ndarray, err: np.ndarray, z: complex, h: float) -> tuple[float, float]:
    """(decay rate [1/s], frequency [Hz]) of the run's own mode (matrix pencil, :func:`stability.modal_poles`)
    whose frequency is nearest the z-domain pole z's (|angle(z)| / h), from a signal sampled at the period h [s]."""
    found = modal_poles(t, err)
    w = abs(np.angle(z)) / h
    pole = found[int(np.argmin(np.abs(np.abs(found.imag) - w)))]
    return float(pole.real), float(abs(pole.imag) / (2.0 * np.pi))


def with_tip_velocity(loop: ContactLoop, x: np.ndarray, v_tip: np.ndarray) -> np.ndarray:
    """x with the robot's joint velocities those that move the tip at ``v_tip`` [m/s] (least squares on the tip's
    Jacobian at x's joint positions): an equilibrium of a frozen reference started sliding with a moving one."""
    system = loop.system
    nQ, nv = system.nQ, system.nv
    out = x.copy()
    system.robot.update(x[:nv], np.zeros(nv))
    J = system.robot.frame_terms(system.tip_fid).jacobian
    out[nQ:nQ + nv] = np.linalg.lstsq(J, np.asarray(v_tip, float), rcond=None)[0]
    return out


def run_from(scene: Scene, x0: np.ndarray) -> Result:
    """A run of ``scene`` started from the state ``x0`` (the scene's layout) with the modes its own start finds
    (the hybrid loop then makes them consistent and, sampled, takes its first sample there)."""
    system = System(scene)
    own_start = system.initial_state

    def initial_state():
        x, modes = own_start()
        if len(x) != len(x0):
            raise ValueError(f"run_from: a state of {len(x)} slots for this scene, got {len(x0)}")
        return np.array(x0, float), modes

    system.initial_state = initial_state
    return run_system(system)


def linear_window(result: Result, t_fit: float, limit: float) -> tuple[np.ndarray, np.ndarray]:
    """(t [s], F_n − F_d [N]) of a run's first contact from ``t_fit`` [s] up to the first sample where the loop
    stops being the linearised one: the error beyond ``limit`` [N], the contact lost, stuck, or its slip
    velocity turned (Coulomb's force then changes sign: the force loop's oscillation moves the tip along the
    surface too, so a slow slide reverses at a small force error)."""
    name = next(c.split(".")[1] for c in result.channels if c.startswith("contact.") and c.endswith(".F_n"))
    err = result[f"contact.{name}.F_n"] - result[f"contact.{name}.F_d"]
    keep = (np.abs(err) <= limit) & (result[f"contact.{name}.touching"] > 0.5)
    if f"contact.{name}.stuck" in result.channels:
        keep &= result[f"contact.{name}.stuck"] < 0.5
        slip = np.asarray(result[f"contact.{name}.v_slip"]).reshape(len(err), -1)
        keep &= np.all(slip * slip[:1] > 0.0, axis=1)  # every tangent's slip as at the start
    keep |= result.t < t_fit
    end = int(np.argmin(keep)) if not np.all(keep) else len(err)
    sel = np.flatnonzero(result.t[:end] >= t_fit)
    return result.t[sel], err[sel]
