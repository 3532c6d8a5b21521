"""DOP853 steps taken in one compiled call over the one pipeline (contactdyn.hybrid.steps) against scipy's core and
solve_ivp's DOP853 on the same right-hand side; the dense output's batched derivatives against the calls."""


import numpy as np
import pytest
from run_agreement import interpreted_evaluate
from scipy.integrate import solve_ivp

from contactdyn import parse_scene
from contactdyn.hybrid import steps
from contactdyn.hybrid.loop import HybridRun
from contactdyn.hybrid.pipeline_mode import PipelineMode
from contactdyn.model.pipeline.pipeline import Pipeline, call
from contactdyn.model.system import System
from contactdyn.numerics import dop853
from contactdyn.scene.scene_file import load_scene
from contactdyn.simulate import prepare


def _sliding(name: str, until: float):
    """(the pipeline's mode, t, x) of a run's last 2-D slide (neither stuck nor launching), amid its last segment."""
    run = HybridRun(System(load_scene(name, {"duration": until})))
    run.run(0.0)
    seg = next(s for s in reversed(run.segments)
               if all(m.touching and not m.stuck and not m.from_rest for m in s.modes))
    assert isinstance(seg.runner, PipelineMode)
    seg.runner.use(seg.modes)
    t = 0.5 * (seg.t0 + seg.t1)
    return seg.runner, t, seg.sol(t)


def _counted(step, taken: list):
    """``step``, noting per attempt whether the compiled call took it."""
    def counted(*args):
        got = step(*args)
        taken.append(got is not None)
        return got
    return counted


def _without_step(fun):
    def plain(t, x):
        return fun(t, x)
    return plain


@pytest.mark.parametrize("name, duration", [("case2_writer5dof", 0.04), ("case2_writer_ur5", 0.5)])
def test_compiled_steps_are_solve_ivps_and_the_scipy_cores(name, duration):
    """A stretch of the writers' slide (~20 steps): the compiled steps are solve_ivp's DOP853 steps (as many
    accepted and rejected within one, as many calls within two attempts, the step ends within 1e-5 of the
    stretch where the counts agree) and scipy's core's; the states agree within the tolerance (their error
    estimates cancel to ~1e-7 of themselves, so rounding moves the steps at 1e-8 and the states at the
    tolerance)."""
    mode, t, x = _sliding(name, 2.0)
    fun = mode.rhs
    span, rtol, atol = (t, t + duration), 1e-7, 1e-9
    got = dop853.solve(fun, span, x, rtol=rtol, atol=atol, step=_counted(fun.step, taken := []))
    assert len(taken) == got.naccept + got.nreject and all(taken)  # every attempt by the compiled call
    core = dop853.solve(_without_step(fun), span, x, rtol=rtol, atol=atol)
    ref = solve_ivp(_without_step(fun), span, x, method="DOP853", rtol=rtol, atol=atol)
    n_steps = len(ref.t) - 1
    assert n_steps > 10
    # rounding may move an error estimate across 1 and so add or drop a step: the counts agree within one step, the
    # step ends where they agree
    assert abs(got.naccept - n_steps) <= 1 and abs(core.naccept - n_steps) <= 1
    assert abs(got.nreject - core.nreject) <= 1
    assert abs(got.nfev - ref.nfev) <= 12 * 2  # DOP853: 12 calls per attempt
    if got.naccept == n_steps:
        assert np.abs(got.t - ref.t).max() <= 1e-5 * duration  # the same steps, moved by rounding
    tol = 10.0 * (atol + rtol * np.abs(ref.y[:, -1]))
    assert np.all(np.abs(got.y[:, -1] - ref.y[:, -1]) <= tol) and np.all(np.abs(core.y[:, -1] - ref.y[:, -1]) <= tol)
    ts = np.linspace(*span, 17)[1:-1]
    assert np.all(np.abs(got.sol(ts) - core.sol(ts)) <= 10.0 * (atol + rtol * np.abs(core.sol(ts))))


