"""The compiled DOP853 (contactdyn.numerics.dop853) against solve_ivp's DOP853 and closed forms."""

import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from contactdyn.errors import SceneError
from contactdyn.numerics.dop853 import solve


def oscillator(t, y):
    """y'' = −y − 0.1 y': y(t) = e^(−t/20) (cos ωt + sin(ωt)/(20ω)), ω² = 1 − 1/400."""
    return np.array([y[1], -y[0] - 0.1 * y[1]])


W = math.sqrt(1.0 - 1.0 / 400.0)


def exact(t):
    t = np.asarray(t)
    return np.exp(-t / 20.0) * (np.cos(W * t) + np.sin(W * t) / (20.0 * W))


def terminal(fn, direction):
    fn.terminal, fn.direction = True, direction
    return fn


@pytest.mark.parametrize("rtol", [1e-6, 1e-9])
def test_same_accepted_steps_as_solve_ivp(rtol):
    """Same method, same step control, same first step: the same accepted steps (to rounding of the
    error norm, which the step size amplifies as err^(1/8)), states within the tolerance."""
    kw = dict(rtol=rtol, atol=rtol * 1e-2, first_step=1e-3)
    ref = solve_ivp(oscillator, (0.0, 20.0), [1.0, 0.0], method="DOP853", dense_output=True, **kw)
    got = solve(oscillator, (0.0, 20.0), [1.0, 0.0], **kw)
    assert got.status == 0
    assert len(got.t) == len(ref.t)
    np.testing.assert_allclose(got.t, ref.t, rtol=1e-7, atol=0.0)
    ts = np.linspace(0.0, 20.0, 333)  # dense output: the same 7th-order interpolant
    assert float(np.abs(got.sol(ts) - ref.sol(ts)).max()) < 1e-3 * rtol  # measured 4e-13, 2e-15
    assert float(np.abs(got.sol(ts)[0] - exact(ts)).max()) < 10 * rtol


def _rejections_of_solve_ivp(fun, t_span, y0, **kw):
    """solve_ivp's DOP853 result and the number of steps it rejected (error norm ≥ 1)."""
    from scipy.integrate._ivp.rk import DOP853

    norms = []
    estimate = DOP853._estimate_error_norm

    def counted(self, K, h, scale):
        norms.append(estimate(self, K, h, scale))
        return norms[-1]

    DOP853._estimate_error_norm = counted
    try:
        ref = solve_ivp(fun, t_span, y0, method="DOP853", **kw)
    finally:
        DOP853._estimate_error_norm = estimate
    return ref, sum(e >= 1.0 for e in norms)


def van_der_pol(t, y, mu=4.0):
    return np.array([y[1], mu * (1.0 - y[0] ** 2) * y[1] - y[0]])


@pytest.mark.parametrize("fun, t_span, y0, kw", [
    (van_der_pol, (0.0, 20.0), [2.0, 0.0], dict(rtol=1e-8, atol=1e-10)),  # measured 44 rejections
    (oscillator, (0.0, 20.0), [1.0, 0.0], dict(rtol=1e-9, atol=1e-11, first_step=5.0)),  # rejected at t = 0
    (oscillator, (3.0, 23.0), [1.0, 0.0], dict(rtol=1e-9, atol=1e-11, first_step=5.0)),  # ... at t = 3
])
def test_rejections_follow_solve_ivp(fun, t_span, y0, kw):
    """After a rejection the step shrinks by solve_ivp's rule, not the core's fixed factor: the same
    accepted and rejected steps. Times agree to the rounding of the error norm (a difference of O(1)
    stage sums, ~1e-8 relative), which a cascade of rejections amplifies (measured 9e-7 on van der Pol)."""
    ref, rejected = _rejections_of_solve_ivp(fun, t_span, y0, **kw)
    got = solve(fun, t_span, y0, **kw)
    assert rejected > 0 and got.nreject == rejected
    assert len(got.t) == len(ref.t)
    np.testing.assert_allclose(got.t, ref.t, rtol=1e-6, atol=0.0)
    assert got.nfev == ref.nfev - rejected  # a rejected attempt skips the end call solve_ivp makes


