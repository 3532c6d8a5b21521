"""The compiled LSODA driver (contactdyn.numerics.lsoda) against solve_ivp's LSODA."""

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from contactdyn.numerics import lsoda
from contactdyn.numerics.integrators import integrate

pytestmark = pytest.mark.skipif(not lsoda.available(), reason="scipy without the compiled LSODA this driver calls")


def van_der_pol(t, y, mu=1000.0):
    """Stiff for μ = 1000: LSODA switches between Adams and BDF along the cycle."""
    return np.array([y[1], mu * (1.0 - y[0] ** 2) * y[1] - y[0]])


def event(fn, terminal, direction):
    fn.terminal, fn.direction = terminal, direction
    return fn


@pytest.mark.parametrize("rtol", [1e-6, 1e-9, 1e-11])
def test_same_steps_states_dense_output_and_events_as_solve_ivp(rtol):
    """The same core called the same way: the same accepted steps and states bitwise, the same interpolants, the
    same event times (a falling crossing, non-terminal, on every cycle)."""
    crossing = event(lambda t, y: y[0] - 1.5, False, -1)
    kw = dict(rtol=rtol, atol=rtol * 1e-2, events=[crossing])
    ref = solve_ivp(van_der_pol, (0.0, 1500.0), [2.0, 0.0], method="LSODA", dense_output=True, **kw)
    got = lsoda.solve(van_der_pol, (0.0, 1500.0), np.array([2.0, 0.0]), **kw)
    assert got.status == 0 and got.success
    assert np.array_equal(got.t, ref.t) and np.array_equal(got.y, ref.y)
    assert got.nfev == ref.nfev
    ts = np.linspace(0.0, 1500.0, 777)
    assert np.array_equal(got.sol(ts), ref.sol(ts))
    assert len(ref.t_events[0]) and np.array_equal(got.t_events[0], ref.t_events[0])


def test_a_terminal_event_ends_the_run_at_its_root_as_solve_ivp():
    """The run stops at the first terminal root; its last state is the interpolant's there, as solve_ivp's."""
    stop = event(lambda t, y: y[0] + 1.0, True, -1)
    kw = dict(rtol=1e-8, atol=1e-10, events=[stop], first_step=1e-4, max_step=5.0)
    ref = solve_ivp(van_der_pol, (0.0, 1500.0), [2.0, 0.0], method="LSODA", dense_output=True, **kw)
    got = integrate(van_der_pol, (0.0, 1500.0), np.array([2.0, 0.0]), "LSODA", **kw)
    assert got.status == ref.status == 1
    assert got.t[-1] == ref.t[-1] == got.t_events[0][0]
    assert np.array_equal(got.y[:, -1], ref.y[:, -1])
    assert abs(got.y[0, -1] + 1.0) < 1e-9


def test_a_crossing_within_the_interpolation_error_of_a_step_start_is_located():
    """LSODA's interpolant misses the state at a step's start by ~1e-10 here: an event whose level lies between
    the two crosses at the step ends but not on the interpolant (solve_ivp's brentq fails); with the bracket's
    ends at the steps' own states it is located at that step's start, within the interpolation error."""
    kw = dict(rtol=1e-6, atol=1e-8)
    run = lsoda.solve(van_der_pol, (0.0, 1500.0), np.array([2.0, 0.0]), **kw)
    steps = run.sol.steps
    miss = [(steps.interpolant(k)(steps.t[k])[0] - steps.ys[k][0], k) for k in range(1, len(steps.history))
            if steps.ys[k + 1][0] < steps.ys[k][0]]  # falling steps
    off, k = min(miss)
    assert off < -1e-11  # the interpolant starts below the state
    level = steps.ys[k][0] + 0.5 * off
    cross = event(lambda t, y: y[0] - level, True, -1)
    with pytest.raises(ValueError, match="different signs"):
        solve_ivp(van_der_pol, (0.0, 1500.0), [2.0, 0.0], method="LSODA", events=[cross], **kw)
    got = lsoda.solve(van_der_pol, (0.0, 1500.0), np.array([2.0, 0.0]), events=[cross], **kw)
    assert got.status == 1
    assert steps.t[k] <= got.t[-1] < steps.t[k + 1]
    assert abs(got.y[0, -1] - level) < abs(off)


def test_a_blow_up_ends_the_run_with_its_time():
    """y' = y² from y(0) = 1 blows up at t = 1: past it the derivatives overflow and scipy's core accepts steps of
    length 0 for ever (solve_ivp's LSODA hangs there); the run ends with status −1 and says where."""
    with np.errstate(over="ignore", invalid="ignore"):
        got = lsoda.solve(lambda t, y: y * y, (0.0, 2.0), np.array([1.0]), rtol=1e-8, atol=1e-10)
    assert got.status == -1 and not got.success
    assert "did not advance" in got.message and "t = 0.99999" in got.message
    assert 0.999 < got.t[-1] <= 1.0


def test_a_nan_derivative_ends_the_run_where_the_state_turns_nan():
    """One nan derivative (a trial state the model cannot solve): scipy's core accepts the step and carries the nan
    on to the end, reporting success (as solve_ivp's LSODA does); here the run ends there with status −1."""
    calls = [0]

    def once_nan(t, y):
        calls[0] += 1
        return np.array([np.nan]) if calls[0] == 30 else -y

    got = lsoda.solve(once_nan, (0.0, 1.0), np.array([1.0]), rtol=1e-8, atol=1e-10)
    assert got.status == -1 and "not finite" in got.message
    assert got.t[-1] < 1.0 and np.all(np.isfinite(got.y))


def test_an_event_in_a_step_shorter_than_t_resolution_is_located_at_its_end():
    """At t = 1e6 s a step of 1e-11 s is below t's resolution (1.2e-10 s): such a step has t_old = t. An event
    crossing in it is located at t (no bracket to search), with the step's end state, where it has crossed."""
    t0 = 1e6

    def shrinking(t, y):  # y' = −1e-3 / y: y reaches 0 at t0 + 5e-4 s, its steps collapsing
        return np.array([-1e-3 / y[0]]) if y[0] > 0 else np.array([np.nan])

    kw = dict(rtol=1e-10, atol=1e-14)
    steps = lsoda.solve(shrinking, (t0, t0 + 1.0), np.array([1e-3]), **kw).sol.steps
    k = next(k for k in range(len(steps.history))
             if steps.t[k + 1] == steps.t[k] and steps.ys[k + 1][0] < steps.ys[k][0])
    level = 0.5 * (steps.ys[k][0] + steps.ys[k + 1][0])
    got = lsoda.solve(shrinking, (t0, t0 + 1.0), np.array([1e-3]), events=[event(lambda t, y: y[0] - level, True, -1)],
                      **kw)
    assert got.status == 1 and got.t[-1] == steps.t[k] == got.t_events[0][0]
    assert got.y[0, -1] == steps.ys[k + 1][0] < level
