"""A run on the compiled DOP853 imports neither scipy.integrate nor scipy.optimize (~0.3–0.7 s of a process's start):
the DOP853 tableau, solve_ivp's first-step estimate and Brent's root finder are the package's own, and must be scipy's
bit for bit (the same steps, the same event times); scipy's C core, LSODA, solve_ivp's methods and RK4 are imported
where a run takes them."""

from __future__ import annotations

import math
import subprocess
import sys

import numpy as np
import pytest
from scipy.integrate._ivp import dop853_coefficients as scipy_tableau
from scipy.integrate._ivp.common import select_initial_step
from scipy.integrate._ivp.rk import MAX_FACTOR, MIN_FACTOR, SAFETY
from scipy.optimize import brentq

from contactdyn.numerics import dop853, dop853_tableau


def test_the_tableau_is_scipys_bit_for_bit():
    for name in ("A", "B", "C", "D", "E3", "E5", "N_STAGES", "N_STAGES_EXTENDED", "INTERPOLATOR_POWER"):
        ours, theirs = getattr(dop853_tableau, name), getattr(scipy_tableau, name)
        assert np.array_equal(ours, theirs) and np.shape(ours) == np.shape(theirs), name
    assert (dop853.SAFETY, dop853.MIN_FACTOR, dop853.MAX_FACTOR) == (SAFETY, MIN_FACTOR, MAX_FACTOR)


def _problems():
    """(f, t0, y0, t_end, max_step, rtol, atol): linear and nonlinear systems, zero and tiny states, a short span."""
    rng = np.random.default_rng(5)
    out = []
    for n in (1, 3, 8):
        M = rng.normal(size=(n, n)) * 10.0 ** rng.uniform(-2, 3)
        out.append((lambda t, y, M=M: M @ y + np.sin(t), 0.3, rng.normal(size=n), 2.0, np.inf, 1e-8, 1e-10))
        out.append((lambda t, y, M=M: M @ np.tanh(y), 0.0, np.zeros(n), 1.0, 0.01, 1e-6, 1e-9))
        out.append((lambda t, y: -y ** 3, 0.0, 1e-9 * np.ones(n), 1e-4, np.inf, 1e-10, 1e-12))
    out.append((lambda t, y: np.zeros(2), 0.0, np.zeros(2), 1.0, np.inf, 1e-8, 1e-10))
    return out


def test_the_first_step_is_solve_ivps_bit_for_bit():
    for f, t0, y0, t_end, max_step, rtol, atol in _problems():
        f0 = f(t0, y0)
        ours = dop853._initial_step(f, t0, y0, f0, t_end, max_step, rtol, atol)
        theirs = select_initial_step(f, t0, y0, t_end, max_step, f0, 1.0, 7, rtol, atol)
        assert ours == float(theirs)
    assert dop853._initial_step(math.cos, 1.0, np.ones(1), np.ones(1), 1.0, 1.0, 1e-8, 1e-8) == 0.0


_FUNCTIONS = [
    (lambda x: x * x - 2.0, 0.0, 2.0),
    (lambda x: math.cos(x) - x, 0.0, math.pi / 2),
    (lambda x: (x - 1e-3) ** 3, -1.0, 1.0),
    (lambda x: math.exp(x) - 1e6, 0.0, 20.0),
    (lambda x: math.tanh(50.0 * (x - 0.3)), -1.0, 1.0),
    (lambda x: x, -1.0, 1.0),
    (lambda x: 1e-300 * (x - 0.5), 0.0, 1.0),
    (lambda x: np.float64(x) - 0.25, 0.0, 1.0),  # (a NumPy scalar, as an event function gives)
]


def _outcome(find, f, a, b, tol):
    """The root found, or the error's class and words."""
    try:
        return find(f, a, b, xtol=tol, rtol=4 * np.finfo(float).eps)
    except (ValueError, RuntimeError) as e:
        return type(e).__name__, str(e)


@pytest.mark.parametrize("tol", [2e-12, 4 * np.finfo(float).eps])
@pytest.mark.parametrize("k", range(len(_FUNCTIONS)))
def test_brent_root_is_brentqs_bit_for_bit(k, tol):
    """The same root, or the same failure (a triple root at 4 ε does not converge in 100 iterations either way)."""
    f, a, b = _FUNCTIONS[k]
    for lo, hi in ((a, b), (b, a)):
        assert _outcome(dop853.brent_root, f, lo, hi, tol) == _outcome(brentq, f, lo, hi, tol)


def test_brent_root_refuses_what_brentq_refuses():
    with pytest.raises(ValueError, match="must have different signs"):
        dop853.brent_root(lambda x: x * x + 1.0, -1.0, 1.0, 1e-12, 1e-15)
    with pytest.raises(ValueError, match="is NaN"):
        dop853.brent_root(lambda x: math.nan if x > 0.0 else -1.0, -1.0, 1.0, 1e-12, 1e-15)
    with pytest.raises(RuntimeError, match="Failed to converge after 3 iterations"):
        dop853.brent_root(lambda x: math.cos(x) - x, 0.0, 1.5, 1e-15, 1e-15, maxiter=3)
    assert dop853.brent_root(lambda x: x, 0.0, 1.0, 1e-12, 1e-15) == 0.0  # (a root at an end)


def test_the_simulators_modules_import_neither_scipy_integrate_nor_optimize():
    """What a run on the compiled DOP853 imports (the loop, the integrators, the compiled steps, the sampled loop)."""
    code = ("import sys, contactdyn.simulate, contactdyn.hybrid.loop, contactdyn.hybrid.steps, "
            "contactdyn.numerics.integrators, contactdyn.numerics.held_steps, contactdyn.hybrid.sampled_law; "
            "print(sorted(m for m in ('scipy.integrate', 'scipy.optimize') if m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "[]"