@pytest.mark.parametrize("max_step, first_step", [(0.05, None), (0.3, 2.0)])  # 2.0: a first step above max_step
def test_max_step_as_solve_ivp(max_step, first_step):
    """The core caps a step at hmax only after an accepted one; the first step is capped here: the same steps."""
    kw = dict(rtol=1e-9, atol=1e-11, max_step=max_step, first_step=first_step)
    ref = solve_ivp(oscillator, (0.0, 20.0), [1.0, 0.0], method="DOP853", **kw)
    got = solve(oscillator, (0.0, 20.0), [1.0, 0.0], **kw)
    assert len(got.t) == len(ref.t)
    np.testing.assert_allclose(got.t, ref.t, rtol=1e-12, atol=0.0)  # measured: identical
    assert float(np.diff(got.t).max()) <= max_step * (1.0 + 1e-12)


def test_error_weights_live_in_the_workspace_rows():
    """The rejected attempt's error norm is read from the core's workspace, which keeps stages 1, 6–12
    only: every stage it does not keep has weight 0 in both of DOP853's error estimates."""
    from scipy.integrate._ivp import dop853_coefficients as coef

    from contactdyn.numerics.dop853 import _ROW_STAGE

    kept = {s for s in _ROW_STAGE if s is not None}
    dropped = [s for s in range(len(coef.E5)) if s not in kept]
    assert dropped == [1, 2, 3, 4, 12]
    assert not np.any(coef.E5[dropped]) and not np.any(coef.E3[dropped])


def test_error_within_tolerance_of_the_closed_form():
    got = solve(oscillator, (0.0, 20.0), [1.0, 0.0], rtol=1e-8, atol=1e-10)
    assert got.t[-1] == 20.0  # the end is hit exactly (the hybrid loop compares t with T)
    ts = np.linspace(0.0, 20.0, 1001)  # dense output between the steps, too
    assert float(np.abs(got.sol(ts)[0] - exact(ts)).max()) < 1e-7


def test_terminal_event_located_on_the_interpolant():
    """cos-like decay crosses 0.3 downwards first at t*: found to ~1e-12 s, state on the surface."""
    ev = terminal(lambda t, y: y[0] - 0.3, -1)
    got = solve(oscillator, (0.0, 20.0), [1.0, 0.0], rtol=1e-10, atol=1e-12, events=[ev])
    from scipy.optimize import brentq

    t_star = brentq(lambda t: exact(t) - 0.3, 0.5, 1.6, xtol=1e-15)
    assert got.status == 1
    assert abs(got.t_events[0][0] - t_star) < 1e-9
    assert got.t[-1] == got.t_events[0][0]
    assert abs(got.y[0, -1] - 0.3) < 1e-12


def test_direction_and_earliest_terminal_event():
    up = terminal(lambda t, y: y[0] - 0.3, +1)  # y falls through 0.3 first: no upward crossing then
    down = terminal(lambda t, y: y[0] + 0.2, -1)  # later, downwards
    got = solve(oscillator, (0.0, 20.0), [1.0, 0.0], rtol=1e-9, atol=1e-11, events=[up, down])
    assert got.status == 1 and len(got.t_events[1]) == 1 and len(got.t_events[0]) == 0
    ref = solve_ivp(oscillator, (0.0, 20.0), [1.0, 0.0], method="DOP853", rtol=1e-9, atol=1e-11,
                    events=[up, down])
    assert abs(got.t_events[1][0] - ref.t_events[1][0]) < 1e-9


def test_event_calls_follow_solve_ivp_contract():
    """g is called at t0 first, then once at every step end in increasing t (the loop's guards rely on it)."""
    calls = []

    def g(t, y):
        calls.append(t)
        return 1.0

    got = solve(oscillator, (0.0, 5.0), [1.0, 0.0], rtol=1e-8, atol=1e-10, events=[g])
    assert calls == list(got.t)


def test_exception_in_the_right_hand_side_propagates():
    def bad(t, y):
        if t > 0.5:
            raise np.linalg.LinAlgError("singular contact system")
        return oscillator(t, y)

    with pytest.raises(np.linalg.LinAlgError, match="singular contact system"):
        solve(bad, (0.0, 2.0), [1.0, 0.0], rtol=1e-8, atol=1e-10)


def test_failure_is_reported_not_hidden():
    got = solve(lambda t, y: np.array([np.nan if t > 0.1 else 1.0]), (0.0, 1.0), [0.0], rtol=1e-8, atol=1e-10)
    assert got.status == -1 and "step size" in got.message
    assert got.t[-1] < 0.2


def test_exception_in_an_event_propagates():
    def g(t, y):
        if t > 0.5:
            raise KeyError("contact 'tip'")
        return 1.0

    with pytest.raises(KeyError, match="tip"):
        solve(oscillator, (0.0, 2.0), [1.0, 0.0], rtol=1e-8, atol=1e-10, events=[g])


