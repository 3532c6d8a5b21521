"""Stability of a sampled, delayed contact loop: the z-domain poles of the simulator's own linearisation.

A sampled controller (``controller.sample_rate`` [Hz], ``controller.delay`` [samples]) evaluates its
law at the sample instants t_k = k h (h = 1 / rate [s]) on the measurement of t_{k−d} and holds the
command until t_{k+1} (zero-order hold). About the contact phase's equilibrium (the continuous loop's,
:class:`~contactdyn.analysis.stability.ContactLoop`: the hold changes nothing at a fixed point) the
loop is linear time-invariant in the sample index, in three pieces, each read off the simulator's own
functions by central differences:

- the plant with the command held, ẋ = A x + B u: ``System.evaluate`` with the phase's controller
  replaced by one that returns u (:class:`HeldCommand`); A = ∂f/∂x, B = ∂f/∂u. Its states are the
  ones something depends on (accumulators and the controller's own states, frozen between samples,
  drop out), as in :mod:`~contactdyn.analysis.stability`;
- the controller: what it reads at t_k (:func:`measured_input`: the state and the contact forces
  with the command *held from the previous sample*, the force a sensor reads at t_k) through its own
  ``command``: (τ, ż) = G(m, z) with the measurement m = (x, u_prev); K = ∂τ/∂m, K_z = ∂τ/∂z and
  L = ∂ż/∂m, L_z = ∂ż/∂z. Its states advance once per sample, z_{k+1} = z_k + h ż (forward Euler);
  a state nothing reads (A10's integral under a massless nominal) is left out, as an accumulator;
- the exact zero-order-hold discretisation (:func:`zoh`): Φ = e^{Ah}, Γ = ∫₀ʰ e^{As} ds B from one
  matrix exponential of [[A, B], [0, 0]] h.

The delay is d blocks of the state, a shift register of past measurements (:func:`closed_loop`):
ξ_k = [x_k, u_{k−1}, z_k, m_{k−1}, …, m_{k−d}], u_k = K m_{k−d} + K_z z_k, x_{k+1} = Φ x_k + Γ u_k.
The loop's z-domain poles are the eigenvalues of that map, without the bonds' constraint-drift
modes (e^{−ωh}, ω = ``stability.BAUMGARTE``: uncontrollable, they stay where Φ puts them); it is
stable when every |z| < 1, and σ = ln|z_max| / h [1/s] is its decay rate (negative: decays),
comparable with a continuous pole's real part (and with a run's, :func:`measured_rate`).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
from scipy.linalg import expm

from ..laws.controllers import Controller
from ..model import dynamics
from ..model.constraints import Rows
from .stability import BAUMGARTE, ContactLoop, modal_poles

__all__ = ["HeldCommand", "SampledLinearization", "SampledLoop", "zoh", "closed_loop", "decay_rate",
           "measured_input", "measured_rate"]

_FD_STEP = 1e-6  #: relative central-difference step (as stability.py's)


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


class HeldCommand(Controller):
    """A controller that returns a fixed command (the held one) and freezes the law's own states."""

    name = "held_command"

    def __init__(self, tau: np.ndarray, n_states: int, outputs: str = "torque"):
        super().__init__(None, len(tau))
        self.tau = np.asarray(tau, float)
        self.n_states = n_states
        self.outputs = outputs

    def command(self, inp):
        return self.tau.copy(), (np.zeros(self.n_states) if self.n_states else None)


def measured_input(loop: ContactLoop, t: float, x: np.ndarray, held: np.ndarray):
    """The controller's input at (t, x) with the command ``held`` acting: the state as it is and the
    contact forces the held command makes (a bond's force comes from the linear solve, so it depends
    on the command that acts, the previous sample's), the contacts' generalized force on the joints
    τ_c = H q̈ + h − τ [N·m or N] from the same solve (robot with ideal drives, no limits pressing)."""
    system, phase, modes = loop.system, loop.phase, loop.modes
    held_phase = replace(phase, controller=HeldCommand(held, phase.controller.n_states, phase.controller.outputs))
    ev = system.evaluate(t, x, modes, held_phase)
    nQ, nv = system.nQ, system.nv
    system.robot.update(x[:nv], x[nQ:nQ + nv])
    f = np.zeros(nQ)
    f[:nv] = -system.robot.h
    pre = dynamics.Evaluation(np.empty(0), np.empty(0), [], {}, {}, {}, {}, {}, {}, np.empty(0), np.empty(0),
                              np.empty(0), None, {})
    kins, _ = dynamics._contact_terms(system, x, modes, f, np.zeros(system.ny), Rows(), pre, False)
    inp, *_ = dynamics._control_input(system, t, x, modes, phase, f, kins, pre)
    inp.forces = {**ev.normal_force, **ev.interface}
    if phase.controller.uses_forces:
        qdd = ev.xdot[nQ:nQ + nv]
        inp.tau_contact = system.robot.H @ qdd + system.robot.h - ev.tau
    return inp


@dataclass(frozen=True)
class SampledLinearization:
    """The pieces of the sampled loop about the equilibrium (deviation variables)."""

    x: np.ndarray  #: equilibrium state (all slots)
    u: np.ndarray  #: equilibrium command [N·m or N]
    plant: np.ndarray  #: indices of the plant's states (something depends on them)
    zs: np.ndarray  #: indices of the controller's own states
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
        """z-domain poles at ``rate`` [Hz] and ``delay`` [samples], the constraint-drift ones dropped."""
        z = np.linalg.eigvals(self.transition(rate, delay))
        drift = np.argsort(np.abs(z - np.exp(-BAUMGARTE / rate)))[: self.n_drift]
        return np.delete(z, drift)

    def dominant(self, rate: float, delay: int) -> complex:
        """The pole of largest modulus."""
        z = self.poles(rate, delay)
        return complex(z[int(np.argmax(np.abs(z)))])

    def sigma(self, rate: float, delay: int) -> float:
        """Decay rate σ = ln|z_max| · rate [1/s] (negative: decays)."""
        return decay_rate(self.dominant(rate, delay), 1.0 / rate)

    def map(self, rates: np.ndarray, delays: np.ndarray) -> np.ndarray:
        """σ [1/s] over a grid: entry [i, j] at delays[i], rates[j]."""
        return np.array([[self.sigma(float(f), int(d)) for f in rates] for d in delays])


