"""RK4 as a method of scipy's ``solve_ivp``: the classical fixed-step Runge–Kutta method (4 calls per step) with
step ``solver.max_step`` [s] and cubic Hermite dense output (:mod:`contactdyn.numerics.integrators`, ``RK4``).

Its own module because it subclasses scipy.integrate's ``OdeSolver``: a run that does not take RK4 does not import
scipy.integrate (nor scipy.optimize, which it imports: ~0.3 s of a process's start).
"""

from __future__ import annotations

import numpy as np
from scipy.integrate import DenseOutput, OdeSolver

__all__ = ["RK4", "HermiteOutput", "RK4_RECHECK_GROWTH"]

RK4_RECHECK_GROWTH = 1e3  #: the step is checked again once the state has grown this much since the last check


class HermiteOutput(DenseOutput):
    """Cubic Hermite interpolant of one step from the end values and slopes."""

    def __init__(self, t_old: float, t: float, y_old: np.ndarray, f_old: np.ndarray, y: np.ndarray, f: np.ndarray):
        super().__init__(t_old, t)
        self.h = t - t_old
        self.y_old, self.f_old, self.y, self.f = y_old, f_old, y, f

    def _call_impl(self, t):
        s = (np.asarray(t) - self.t_old) / self.h
        h00 = (1 + 2 * s) * (1 - s) ** 2
        h10 = s * (1 - s) ** 2
        h01 = s * s * (3 - 2 * s)
        h11 = s * s * (s - 1)
        if np.ndim(s) == 0:
            return h00 * self.y_old + h10 * self.h * self.f_old + h01 * self.y + h11 * self.h * self.f
        return (np.outer(self.y_old, h00) + np.outer(self.h * self.f_old, h10) + np.outer(self.y, h01)
                + np.outer(self.h * self.f, h11))


class RK4(OdeSolver):
    """Classical 4th-order Runge–Kutta with a fixed step ``max_step`` [s] (the last step is cut to t_bound).

    Before its first step it checks the step against the system's modes at the start (``instability``, solve_ivp's
    option: :func:`~contactdyn.numerics.integrators.fixed_step_instability`, as ``integrate`` passes it; not where
    ``check_start`` is false: a later segment of a mode already checked) and stops with that reason rather than run
    a blow-up;
    it checks again whenever the state has grown RK4_RECHECK_GROWTH-fold since the last
    check, and a step that leaves the finite numbers stops it too.
    """

    def __init__(self, fun, t0, y0, t_bound, max_step=np.inf, vectorized=False, rtol=None, atol=None,
                 first_step=None, instability=None, check_start=True, **extraneous):
        super().__init__(fun, t0, y0, t_bound, vectorized)
        if not np.isfinite(max_step) or max_step <= 0.0:
            raise ValueError("RK4 takes fixed steps of solver.max_step: give solver.max_step [s]")
        self.h = float(max_step)
        self.t0 = t0
        self.k = 0  #: steps taken (t_k = t0 + k h, no accumulated rounding)
        self.f = self.fun(self.t, self.y)
        self.y_old = self.f_old = None
        #: instability(fun, t, x, h) -> why the step h [s] cannot work from (t, x), or None (None: not checked)
        self.instability = instability if instability is not None else lambda fun, t, x, h: None
        self.unstable = self.instability(self.fun, t0, np.asarray(y0, float), self.h) if check_start else None
        self.checked_size = float(np.max(np.abs(y0), initial=0.0)) + 1.0  #: state size at the last check

    def _step_impl(self):
        t, y, f, h = self.t, self.y, self.f, self.h
        if self.unstable:
            return False, self.unstable
        t_new = self.t0 + (self.k + 1) * h
        if self.direction * (t_new - self.t_bound) > 0 or abs(t_new - self.t_bound) < 1e-12 * h:
            t_new = self.t_bound
        h = t_new - t
        k2 = self.fun(t + 0.5 * h, y + 0.5 * h * f)
        k3 = self.fun(t + 0.5 * h, y + 0.5 * h * k2)
        k4 = self.fun(t + h, y + h * k3)
        y_new = y + (h / 6.0) * (f + 2.0 * k2 + 2.0 * k3 + k4)
        if not np.all(np.isfinite(y_new)):
            return False, (f"the state left the finite numbers in the step from t = {t:.6g} s "
                           f"(step {h:.3g} s): too large a step, or a scene that blows up")
        size = float(np.max(np.abs(y_new), initial=0.0))
        if size > RK4_RECHECK_GROWTH * self.checked_size:  # grown a lot: the step may have left the region
            self.checked_size = size
            self.unstable = self.instability(self.fun, t_new, y_new, h)
            if self.unstable:
                return False, f"at t = {t_new:.6g} s {self.unstable}"
        self.y_old, self.f_old = y, f
        self.t, self.y = t_new, y_new
        self.f = self.fun(t_new, y_new)
        self.k += 1
        return True, None

    def _dense_output_impl(self):
        return HermiteOutput(self.t_old, self.t, self.y_old, self.f_old, self.y, self.f)