def test_interpolants_cost_three_calls_per_step_and_only_where_asked():
    calls = []

    def counted(t, y):
        calls.append(t)
        return oscillator(t, y)

    got = solve(counted, (0.0, 10.0), [1.0, 0.0], rtol=1e-8, atol=1e-10)
    assert got.nfev == len(calls)  # the core's count and ours agree
    n_steps = len(got.t) - 1
    got.sol(np.array([0.5 * (got.t[0] + got.t[1])]))  # one step's interpolant
    assert got.sol.late_calls == 3
    got.sol(np.linspace(0.0, 10.0, 1001))  # all steps: 3 calls each, the first not again
    assert got.sol.late_calls == 3 * n_steps == len(calls) - got.nfev


def test_events_read_each_step_on_its_own_interpolant():
    """Event location evaluates the step's own interpolant (as solve_ivp's step dense output): its start
    state exactly at the step's start, its end state to rounding, and inside the step the values the
    output's DenseSolution gives."""
    got = solve(oscillator, (0.0, 10.0), [1.0, 0.0], rtol=1e-8, atol=1e-10)
    steps = got.sol.steps
    for i in (0, 1, len(got.t) // 2, len(got.t) - 2):
        t_old, t_new = got.t[i], got.t[i + 1]
        assert np.array_equal(steps.at(i, t_old), got.y[:, i])
        assert np.allclose(steps.at(i, t_new), got.y[:, i + 1], rtol=1e-14, atol=1e-15)
        for s in (0.25, 0.5, 0.9):
            t = t_old + s * (t_new - t_old)
            assert np.array_equal(steps.at(i, t), got.sol(t))


@pytest.mark.parametrize("scene, duration, force_tol", [
    ("b1", 0.5, 1e-5),  # smooth sliding: measured 1.4e-6 N apart, each ~2e-6 N from the reference
    ("case2_writer_b", 1.5, 1e-4),  # touch, impact, stick, slip, separation: measured 5e-6 N apart
])
def test_scenes_agree_with_solve_ivp(scene, duration, force_tol):
    """A whole hybrid run on DOP853C (the default) and on solve_ivp's DOP853: the same events at the same
    times, channels within the error, the same number of steps to 1 % (measured: equal on B1, 1694
    against 1691 on the writer; the core's own rejection rule took 26 % more on B1)."""
    from contactdyn import simulate

    ref = simulate(scene, {"duration": duration, "solver.method": "DOP853"})
    got = simulate(scene, {"duration": duration})
    assert got.stats["method"] == "DOP853C"
    assert abs(got.stats["steps"] - ref.stats["steps"]) <= 0.01 * ref.stats["steps"]
    assert [(e["kind"], e["name"]) for e in got.events] == [(e["kind"], e["name"]) for e in ref.events]
    assert max((abs(a["t"] - b["t"]) for a, b in zip(got.events, ref.events, strict=True)), default=0.0) < 1e-7
    for name in (c for c in ref.channels if c.endswith(".F_n")):
        assert float(np.abs(got[name] - ref[name]).max()) < force_tol
    assert float(np.abs(got["tip"] - ref["tip"]).max()) < 1e-8
    assert got.stats["segments_by_method"] == {"DOP853C": ref.stats["segments_by_method"]["DOP853"]}


def test_a_scipy_without_the_compiled_core_is_named(monkeypatch):
    from scipy.integrate import _dop

    monkeypatch.delattr(_dop, "dopri853")  # (what an older scipy has not)
    with pytest.raises(SceneError, match="solver.method.*DOP853C.*scipy"):
        solve(oscillator, (0.0, 1.0), [1.0, 0.0], rtol=1e-8, atol=1e-10)


def test_the_stages_states_need_no_copy(monkeypatch):
    """The core hands the right-hand side views of its workspace, which its next stages overwrite; only the step
    end's state is copied (the events read it later). With every state copied, a run with stick, a 2-D launch,
    turns and joint limits (the 5-DOF writer's first 1.2 s) gives the same channels and events bitwise."""
    import contactdyn.numerics.dop853 as dop
    from contactdyn import simulate

    own = simulate("case2_writer5dof", {"duration": 1.2})
    f = dop._Core.f
    monkeypatch.setattr(dop._Core, "f", lambda self, t, x: f(self, t, x.copy()))
    copied = simulate("case2_writer5dof", {"duration": 1.2})
    assert own.events == copied.events and own.stats["steps"] == copied.stats["steps"]
    for name in own.channels:
        np.testing.assert_array_equal(own[name], copied[name], err_msg=name)  # (nan where both have none)