class SampledLoop:
    """A scene's contact phase (:class:`ContactLoop`) linearised as a sampled loop."""

    def __init__(self, loop: ContactLoop):
        self.loop = loop

    def linearize(self, x_guess: np.ndarray | None = None) -> SampledLinearization:
        """The pieces about the continuous loop's equilibrium (the hold keeps it), Newton from ``x_guess``."""
        loop = self.loop
        lin = loop.linearize(x_guess)
        x = lin.x
        system, phase = loop.system, loop.phase
        nQ, nv = system.nQ, system.nv
        ctl = phase.controller
        z0 = 2 * nQ + phase.z_slice.start
        zs = np.arange(z0, z0 + ctl.n_states)
        u = self._command(x, np.zeros(nv))[0]  # first pass: the forces of some held command...
        for _ in range(50):  # ...then of the command itself (a fixed point: u = G(x, u))
            u_new = self._command(x, u)[0]
            if np.max(np.abs(u_new - u)) <= 1e-12 * max(1.0, float(np.max(np.abs(u)))):
                break
            u = u_new
        A_full, B_full = self._plant_jacobians(x, u)
        plant = np.setdiff1d(np.flatnonzero(np.any(A_full != 0.0, axis=0)), zs)  # accumulators: no column
        A, B = A_full[np.ix_(plant, plant)], B_full[plant]
        K, K_z, L, L_z = self._controller_jacobians(x, u, plant, zs)
        read = np.flatnonzero(np.any(K_z != 0.0, axis=0) | np.any(L_z != 0.0, axis=0))  # states the law reads
        zs, K_z, L, L_z = zs[read], K_z[:, read], L[read], L_z[np.ix_(read, read)]
        return SampledLinearization(x, u, plant, zs, A, B, K, K_z, L, L_z, 2 * loop.n_bond_rows, lin.poles)

    def _held_rate(self, x: np.ndarray, u: np.ndarray) -> np.ndarray:
        loop = self.loop
        ctl = loop.phase.controller
        phase = replace(loop.phase, controller=HeldCommand(u, ctl.n_states, ctl.outputs))
        return loop.system.evaluate(loop.t_eq, x, loop.modes, phase).xdot

    def _command(self, x: np.ndarray, held: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(τ, ż) of the phase's controller on the measurement at (t_eq, x) with ``held`` acting."""
        ctl = self.loop.phase.controller
        tau, zdot = ctl.command(measured_input(self.loop, self.loop.t_eq, x, held))
        return np.asarray(tau, float)[: len(held)], (np.zeros(0) if zdot is None else np.asarray(zdot, float))

    def _plant_jacobians(self, x: np.ndarray, u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        n, p = len(x), len(u)
        A, B = np.empty((n, n)), np.empty((n, p))
        for j in range(n):
            step = _FD_STEP * max(1.0, abs(x[j]))
            xp, xm = x.copy(), x.copy()
            xp[j] += step
            xm[j] -= step
            A[:, j] = (self._held_rate(xp, u) - self._held_rate(xm, u)) / (2.0 * step)
        for j in range(p):
            step = _FD_STEP * max(1.0, abs(u[j]))
            up, um = u.copy(), u.copy()
            up[j] += step
            um[j] -= step
            B[:, j] = (self._held_rate(x, up) - self._held_rate(x, um)) / (2.0 * step)
        return A, B

    def _controller_jacobians(self, x: np.ndarray, u: np.ndarray, plant: np.ndarray, zs: np.ndarray):
        """K, K_z, L, L_z: the command's and the states' rates' derivatives by the measurement [x (plant),
        u_prev] and by the controller's states."""
        p, r = len(u), len(zs)
        columns = [("x", int(i)) for i in plant] + [("u", j) for j in range(p)] + [("x", int(i)) for i in zs]
        D_tau, D_zdot = np.empty((p, len(columns))), np.empty((r, len(columns)))
        for c, (what, i) in enumerate(columns):
            base = x if what == "x" else u
            step = _FD_STEP * max(1.0, abs(base[i]))
            outs = []
            for sign in (1.0, -1.0):
                xv, uv = x.copy(), u.copy()
                (xv if what == "x" else uv)[i] += sign * step
                outs.append(self._command(xv, uv))
            D_tau[:, c] = (outs[0][0] - outs[1][0]) / (2.0 * step)
            D_zdot[:, c] = (outs[0][1] - outs[1][1]) / (2.0 * step)
        m = len(plant) + p
        return D_tau[:, :m], D_tau[:, m:], D_zdot[:, :m], D_zdot[:, m:]


def measured_rate(t: np.ndarray, err: np.ndarray, z: complex, h: float) -> float:
    """Decay rate [1/s] of the run's own mode (matrix pencil, :func:`stability.modal_poles`) whose
    frequency is nearest the z-domain pole z's (angle(z) / h), from a signal sampled at the period h [s]."""
    found = modal_poles(t, err)
    w = abs(np.angle(z)) / h
    return float(found[int(np.argmin(np.abs(np.abs(found.imag) - w)))].real)
