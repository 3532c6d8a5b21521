"""Integrators for the smooth phases: scipy's ``solve_ivp`` methods by name, ``auto``, ``RK4``, ``DOP853C``.

``DOP853C`` (the default) is DOP853 stepped by scipy's compiled core (:mod:`contactdyn.numerics.dop853`):
the same method, the same steps and events as ``solve_ivp``'s ``DOP853`` (which stays selectable),
at a fraction of its per-step cost. It alone takes a sampled controller's sample instants as step boundaries
inside one run (``integrate``'s ``hold``, :mod:`contactdyn.numerics.held_steps`); the hybrid loop ends a
segment at each for the other methods.

``RK4`` is the classical fixed-step Runge–Kutta method (4 calls per step, :mod:`.rk4`) with step
``solver.max_step`` [s] (required), cubic Hermite dense output and scipy's event location:
the like-for-like comparison with fixed-step simulators (MuJoCo's RK4, Drake's discrete
plant). It has no error control: its error is whatever the step gives.

``auto`` detects stiffness by what the explicit method does, as LSODA does, rather than by
eigenvalues alone (a stiff mode that nothing excites, e.g. a relaxed massless surface end
of rate k/b = 1e5 1/s, costs an explicit method nothing). A segment starts with DOP853
(``AUTO_EXPLICIT``: the compiled one) and a budget of ``STEP_BUDGET`` steps. When the
budget runs out, the eigenvalues λ of the finite-difference Jacobian ∂f/∂x (n + 1 calls of
the compiled right-hand side) are compared with the step size h the method had reached: if
some mode decays within the rest of the segment (−Re λ · T ≥ ``DECAY_SPAN``) and h|λ| lies
in ``STABILITY_BAND`` — the step is held at the edge of DOP853's stability region, not set
by accuracy — the rest of the segment runs with Radau IIA (order 5, L-stable) and the same
finite-difference Jacobian; else DOP853 goes on without a budget. A fast mode that does
not decay (an undamped stiff contact ringing) must be resolved by either method, and
DOP853's steps are cheaper. A step held at the scene's ``max_step`` is not stability-bound (Radau's is bounded
by it too); under a sampled law's hold the step judged is the longest of the budget's last ones (a step clipped to
a sample instant is shorter), and Radau is taken only where a sample period spans ``HOLD_SWITCH`` of them (Radau
ends a segment at every sample). Measured (docs/performance.md): near-rigid contact 1e8 N/m, 2
s: DOP853 1.9 s, Radau 0.32 s; 1e-3 kg equivalent mass: 4.0 s against 0.75 s; on scenes
without such modes ``auto`` is DOP853 and costs nothing more.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

from . import dop853, held_steps

__all__ = ["METHODS", "IMPLICIT", "EXPLICIT", "FIXED", "AUTO_EXPLICIT", "HOLD_SWITCH", "stability_bound",
           "jacobian_eigenvalues", "FiniteDifferenceJacobian", "integrate", "carries_hold"]

#: ``auto``, explicit Runge–Kutta methods and the implicit ones for stiff scenes
METHODS = ("auto", "DOP853", "DOP853C", "RK45", "RK23", "Radau", "BDF", "LSODA", "RK4")
EXPLICIT = ("DOP853", "DOP853C", "RK45", "RK23", "RK4")
COMPILED = ("DOP853C",)  #: run by contactdyn.numerics.dop853 rather than solve_ivp
AUTO_EXPLICIT = "DOP853C"  #: ``auto``'s method until the step budget says a segment is stiff
FIXED = ("RK4",)  #: fixed-step methods: the step is solver.max_step
IMPLICIT = ("Radau", "BDF", "LSODA")

STABILITY_RADIUS = 6.0  #: DOP853's stability region reaches about |hλ| ≈ 6 along the negative real axis [-]
STEP_BUDGET = 1000  #: DOP853 steps in a segment before ``auto`` checks for stiffness
RK4_RADIUS = 2.78  #: RK4 is stable for real hλ in [-2.78, 0] [-]
RK4_GROWTH = 1.001  #: a decaying mode amplified by more than this per step is an instability [-]
STABILITY_BAND = (0.5, 8.0)  #: h|λ| in this band: the step is stability-bound (measured 1.4–1.6 on stiff scenes)
DECAY_SPAN = 20.0  #: a mode "decays within the span" when −Re λ · T is at least this [-]
#: [-] under a sampled law's hold ``auto`` takes Radau only for an explicit step below 1/HOLD_SWITCH of the sample
#: period: Radau ends a segment at every sample, each costing ~45 compiled DOP853 steps
#: (benchmarks/stiff_force.toml at 1 kHz: 8.2 ms a sample against 0.18 ms a step); with a step near the period
#: either method takes a step or two
HOLD_SWITCH = 40.0


class FiniteDifferenceJacobian:
    """∂f/∂x by forward differences with fixed steps h_j = √ε · max(1, |x_j|): n calls of f.

    Given to Radau/BDF instead of scipy's adaptive ``num_jac``, which keeps enlarging the
    step of a column whose difference is zero (a state nothing depends on in this mode,
    such as a relaxation state of a touching contact) until it overflows.
    """

    def __init__(self, fun: Callable[[float, np.ndarray], np.ndarray]):
        self.fun = fun
        self.calls = 0  #: calls of f made for Jacobians

    def __call__(self, t: float, x: np.ndarray, f0: np.ndarray | None = None) -> np.ndarray:
        if f0 is None:
            f0 = np.asarray(self.fun(t, x), float)
            self.calls += 1
        n = len(x)
        jac = np.empty((n, n))
        for j in range(n):
            h = _SQRT_EPS * max(1.0, abs(float(x[j])))
            xp = x.copy()
            xp[j] += h
            jac[:, j] = (np.asarray(self.fun(t, xp), float) - f0) / h
        self.calls += n
        return jac


_SQRT_EPS = math.sqrt(np.finfo(float).eps)


def jacobian_eigenvalues(fun: Callable[[float, np.ndarray], np.ndarray], t: float, x: np.ndarray) -> np.ndarray:
    """Eigenvalues [1/s] of the finite-difference Jacobian ∂f/∂x at (t, x) (empty if not finite)."""
    jac = FiniteDifferenceJacobian(fun)(t, x)
    if not np.all(np.isfinite(jac)):
        return np.zeros(0)
    return np.linalg.eigvals(jac)


def stability_bound(fun: Callable[[float, np.ndarray], np.ndarray], t: float, x: np.ndarray, h: float,
                    span: float) -> tuple[bool, float]:
    """(is the explicit step h [s] stability-bound by a decaying mode, that mode's |λ| [1/s] or 0).

    ``span`` [s]: what remains of the segment; a mode counts if −Re λ · span ≥ DECAY_SPAN and
    h|λ| is in STABILITY_BAND.
    """
    lam = jacobian_eigenvalues(fun, t, x)
    if not len(lam) or span <= 0.0 or h <= 0.0:
        return False, 0.0
    size = np.abs(lam)
    stiff = (-lam.real * span >= DECAY_SPAN) & (h * size >= STABILITY_BAND[0]) & (h * size <= STABILITY_BAND[1])
    return bool(np.any(stiff)), float(size[stiff].max()) if np.any(stiff) else 0.0


def rk4_amplification(z: np.ndarray) -> np.ndarray:
    """|R(z)|: RK4's growth per step of a mode e^{λt} with z = hλ (R = 1 + z + z²/2 + z³/6 + z⁴/24)."""
    return np.abs(1 + z * (1 + z / 2 * (1 + z / 3 * (1 + z / 4))))


def fixed_step_instability(fun: Callable[[float, np.ndarray], np.ndarray], t: float, x: np.ndarray,
                           h: float) -> str | None:
    """Why RK4's step h [s] cannot work from (t, x), or None: a mode that does not grow (Re λ ≤ 0)
    but that the step amplifies by more than RK4_GROWTH per step. Names its period 2π/|λ| [s]."""
    lam = jacobian_eigenvalues(fun, t, x)
    bad = lam[(lam.real <= 0.0) & (rk4_amplification(h * lam) > RK4_GROWTH)] if len(lam) else lam
    if not len(bad):
        return None
    fast = bad[np.argmax(np.abs(bad))]
    size = float(abs(fast))
    return (f"the step {h:.3g} s is too large for the stiffest mode (|λ| = {size:.3g} 1/s, period "
            f"{2 * math.pi / size:.3g} s): RK4 amplifies it {float(rk4_amplification(h * fast)):.3g}× per step "
            f"where it decays; take solver.max_step below {RK4_RADIUS / size:.2g} s or an adaptive method")


def carries_hold(method: str) -> bool:
    """Does the method take a sampled controller's sample instants as step boundaries (``integrate``'s hold)?"""
    return method in COMPILED


def integrate(fun, t_span: tuple[float, float], y0: np.ndarray, method: str, *, rtol: float, atol: float,
              max_step: float = np.inf, events=None, first_step: float | None = None, jac=None, hold=None,
              checked: bool = False):
    """One smooth segment by the named method, with dense output and events (``solve_ivp``'s result fields).

    ``hold``: a sampled controller's hold whose sample instants are step boundaries inside the run
    (:mod:`contactdyn.numerics.held_steps`); the compiled DOP853 (``COMPILED``) only: ``carries_hold``.
    ``checked``: RK4's step was checked against this mode already (an earlier segment of it, ended by a sample or
    a corner): no check at the segment's start (its check on the state's growth stays)."""
    if hold is not None:
        if method not in COMPILED:
            raise ValueError(f"{method} does not carry a hold: its segments end at the sample instants")
        return held_steps.solve(fun, t_span, y0, rtol=rtol, atol=atol, max_step=max_step, events=events,
                                first_step=first_step, step=getattr(fun, "step", None), hold=hold)
    if method in COMPILED:  # a compiled mode's right-hand side brings its compiled step (contactdyn.hybrid.steps)
        return dop853.solve(fun, t_span, y0, rtol=rtol, atol=atol, max_step=max_step, events=events,
                            first_step=first_step, step=getattr(fun, "step", None))
    from scipy.integrate import solve_ivp  # (here: a run on the compiled DOP853 never imports scipy.integrate)

    from . import lsoda

    if method == "LSODA" and jac is None and lsoda.available():  # solve_ivp's steps without its per-step Python
        return lsoda.solve(fun, t_span, y0, rtol=rtol, atol=atol, max_step=max_step, events=events,
                           first_step=first_step)
    options = {"jac": jac} if jac else {}
    if method == "RK4":
        from .rk4 import RK4

        method, options = RK4, {"instability": fixed_step_instability, "check_start": not checked}
    method, events = _searching_steps(method, events or [])
    return solve_ivp(fun, t_span, y0, method=method, rtol=rtol, atol=atol, max_step=max_step, events=events or None,
                     dense_output=True, first_step=first_step, **options)


def _searching_steps(method, events: list):
    """``solve_ivp``'s method and events such that an event that also looks inside a step (``dips(t_old, state_at)``,
    :class:`~contactdyn.hybrid.events.DipWatch`) searches each step on its dense output, as our DOP853 and LSODA
    have it do (:class:`~contactdyn.numerics.dop853._EventWatch`): the method's class records the dense output it
    gives ``solve_ivp`` after each step, and the event reports a fall through zero where a dip was found."""
    if not any(getattr(e, "dips", None) is not None for e in events):
        return method, events
    if isinstance(method, str):
        import scipy.integrate

        method = getattr(scipy.integrate, method)
    last: dict = {}

    class Recorded(method):
        def dense_output(self):
            last["step"] = dense = super().dense_output()
            return dense

    return Recorded, [_Searching(e, last) if getattr(e, "dips", None) is not None else e for e in events]


class _Searching:
    """An event with ``dips`` under ``solve_ivp``: at each new step end, where its value is positive, also searched
    inside the step just taken, on its dense output (``last["step"]``); a dip found reads as −1 there, and the event
    holds its value negative from the dip on while ``solve_ivp`` locates the root."""

    def __init__(self, event, last: dict):
        self.event, self.last = event, last
        self.terminal, self.direction = event.terminal, event.direction
        self.t_end = -math.inf  #: [s] the last step end

    def __call__(self, t: float, y: np.ndarray) -> float:
        g = self.event(t, y)
        if t <= self.t_end:  # (a root being located inside the last step)
            return g
        self.t_end = t
        step = self.last.get("step")
        if step is None or step.t_max != t:
            return g
        if g > 0.0 and self.event.dips(step.t_min, step):
            return -1.0
        if g <= 0.0 and hasattr(self.event, "first_fall"):  # (a fall: the first of several, if its stages swung)
            self.event.first_fall(step.t_min, step)
        return g
