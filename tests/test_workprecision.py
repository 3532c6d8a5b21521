"""Speed against error: the compiled right-hand side, the integrators, the bench.

- the compiled call (the one pipeline, contactdyn.hybrid.pipeline_mode) computes the same derivatives, event
  values and output samples as the interpreted call (the same call run as Python: run_agreement), in every mode of
  every scene in sims/ and benchmarks/hard/;
- B1 at its default settings against the hand-written closed-form model
  (benchmarks/b1_reference.py, rtol 1e-13);
- the fixed-step RK4 converges at order 4; ``auto`` picks Radau only for stiff scenes;
- the bench: reference self-check, errors falling with the tolerance, report files,
  the comparison with other simulators, the CLI entry.
No assertion on wall time (the machine is shared).
"""

from __future__ import annotations

import argparse
import importlib.util
import itertools
import json
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from run_agreement import interpreted_evaluate, interpreted_samples

from contactdyn.analysis.workprecision import (
    WorkPoint,
    bench,
    bench_command,
    compare_with_others,
    errors,
    recommend,
    write_report,
)
from contactdyn.errors import SceneError, SimulationError
from contactdyn.hybrid.pipeline_mode import PipelineMode
from contactdyn.model.contact import ContactMode
from contactdyn.model.pipeline.pack import unsupported
from contactdyn.model.pipeline.pipeline import Pipeline
from contactdyn.numerics.integrators import FiniteDifferenceJacobian, jacobian_eigenvalues, stability_bound
from contactdyn.scene.scene_file import load_scene
from contactdyn.simulate import prepare, simulate

ROOT = Path(__file__).resolve().parent.parent
SCENES = sorted(str(p) for p in (ROOT / "sims").glob("*.toml")) + \
    sorted(str(p) for p in (ROOT / "benchmarks" / "hard").glob("*.toml"))


