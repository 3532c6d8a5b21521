"""The batched output of motor, elastic and force-reading phases equals the readable model per sample.

Each scene runs twice on the same integration: once with the plans' batched output
(:func:`~contactdyn.compiled.samples.plan_samples`), once with every output sample from
``System.evaluate(full=True)``. Every channel must agree to 1e-10 (relative to the channel's scale).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import contactdyn.compiled.rhsplan as rhsplan
import contactdyn.compiled.samples as samples
from contactdyn import Robot, parse_scene
from contactdyn.compiled.rhsplan import _PLANS
from contactdyn.compiled.samples import evaluated_samples, plan_derivatives
from contactdyn.laws.trajectory import profile
from contactdyn.model.contact import ContactMode
from contactdyn.model.system import System
from contactdyn.output.channels import _per_sample
from contactdyn.scene.scene_file import load_scene
from contactdyn.simulate import run_system, simulate

#: scene -> a duration [s] that holds its phases' kinds (motor, elastic, force-reading, a carried reference)
SCENES = {"case1_cart": 1.1, "case2_writer_motors": 0.3, "case3_a_force": 0.3, "case3_b_force": 0.3, "b1": 0.3}


def _readable(plan, ts, X):
    return evaluated_samples(plan.system, ts, X, plan.modes, plan.phase)


#: a prismatic axis under a joint PD asking far more than its voltage limit gives: it clips, then settles
CASE3 = {"R": 0.175, "C_M": 0.0575, "J": 7.9e-4, "N": 50.0, "wheel_radius": 0.15, "u_max": 6.0}


def _clipping_axis(drive: dict) -> dict:
    return {"duration": 0.3, "solver": {"output_rate": 1000.0},
            "robot": {"urdf": "cylindrical3", "active_joints": ["q3"], "gravity": [0.0, 0.0, 0.0], "q0": [0.0],
                      "drive": drive},
            "controller": {"kind": "joint_pd", "kp": 2e5, "kd": 0.0},
            "phase": [{"name": "go", "reference": {"space": "joint", "start": [0.02], "moves": []}}]}


def _assert_same_channels(scene, overrides, monkeypatch):
    fast = simulate(scene, overrides)
    monkeypatch.setattr(rhsplan, "plan_samples", _readable)
    ref = simulate(scene, overrides)
    assert fast.channels.keys() == ref.channels.keys()
    assert np.array_equal(fast.channels["t"], ref.channels["t"])
    for name, want in ref.channels.items():
        got = fast.channels[name]
        scale = 1.0 + np.nanmax(np.abs(want)) if np.any(np.isfinite(want)) else 1.0
        assert np.array_equal(np.isnan(got), np.isnan(want)), name
        assert np.nanmax(np.abs(got - want), initial=0.0) <= 1e-10 * scale, name
    return fast


@pytest.mark.parametrize("scene", SCENES)
def test_batched_output_equals_evaluate(scene, monkeypatch):
    _assert_same_channels(scene, {"duration": SCENES[scene], "solver.output_rate": 500.0}, monkeypatch)


@pytest.mark.parametrize("drive", [{"kind": "dc_motor", **CASE3},
                                   {"kind": "elastic", **CASE3, "c": 14000.0, "d": 0.0196}], ids=["rigid", "elastic"])
def test_clipped_voltages_in_the_batched_output(drive, monkeypatch):
    """Samples where a voltage clips take the drive law itself: the same u (at ±u_max), τ and motion channels."""
    result = _assert_same_channels(parse_scene(_clipping_axis(drive)), None, monkeypatch)
    u = result.channels["u"][:, 0]
    assert np.mean(np.abs(u) == CASE3["u_max"]) > 0.1 and np.mean(np.abs(u) < CASE3["u_max"]) > 0.1


def _pressing_writer(u_max: float | None = None) -> dict:
    """A7 on the 2-DOF writer pressing a bonded wall under DC motors (``u_max`` [V]: their voltage limit, None:
    none): every sample folded."""
    q0 = [0.3, 1.2]  # [rad] the writer's pose, tip at p0
    p0 = Robot.load("writer2r").frame_position(np.array(q0), "tip")
    drive = {"kind": "dc_motor", "R": 0.272, "C_M": 0.061, "J": 0.000452, "N": 160.0, "N_star": 65.12,
             **({"u_max": u_max} if u_max is not None else {})}
    return {"duration": 0.3, "solver": {"output_rate": 500.0},
            "robot": {"urdf": "writer2r", "q0": q0, "drive": drive},
            "controller": {"kind": "position_dynamic", "kp": 400.0, "kv": 40.0},
            "phase": [{"name": "main", "reference": {"space": "task", "start": (p0 + [0.01, 0.0, -0.03]).tolist(),
                                                     "moves": []}}],
            "contact": {"c": {"point": p0.tolist(), "bonded": True,
                              "normal": {"direction": [-1, 0, 0], "model": "b", "k": 1e4, "b": 10.0, "m": 2.0}}}}


def test_folded_forces_with_clipped_voltages_in_the_batched_output(monkeypatch):
    """A7 pressing a bonded wall with a voltage limit (tests/test_controllers.py's case): the measured force
    folded into the solve and the clip re-checked with it, through the plan's fold at every sample."""
    doc = _pressing_writer(u_max=4.0)
    result = _assert_same_channels(parse_scene(doc), None, monkeypatch)
    u = result.channels["u"]
    assert np.mean(np.abs(u) == 4.0) > 0.05 and np.mean(np.abs(u) < 4.0) > 0.05


def test_folded_forces_with_coulomb_friction_in_b(monkeypatch):
    """A7 bonded to a wall (a normal row: the measured force folded into the solve) while sliding on a
    compliant model-(a) floor with Coulomb friction: the floor's normal force is its interface stage's, known,
    so −μ max(F_n, 0) d goes into b before the plan's fold over samples (``_fold_all``) reads it."""
    q0 = [0.3, 1.2]  # [rad] the writer's pose, tip at p0
    p0 = Robot.load("writer2r").frame_position(np.array(q0), "tip")
    drive = {"kind": "dc_motor", "R": 0.272, "C_M": 0.061, "J": 0.000452, "N": 160.0, "N_star": 65.12}
    floor = {"direction": [0, 0, 1], "model": "a", "m": 1.0, "k_ext": 1e4, "b_ext": 5.0, "k_int": 1e4, "b_int": 2.0}
    doc = {"duration": 0.4, "solver": {"output_rate": 500.0},
           "robot": {"urdf": "writer2r", "q0": q0, "drive": drive},
           "controller": {"kind": "position_dynamic", "kp": 400.0, "kv": 40.0},
           "phase": [{"name": "main", "reference": {
               "start": (p0 + [0.0, 0.0, -0.01]).tolist(),
               "moves": [{"kind": "trapezoid", "delta": [0.02, 0.0, 0.0], "duration": 0.4}]}}],
           "contact": {"wall": {"point": p0.tolist(), "bonded": True,
                                "normal": {"direction": [-1, 0, 0], "model": "b", "k": 1e3, "b": 10.0, "m": 2.0}},
                       "floor": {"point": (p0 + [0.0, 0.0, -0.002]).tolist(), "normal": floor,
                                 "tangent": {"model": "friction", "directions": [[1.0, 0.0, 0.0]], "mu": 0.3}}}}
    folded = []  # per call of the fold over samples: (the plan folds rows, Coulomb terms in b, the floor slides, N)
    fold_all = samples._fold_all

    def spy(plan, X, *args):
        floor_mode = plan.modes[[c.name for c in plan.system.contacts].index("floor")]
        folded.append((plan.folded_parts is not None and plan.nr > 0, len(plan.coulomb_terms) > 0,
                       floor_mode.touching and not floor_mode.stuck, len(X)))
        return fold_all(plan, X, *args)

    monkeypatch.setattr(samples, "_fold_all", spy)
    result = _assert_same_channels(parse_scene(doc), None, monkeypatch)
    assert sum(n for rows, coulomb, sliding, n in folded if rows and coulomb and sliding) >= 150
    F_n, F_f = result.channels["contact.floor.F_n"], result.channels["contact.floor.F_f"][:, 0]
    assert F_n.max() > 30.0 and np.abs(F_f).max() > 9.0  # μ F_n of ~12 N in b


@pytest.mark.parametrize("scene, duration", [("b1", 2.0), ("case2_writer_b", 1.2), ("case1_cart", 4.0)])
def test_time_terms_of_phi_are_the_moves_and_ramps(scene, duration):
    """φ's time terms (written by the compiled plan_phi.write_phi) are bitwise each move's σ, σ'/T
    (trajectory.profile) and each ramp's set-point (Ramp.at), before, inside and after every move and ramp and
    at both sides of each corner: constant velocity, trapezoid, triangle, velocity ramp, exponential, step
    and linear set-points."""
    system = System(load_scene(scene, {"duration": duration, "solver.output_rate": 10.0}))
    run_system(system)
    x0, _ = system.initial_state()
    checked = 0
    for plan in (p for p in _PLANS[system].values() if p.ok and len(p.time_moves) + len(p.time_ramps)):
        corners = [c for _, m in plan.time_moves for c in m.corners()] + [c for _, r, _ in plan.time_ramps
                                                                             for c in r.corners()]
        for t in np.concatenate([np.linspace(-0.5, 6.0, 101), np.ravel(corners)]):
            phi = plan.phi_at(float(t), x0)
            for slot, m in plan.time_moves:
                sigma, dsigma, _ = profile(m.kind, m.tau(t), m.accel_fraction)
                assert (phi[plan.i_e + slot], phi[plan.i_e + slot + 1]) == (sigma, dsigma / m.duration), t
            for slot, ramp, _ in plan.time_ramps:
                assert phi[plan.i_e + slot] == ramp.at(t)[0], t
            assert phi[-1] == 1.0
        checked += 1
    assert checked


def test_mode_flags_per_run_of_samples():
    """A channel read off the modes (touching, stuck) is the same evaluated once per run of samples
    sharing one modes list as per sample, runs of one and a list coming back included."""
    free, slide, stick = [ContactMode()], [ContactMode(True, False, (1.0,))], [ContactMode(True, True)]
    modes_of = [free] * 3 + [slide] + [stick] * 4 + [slide] * 2 + [free]
    for value in (lambda m: m[0].touching, lambda m: m[0].stuck):
        assert np.array_equal(_per_sample(modes_of, value), [float(value(m)) for m in modes_of])
    assert _per_sample([], lambda m: m[0].stuck).shape == (0,)


@pytest.mark.parametrize("scene", ["b1", "case2_writer_b", "hard_mass_ratio"])
def test_derivatives_of_many_states_are_the_calls_bitwise(scene):
    """``plan_derivatives`` (the dense output's extra stages all at once) gives bitwise the plan's call at
    each state (a stiff chain included: a last-bit difference there shows in the stages' rates at 1e-11)."""
    path = Path(__file__).resolve().parent.parent / "benchmarks" / "hard" / f"{scene[5:]}.toml"
    system = System(load_scene(str(path) if scene.startswith("hard_") else scene, {"solver.output_rate": 10.0}))
    run_system(system)
    rng = np.random.default_rng(5)
    x0, _ = system.initial_state()
    checked = 0
    for plan in (p for p in _PLANS[system].values() if p.ok):
        derivatives = plan_derivatives(plan)
        assert derivatives is not None
        ts = plan.phase.t_start + rng.uniform(0.0, 0.5, 40)
        X = x0 + 1e-3 * rng.normal(size=(40, system.n))
        got = derivatives(ts, X)
        for t, x, xd in zip(ts, X, got, strict=True):
            assert np.array_equal(plan.rhs(float(t), x.copy()), xd)
        checked += 1
    assert checked


@pytest.mark.parametrize("scene", ["case3_b_position", "case3_b_force", "writer"])
def test_law_over_all_samples_equals_the_per_sample_law(scene, monkeypatch):
    """A folded plan's output with the law's command over all samples at once (``folded_parts_all``) equals
    the law called per sample to round-off (1e-14 of each array's largest entry: a stacked product may sum
    in another order on another BLAS; on this machine's the two are bitwise equal); fails if the stacked
    torque, increments or inputs differ (the writer's 2 joints: sums of several nonzero terms)."""
    solve = samples._solve_folded_samples
    seen = []

    def both(plan, ts, X):
        got = solve(plan, ts, X)
        stacked = plan.__dict__.pop("folded_parts_all", None)
        try:
            want = solve(plan, ts, X)
        finally:
            if stacked is not None:
                plan.folded_parts_all = stacked
        seen.append(stacked is not None)
        for g, w in zip(got[:5], want[:5], strict=True):
            np.testing.assert_allclose(g, w, rtol=0.0, atol=1e-14 * max(float(np.max(np.abs(w), initial=0.0)), 1e-300))
        return got

    monkeypatch.setattr(samples, "_solve_folded_samples", both)
    monkeypatch.setattr(samples, "_kernel_samples", lambda plan, ts, X: None)  # (the path where the kernel declines)
    simulate(parse_scene(_pressing_writer()) if scene == "writer" else scene)
    assert any(seen)  # the stacked law ran


def test_stacked_pseudo_inverse_is_each_sample_s():
    """J⁺ over a stack equals each sample's J⁺ bitwise, and numpy's pinv (rcond 1e-10) to round-off, full rank or
    not (a zero sample: J⁺ = 0)."""
    from contactdyn.laws.controllers.dynamic import pseudo_inverse

    rng = np.random.default_rng(5)
    J = rng.normal(size=(40, 3, 5))
    for stack in (J, np.concatenate((J, np.zeros((1, 3, 5))))):
        want = np.array([pseudo_inverse(j) for j in stack])
        got = pseudo_inverse(stack)
        assert np.array_equal(got, want)
        assert np.allclose(got, np.linalg.pinv(stack, rcond=1e-10), rtol=0, atol=1e-12)