def _two_tables(shift: float):
    """cylindrical3 sliding on two frictionless rigid tables at the same height, the second ``shift`` [m] above the
    first (negative: below): the same rows, their Baumgarte terms apart by the shift; the mode with both touching."""
    rigid = {"direction": [0, 0, 1], "model": "rigid"}
    doc = {"duration": 0.3, "robot": {"urdf": "cylindrical3", "q0": [0.3, 0.2, 1.0], "v0": [0.5, -0.3, 0.0]},
           "contact": {"a": {"point": [1.0, 0.0, 0.2], "normal": rigid},
                       "b": {"point": [1.0, 0.0, 0.2 + shift], "normal": rigid}},
           "controller": {"kind": "task_pd", "kp": 1e4, "kd": 20.0},
           "phase": [{"name": "main", "reference": {"start": [0.9, 0.1, 0.2]}}]}
    system, modes, phase, x = prepare(parse_scene(doc))
    return system, [m.with_(touching=True) for m in modes], phase, x


def test_redundant_rows_that_agree_are_solved_in_the_call():
    """Two tables at one height: the KKT matrix singular but its system consistent; the call solves it by the
    minimum-norm least squares (status 1, counted: not regular), the interpreted call's forces and rates to
    rounding."""
    system, modes, phase, x = _two_tables(0.0)
    pipe = Pipeline(system, modes, phase)
    p = pipe.packed
    got = call(0.0, x.copy(), p.ints, p.reals, p.work, p.events)
    assert p.events[-1] == 1.0 and pipe.least_squares == 1
    ref = interpreted_evaluate(system, 0.0, x, modes, phase)
    assert not ref.regular
    assert np.abs(got - ref.xdot).max() <= 1e-10 * (1.0 + np.abs(ref.xdot).max())
    assert ref.normal_force["a"] == pytest.approx(ref.normal_force["b"], rel=1e-9)  # the load split evenly


def test_rows_that_disagree_are_solved_in_the_call_by_least_squares():
    """cylindrical3 on two rigid tables, the second 1 mm below, both touching: their rows are the same and their
    Baumgarte terms are not, so the KKT system has no solution. The call answers with the minimum-norm least squares
    (status 1, not 0: not a call with no answer, failed_calls 0): ẋ and λ as the interpreted call's
    (``interpreted_evaluate``) to 1e-9, ``regular`` False on both paths, the call counted."""
    system, modes, phase, x = _two_tables(-1e-3)
    pipe = Pipeline(system, modes, phase)
    p = pipe.packed
    for t, state in ((0.0, x), (0.05, x + 1e-3 * np.arange(x.size))):
        got = call(t, state.copy(), p.ints, p.reals, p.work, p.events)
        ref = interpreted_evaluate(system, t, state, modes, phase)
        assert p.events[-1] == 1.0 and not ref.regular
        assert np.abs(got - ref.xdot).max() <= 1e-9 * np.abs(ref.xdot).max()
    assert pipe.least_squares == 2 and pipe.failed_calls == 0
    mode = PipelineMode(pipe)
    ev = mode.evaluation(0.0, x)
    ref = interpreted_evaluate(system, 0.0, x, modes, phase)
    assert not ev.regular and mode.singular == 3 and pipe.failed_calls == 0
    assert np.abs(ev.lam - ref.lam).max() <= 1e-9 * np.abs(ref.lam).max()  # (min-norm: λ unique too)
    assert ev.normal_force == pytest.approx(ref.normal_force, rel=1e-9)


def test_a_run_on_rows_that_disagree_takes_every_step_in_the_call():
    """The same two tables 1 mm apart through 0.3 s (every call singular): every DOP853 attempt is taken by the
    compiled call, no call without an answer, and the run is the interpreted call's (scipy's core on
    ``interpreted_evaluate``) within the tolerance."""
    system, modes, phase, x = _two_tables(-1e-3)
    mode = PipelineMode(Pipeline(system, modes, phase))
    fun = mode.rhs
    span, rtol, atol = (0.0, 0.3), 1e-10, 1e-12
    got = dop853.solve(fun, span, x, rtol=rtol, atol=atol, step=_counted(fun.step, taken := []))
    assert mode.pipe.failed_calls == 0 and mode.singular == got.nfev
    assert got.status == 0 and taken and all(taken)  # every attempt in the call

    def interpreted(t, x_):
        return interpreted_evaluate(system, t, x_, modes, phase).xdot

    ref = dop853.solve(interpreted, span, x, rtol=rtol, atol=atol)
    assert got.naccept == ref.naccept > 3 and got.nreject == ref.nreject
    assert np.abs(got.y[:, -1] - x).max() > 0.1  # it moved
    assert np.all(np.abs(got.y[:, -1] - ref.y[:, -1]) <= 10.0 * (atol + rtol * np.abs(ref.y[:, -1])))