def _b1_reference():
    spec = importlib.util.spec_from_file_location("b1_reference", ROOT / "benchmarks" / "b1_reference.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def _mode_variants(system, modes):
    """Every touching/stuck/slip-direction combination of the scene's contacts (at most 16); a 2-D slide
    also launching from rest (its direction solved per call)."""
    per_contact = []
    for c, m in zip(system.contacts, modes, strict=True):
        k = len(c.tangents)
        slips = [m.slip] if not k else ([(1.0,), (-1.0,)] if k == 1 else [(0.6, 0.8), (-1.0, 0.0)])
        opts = []
        for touching, stuck in ((True, False), (True, True), (False, False)):
            if stuck and c.friction is None:
                continue
            for slip in slips:
                opts.append(ContactMode(touching, stuck, tuple(slip), m.offsets))
            if k == 2 and not stuck:
                opts.append(ContactMode(touching, stuck, slips[0], m.offsets, from_rest=True))
        per_contact.append(opts)
    return list(itertools.islice(itertools.product(*per_contact), 16))


@pytest.mark.parametrize("path", SCENES, ids=lambda p: Path(p).stem)
def test_compiled_call_agrees_with_the_interpreted_call(path):
    """Every mode packs (a mode the pipeline cannot pack would stop a run); derivatives, event values and output
    samples of the compiled call equal the interpreted call's (``run_agreement.interpreted_evaluate`` and
    ``interpreted_samples``, rtol 1e-9). Every row's force is compared, where the rows hold one body twice (a box on
    four corners) too: the two calls do the same operations, so a pivot of rounding size is the same in both (the
    readable model, another order of the arithmetic, could only be held to the rows' resultant there)."""
    system, modes, phase, x0 = prepare(load_scene(path, {"duration": 0.1}))
    rng = np.random.default_rng(3)
    pressing = replace(phase, limits=((0, 1),)) if 0 in system.limits.by_index else phase  # joint 0 on its limit
    for variant, phase in [(v, phase) for v in _mode_variants(system, modes)] + [(modes, pressing)]:
        variant = list(variant)
        assert unsupported(system, variant, phase) == ""
        plan = PipelineMode(Pipeline(system, variant, phase))
        states = [x0 + 1e-3 * rng.normal(size=system.n) for _ in range(3)]
        ts = np.array([0.01, 0.05, 0.09])
        samples = plan.samples(ts, np.array(states))
        ref_samples = interpreted_samples(system, ts, np.array(states), variant, phase)
        for t, x in zip(ts, states, strict=True):
            ev = interpreted_evaluate(system, t, x, variant, phase)
            got = plan.rhs(t, x)
            scale = 1.0 + np.abs(ev.xdot).max()
            assert np.abs(got - ev.xdot).max() <= 1e-9 * scale
            for ci, c in enumerate(system.contacts):
                F = ev.normal_force[c.name]
                assert plan.normal_force(ci, t, x) == pytest.approx(F, rel=1e-9, abs=1e-9 * scale)
                if not variant[ci].touching:
                    assert plan.gap(ci, t, x) == pytest.approx(ev.gap[c.name], rel=1e-9, abs=1e-12)
                if c.name in ev.slip:
                    np.testing.assert_allclose(plan.slip(ci, t, x), ev.slip[c.name], rtol=1e-9, atol=1e-12)
                if variant[ci].touching and variant[ci].stuck:
                    np.testing.assert_allclose(plan.stick_force(ci, t, x), ev.friction[c.name], rtol=1e-8,
                                               atol=1e-9 * scale)
            assert plan.limit_torque(t, x) == pytest.approx(ev.limit_torque, rel=1e-9, abs=1e-9 * scale)
        for name in ("tau", "tip", "body_force", "limit_torque"):
            np.testing.assert_allclose(getattr(samples, name), getattr(ref_samples, name), rtol=1e-8, atol=1e-8)
        for field in ("F_n", "gap", "F_d", "F_f", "v_slip", "iface", "stages"):
            for key, val in getattr(ref_samples, field).items():
                np.testing.assert_allclose(getattr(samples, field)[key], val, rtol=1e-8, atol=1e-8,
                                           err_msg=f"{field}[{key}]")


def test_b1_default_against_closed_form():
    """B1 at its default settings: F_n within 1e-5 N, x_tip within 1e-9 m of the hand-written model."""
    b1 = _b1_reference()
    ref = b1.reference()
    res = simulate("b1")
    assert res.stats["compiled_modes"] >= 1
    assert len(res.t) == 2001
    e_f, e_x = b1.errors({"F_n": res["contact.tip.F_n"], "x_tip": res["tip"][:, 0]}, ref)
    assert e_f < 1e-5
    assert e_x < 1e-9
    # and the reference is itself converged far below that
    assert b1.self_check()[0] < 1e-8


def test_rk4_fixed_step_converges_at_fourth_order():
    ref = simulate("b1", {"duration": 0.2, "solver.rtol": 1e-12, "solver.atol": 1e-14})
    errs = []
    for h in (4e-3, 2e-3):
        res = simulate("b1", {"duration": 0.2, "solver.method": "RK4", "solver.max_step": h})
        assert res.stats["steps"] == round(0.2 / h)
        errs.append(errors(res, ref)[1])
    assert 10.0 < errs[0] / errs[1] < 24.0  # 2^4 = 16


def test_fixed_step_needs_a_step():
    with pytest.raises(SceneError, match="solver.max_step"):
        simulate("b1", {"duration": 0.01, "solver.method": "RK4"})


def test_jacobian_eigenvalues_and_the_stiffness_rule():
    A = np.array([[0.0, 1.0], [-1e8, -2e4]])  # critically damped, λ = −1e4 (double)
    x = np.array([0.1, 0.2])
    lam = jacobian_eigenvalues(lambda t, x: A @ x, 0.0, x)
    np.testing.assert_allclose(np.sort(lam.real), [-1e4, -1e4], rtol=1e-3)
    # DOP853 held at h|λ| ≈ 1.5 by a decaying mode: stiff; the same mode at an accuracy-bound h: not
    assert stability_bound(lambda t, x: A @ x, 0.0, x, 1.5e-4, 2.0)[0]
    assert not stability_bound(lambda t, x: A @ x, 0.0, x, 1e-6, 2.0)[0]
    B = np.array([[0.0, 1.0], [-1e8, 0.0]])  # as fast but undamped: it must be resolved anyway
    assert not stability_bound(lambda t, x: B @ x, 0.0, x, 1.5e-4, 2.0)[0]


def test_finite_difference_jacobian_with_an_inert_state():
    """A state nothing depends on gives a zero column, not an overflowing step (scipy's num_jac does)."""
    jac = FiniteDifferenceJacobian(lambda t, x: np.array([x[1], -x[0], 0.0]))
    J = jac(0.0, np.array([1.0, 2.0, 3.0]))
    np.testing.assert_allclose(J, [[0, 1, 0], [-1, 0, 0], [0, 0, 0]], atol=1e-6)
    assert jac.calls == 4


def test_auto_picks_radau_for_a_near_rigid_contact_only():
    stiff = simulate(str(ROOT / "benchmarks" / "hard" / "stiff.toml"), {"solver.output_rate": 50.0})
    assert stiff.stats["segments_by_method"] == {"DOP853C": 1, "Radau": 1}  # switched after the step budget
    assert stiff.stats["auto_switches"] == 1
    assert stiff.stats["stiffness"] > 5e3  # [1/s] the contact mode, ω = sqrt(k / m_y) = 6.6e3
    short = simulate(str(ROOT / "benchmarks" / "hard" / "stiff.toml"), {"duration": 0.02})
    assert set(short.stats["segments_by_method"]) == {"DOP853C"}  # 0.02 s: ~20 stability-bound steps only
    b1 = simulate("b1", {"duration": 0.02, "solver.method": "auto"})
    assert set(b1.stats["segments_by_method"]) == {"DOP853C"}


def test_bench_errors_fall_with_the_tolerance(tmp_path):
    ref, points, build_ms = bench("b1", {"duration": 0.3, "solver.output_rate": 200.0}, methods=("DOP853",),
                                  rtols=(1e-4, 1e-7), repeats=1)
    assert ref.force_error < 1e-7  # the reference against half its tolerance
    loose, tight = points
    assert loose.status == tight.status == "ok"
    assert tight.force_error < loose.force_error / 30.0
    assert tight.position_error < loose.position_error / 30.0
    assert tight.rhs_evals > loose.rhs_evals > 0 and build_ms > 0
    doc = write_report("b1_short", ref, points, build_ms, tmp_path)
    for ext in ("csv", "json", "md", "png"):
        assert (tmp_path / f"b1_short.{ext}").stat().st_size > 0
    assert json.loads((tmp_path / "b1_short.json").read_text())["points"][1]["rtol"] == 1e-7
    assert doc["recommended"] in (None, loose.label, tight.label)


def test_recommend_and_compare_with_others():
    pts = [WorkPoint("DOP853", 1e-3, 1e-5, None, wall_ms=20.0, force_error=0.5),
           WorkPoint("DOP853", 1e-6, 1e-8, None, wall_ms=50.0, force_error=1e-4),
           WorkPoint("RK45", 1e-6, 1e-8, None, wall_ms=40.0, force_error=1e-3),
           WorkPoint("RK23", 1e-3, 1e-5, None, status="failed")]
    assert recommend(pts, peak_force=100.0, relative=1e-5).label == "RK45 rtol=1e-06"
    assert recommend(pts, peak_force=100.0, relative=1e-9) is None
    rows = compare_with_others(pts, [("A", 1.0, 0.03), ("B", 0.01, 1.2), ("C", 1e-5, 10.0)])
    assert rows[0]["ours"] == "DOP853 rtol=0.001" and rows[0]["ahead"] and rows[0]["factor_ok"] is None
    assert rows[1]["ours"] == "RK45 rtol=1e-06" and rows[1]["speedup"] == pytest.approx(30.0)
    assert rows[1]["factor_ok"] is True
    assert rows[2]["ours"] == "none" and not rows[2]["ahead"]


def test_bench_command_writes_the_report(tmp_path, capsys):
    args = argparse.Namespace(scene="b1", methods="DOP853,RK4=2e-3", rtols="1e-5", repeats=1, out=str(tmp_path),
                              set=["duration=0.1", "solver.output_rate=100"])
    assert bench_command(args) == 0
    text = (tmp_path / "b1.md").read_text()
    assert "DOP853 rtol=1e-05" in text and "RK4 h=0.002" in text
    # a 0.1 s B1 is not the B1 the other simulators were timed on (2 s): no comparison, and it says why
    out = capsys.readouterr().out
    assert "vs MuJoCo" not in out and "no comparison with the other simulators" in out
    assert json.loads((tmp_path / "b1.json").read_text())["others"] == []


def test_bench_command_rejects_unknown_methods(tmp_path):
    args = argparse.Namespace(scene="b1", methods="Euler", rtols=None, repeats=1, out=str(tmp_path),
                              set=["duration=0.05"])
    with pytest.raises(SceneError, match="--methods"):
        bench_command(args)


def test_rk4_step_beyond_the_stiffest_mode_stops_with_the_cause():
    """b1's stiffest mode: |λ| ≈ 92 1/s; h = 0.5 s amplifies it ~1e5× per step (it once exited 0 at 8.8e23 N)."""
    with pytest.raises(SimulationError) as info:
        simulate("b1", {"duration": 0.5, "solver.method": "RK4", "solver.max_step": 0.5})
    message = str(info.value)
    assert "too large for the stiffest mode" in message and "period 0.0686 s" in message
    assert "successfully" not in message
    assert simulate("b1", {"duration": 0.05, "solver.method": "RK4", "solver.max_step": 0.01}).stats["steps"] == 5


def test_rk4_amplification_matches_the_closed_form():
    from contactdyn.numerics.integrators import RK4_RADIUS, rk4_amplification

    assert RK4_RADIUS < 2.7852935  # the stated bound is inside the real stability interval [-2.7852935, 0]
    got = rk4_amplification(np.array([0.0, -1.0, -2.7852935, -3.0, 2.8j]))
    assert got[0] == 1.0 and got[1] == pytest.approx(1 - 1 + 1 / 2 - 1 / 6 + 1 / 24, rel=1e-15)
    assert got[2] == pytest.approx(1.0, abs=1e-6)  # the edge of the stability interval on the real axis
    assert got[3] == pytest.approx(1 - 3 + 9 / 2 - 27 / 6 + 81 / 24, rel=1e-15) and got[3] > 1
    assert got[4] < 1.0  # inside the stability region along the imaginary axis (|z| < 2.83)


def test_rk4_rechecks_the_step_when_the_state_grows():
    """y' = -λ(t) y with λ = 1 1/s, then 1000 1/s from t = 1 s: h = 0.01 s is stable at the start only."""
    from scipy.integrate import solve_ivp

    from contactdyn.numerics.integrators import fixed_step_instability
    from contactdyn.numerics.rk4 import RK4

    def fun(t, y):
        return -(1.0 if t < 1.0 else 1000.0) * y

    sol = solve_ivp(fun, (0.0, 2.0), [1.0], method=RK4, max_step=0.01, instability=fixed_step_instability)
    assert sol.status == -1 and 1.0 < sol.t[-1] < 1.1
    assert "too large for the stiffest mode (|λ| = 1e+03 1/s, period 0.00628 s)" in sol.message