def test_compiled_steps_locate_the_events_as_scipys_core():
    """A terminal event on the slip velocity read off the pipeline's event values (its ring, which each compiled
    step's FSAL call enters) crossing a level it reaches mid-run: the same root as with scipy's core, to 1e-9 s."""
    mode, t, x = _sliding("case2_writer5dof", 2.0)
    fun = mode.rhs

    def v_x(t_, x_):  # [m/s] the slip velocity's first component, off the call at (t_, x_)
        return float(mode.slip(0, t_, x_)[0])

    ahead = dop853.solve(_without_step(fun), (t, t + 0.1), x, rtol=1e-7, atol=1e-9)
    level = 0.5 * (v_x(t, x) + v_x(ahead.t[-1], ahead.y[:, -1].copy()))  # crossed about 50 ms in

    def slip_x(t_, x_):
        return v_x(t_, x_) - level

    slip_x.terminal = True
    span = (t, t + 0.1)
    got = dop853.solve(fun, span, x, rtol=1e-7, atol=1e-9, events=[slip_x], step=_counted(fun.step, taken := []))
    core = dop853.solve(_without_step(fun), span, x, rtol=1e-7, atol=1e-9, events=[slip_x])
    assert got.status == core.status == 1 and got.t[-1] < span[1] and taken and all(taken)
    assert got.t_events[0][0] == pytest.approx(core.t_events[0][0], abs=1e-9)


def test_the_batched_derivatives_are_the_calls_bitwise(monkeypatch):
    """The dense output's extra stages in one compiled call equal the pipeline's right-hand side per state to the
    bit; from a state the compiled call declines on (made to decline at the 4th here), the right-hand side takes
    them."""
    mode, t, x = _sliding("case2_writer5dof", 2.0)
    fun, packed = mode.rhs, mode.pipe.packed
    rng = np.random.default_rng(5)
    X = x + 1e-5 * rng.normal(size=(6, len(x)))
    ts = t + np.linspace(0.0, 1e-3, 6)
    want = np.array([fun(float(tk), xk.copy()) for tk, xk in zip(ts, X, strict=True)])
    done = []
    original = steps.rates_at
    monkeypatch.setattr(steps, "rates_at", lambda *a: done.append(original(*a)[1]) or original(*a))
    assert np.array_equal(steps.derivatives(packed, fun)(ts, X), want) and done == [len(ts)]  # all by the call
    calls = []
    monkeypatch.setattr(steps, "rates_at", lambda *a: (original(*a)[0], 3))
    batch = steps.derivatives(packed, lambda t_, x_: calls.append(t_) or fun(t_, x_))
    assert np.array_equal(batch(ts, X), want) and calls == list(ts[3:])


def test_a_steps_interpolant_in_one_call_is_the_three_calls_bitwise(monkeypatch):
    """A located event's step interpolant in one compiled call (steps.interpolant) is the one build_interpolants
    forms by the right-hand side's three calls, to the bit, on the writer's slide steps; where a call of it declines
    (made to here) the builder gives None and the step is built by those calls."""
    mode, t, x = _sliding("case2_writer5dof", 2.0)
    fun = mode.rhs
    got = dop853.solve(fun, (t, t + 0.01), x, rtol=1e-7, atol=1e-9, step=fun.step)
    st = got.sol.steps
    assert len(st.t) > 3
    for i in range(len(st.t) - 1):
        one = fun.interpolant(st.t[i], st.t[i + 1] - st.t[i], st.y_old(i), st.f_old(i), st.blocks[i])
        dop853.build_interpolants([(st, i)], None)  # by fun: three calls
        assert one.shape == st.coef[i].shape and np.array_equal(one, st.coef[i])
    monkeypatch.setattr(steps, "interpolant", lambda *a: (steps.DECLINED, None))
    assert steps.interpolant_builder(mode.pipe.packed)(st.t[0], st.t[1] - st.t[0], st.y0, st.f0, st.blocks[0]) is None
