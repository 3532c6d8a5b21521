"""Every scene in sims/ loads and runs (a shortened smoke run), plus the scene-level checks.

Smoke runs override ``duration`` (long enough to pass each scene's first contact) and use a
low ``output_rate``; the full runs are the benchmark's and the reproduction document's job.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from contactdyn import simulate
from contactdyn.scene.scene_file import load_scene, sims_dir

SCENES = sorted(p.stem for p in sims_dir().glob("*.toml"))

#: [s] smoke-run length per scene: past the first contact (and its impact) where there is one
SMOKE_DURATION = {"b1": 0.3, "case1_cart": 1.2, "case2_writer_b": 1.2, "case2_writer_rigid": 1.2,
                  "case2_writer_motors": 1.2}
SMOKE_DURATION.update({f"case3_{env}_{law}": 1.6 for env in "ab" for law in ("position", "force")})
SMOKE_DURATION["case3_b_force_varied"] = 1.6
CASE3 = ("case3_b_position", "case3_a_position", "case3_b_force", "case3_a_force", "case3_b_force_varied")
CASE_SCENES = ("case1_cart", "case2_writer_b", "case2_writer_rigid", "case2_writer_motors", "case2_writer5dof", *CASE3)


def test_sims_folder_holds_the_case_scenes():
    for name in CASE_SCENES:
        assert name in SCENES


#: scenes on main that wait for another branch (remove an entry when its branch lands)
PENDING: dict[str, str] = {}


@pytest.mark.parametrize("name", [pytest.param(n, marks=pytest.mark.xfail(reason=PENDING[n], strict=False))
                                  if n in PENDING else n for n in SCENES])
def test_scene_loads_and_smoke_runs(name):
    scene = load_scene(name)
    assert scene.description, f"{name}: a scene says what it is"
    duration = min(scene.duration, SMOKE_DURATION.get(name, 0.3))
    result = simulate(name, {"duration": duration, "solver.output_rate": 200.0})
    assert result.t[-1] == pytest.approx(duration)
    for channel, values in result.channels.items():
        if channel.endswith(".F_d") or channel == "tip_ref":  # NaN where a phase has no set-point / reference
            continue
        assert np.all(np.isfinite(values)), f"{name}: channel {channel} has non-finite values"


def test_writer_retouch_after_separation_is_seen():
    """Regression: right after the impact at B the tip separates at zero gap and comes back within
    ~1 ms (the force ramp pushes it); a touch event that started at zero missed the re-touch and
    the tip sank 0.4 m through the surface. Free contacts must never penetrate."""
    result = simulate("case2_writer_b", {"duration": 1.1, "solver.output_rate": 5000.0})
    free = result["contact.tip.touching"] == 0.0
    assert free.any()
    assert result["contact.tip.gap"][free].min() > -1e-9  # [m] only the touch tolerance
    assert len(result.impacts) == 2  # the impact at B, then the re-touch's small one
    assert result["contact.tip.F_n"][-1] > 50.0  # [N] pressing, following the 100 N ramp


def test_writer_stick_to_slip_at_the_cone_edge_does_not_storm():
    """Regression: the slip event fired exactly on the cone edge μF, where the stick test (which
    allows a tolerance) re-stuck at once: a stick/slip event storm at t = 1.31 s. The slip event
    now fires a tolerance beyond what the stick test accepts."""
    result = simulate("case2_writer_b", {"duration": 1.5, "solver.output_rate": 200.0})
    kinds = [e["kind"] for e in result.events if e["t"] > 1.0]
    assert kinds.count("slip") == 1
    after = result.t > 1.4
    F_n, F_f = result["contact.tip.F_n"][after], result["contact.tip.F_f"][after, 0]
    np.testing.assert_allclose(np.abs(F_f), 0.4 * F_n, rtol=1e-9)  # sliding: |F_f| = μ F


def test_writer_impact_momenta_near_the_papers_and_inside_the_cone():
    """Case 2's impact at B (model b surface): the paper gives FΔt = 0.0368 N·s and
    F_fΔt = −0.0157 N·s. Our approach gains are chosen so FΔt lands within 5 % (0.0360); the
    friction impulse has the paper's sign (the tip slides towards +x) and obeys the Coulomb cone
    |F_fΔt| ≤ μ FΔt (the impact jams: strictly less). The paper's ratio 0.427 > μ = 0.4 would
    violate it, so it cannot be matched by a consistent plastic impact."""
    result = simulate("case2_writer_b", {"duration": 1.0, "solver.output_rate": 100.0})
    impact = result.impacts[0]
    F, (F_f,) = impact["normal_impulse"], impact["friction_impulse"]
    assert F == pytest.approx(0.0368, rel=0.05)  # [N·s]
    assert F_f < 0.0 and abs(F_f) <= 0.4 * F * (1 + 1e-12)
    assert impact["jammed"] and abs(F_f) / F < 0.4


def test_case_scene_comments_cite_their_choices():
    """Each case scene comments its parameters: the paper's section or 'our choice'."""
    for name in SCENES:
        if not name.startswith("case"):
            continue
        text = (sims_dir() / f"{name}.toml").read_text()
        assert "sec." in text and "our choice" in text, name
        assert not math.isnan(load_scene(name).duration)


# ---- case 1: the cart --------------------------------------------------------------------
@pytest.fixture(scope="module")
def cart_run():
    return simulate("case1_cart", {"solver.output_rate": 2000.0})


def test_cart_stages_are_named_from_body_and_tip(cart_run):
    """Stages count from the body (env1 = x″_e, env2 = x′_e) and from the tip (rob1, rob2), masses skipped."""
    for d in ("n", "t1"):
        assert {k.split(".")[3] for k in cart_run.channels if k.startswith(f"stage.tip.{d}.")} == \
            {"env1", "env2", "rob1", "rob2"}


def test_cart_interface_junction_balances_both_sides(cart_run):
    """Regression: the massless point where the two external stages meet carried only the cart
    side's stage, so the interface force was 0 at every touch (touch/separate storm). It must
    balance: x′_e's force = x′_r's force = the contact force, in both directions."""
    touching = cart_run["contact.tip.touching"] > 0
    for d, F in (("n", "contact.tip.F_n"), ("t1", "contact.tip.t1.F")):
        F_e, F_r = cart_run[f"stage.tip.{d}.env2.F"][touching], cart_run[f"stage.tip.{d}.rob2.F"][touching]
        np.testing.assert_allclose(F_e, F_r, rtol=0, atol=1e-9 * np.abs(F_e).max())
        np.testing.assert_allclose(cart_run[F][touching], F_e, rtol=0, atol=1e-9 * np.abs(F_e).max())


def test_cart_chains_meet_undeformed_at_every_touch(cart_run):
    """Regression: on a re-touch the tangential chain was re-anchored without its previous
    offset, starting at 0.12 m compression (1250 N). At each touch the interface stages start
    (nearly) undeformed: |x| ≤ relative speed × one output interval."""
    touches = [e["t"] for e in cart_run.events if e["kind"] == "touch"]
    assert len(touches) >= 1
    for t_touch in touches:
        k = int(np.searchsorted(cart_run.t, t_touch))
        for d in ("n", "t1"):
            for stage in ("env2", "rob2"):
                assert abs(cart_run[f"stage.tip.{d}.{stage}.x"][k]) < 1e-4, (t_touch, d, stage)


def test_cart_chain_ends_relax_exponentially_between_separation_and_retouch():
    """After the separation the four interface stages (free ends, b/k = 1 ms) relax as
    x(t) = x(t0) exp(−(t − t0) / 1 ms) (k x + b ẋ = 0) until the re-touch; before the first touch they
    stay undeformed (no state). With no max_step DOP853 steps 10 ms over that 1 ms decay, and its dense
    output strayed by 9 % of x(t0): the step is capped at one time constant while ends relax."""
    r = simulate("case1_cart", {"solver.output_rate": 2000.0, "solver.max_step": 1.0})
    (t_sep,) = [e["t"] for e in r.events if e["kind"] == "separate"]
    t_retouch = min(e["t"] for e in r.events if e["kind"] == "touch" and e["t"] > t_sep)
    t_touch = min(e["t"] for e in r.events if e["kind"] == "touch")
    between = (r.t > t_sep) & (r.t < t_retouch)
    k0 = int(np.argmax(between))
    assert between.sum() > 40
    for d in ("n", "t1"):
        for stage in ("env2", "rob2"):
            x = r[f"stage.tip.{d}.{stage}.x"]
            assert abs(x[k0]) > 1e-5  # they were deformed at the separation
            relaxed = x[k0] * np.exp(-(r.t[between] - r.t[k0]) / 1e-3)
            assert np.max(np.abs(x[between] - relaxed)) <= 1e-5 * abs(x[k0]), (d, stage)
            assert np.max(np.abs(x[r.t < t_touch])) == 0.0, (d, stage)


def test_cart_forces_reach_their_set_points_and_the_cart_keeps_v0(cart_run):
    """F1 and F2 follow their exponential ramps to 100 N (sec. 5.1): over the last second (1 s after
    the ramps' five time constants) both average 100 N within 0.5 % and every sample stays within 5 %
    (the internal masses ring, Figs. 11-12). The push's reference is relative to the cart (eq. 5) and,
    while touching, F/k beyond the chains' anchors; with a world-frame reference F1 came out at 87 N.
    The cart keeps v0: the servo yields 100 N / 5e4 N·s/m = 2 mm/s (0.8 %)."""
    last = cart_run.t > cart_run.t[-1] - 1.0
    for channel in ("contact.tip.F_n", "contact.tip.t1.F"):  # F2, F1 [N]
        assert cart_run[channel][last].mean() == pytest.approx(100.0, rel=0.005), channel
        np.testing.assert_allclose(cart_run[channel][last], 100.0, rtol=0.05, err_msg=channel)
    np.testing.assert_allclose(cart_run["contact.tip.t1.F_d"][last], 100.0, rtol=0.01)  # 99.3 % 1 s into the ramp
    np.testing.assert_allclose(cart_run["body.cart.v"], 0.25, rtol=0.01)  # [m/s]
    assert np.abs(cart_run["body.cart.u"]).max() > 1.0  # the cart's motor does it [V]
    push = cart_run.t > 1.0
    on_cart = cart_run["tip_ref"][push, 0] - cart_run["body.cart.x"][push]  # [m] the reference rides on the cart
    np.testing.assert_allclose(on_cart, on_cart[-1], atol=0.041)  # only the 40 mm F1_d/k move relative to it


def test_cart_internal_deformations_oscillate_while_external_ones_settle(cart_run):
    """Figs. 11-12 (sec. 5.1): "external deformations (x′_e and x′_r) change towards constant values,
    while internal deformations (x″_e and x″_r) are oscillatory". Over the last second, in both
    directions, each internal stage swings at least twice as much as each external one (we measure
    about 3x) around the same mean (~10 mm: the chain's four stages carry the same ~100 N)."""
    last = cart_run.t > cart_run.t[-1] - 1.0
    for d in ("n", "t1"):
        swing = {s: np.ptp(cart_run[f"stage.tip.{d}.{s}.x"][last]) for s in ("env1", "env2", "rob1", "rob2")}
        assert min(swing["env1"], swing["rob1"]) > 2.0 * max(swing["env2"], swing["rob2"]), (d, swing)
        means = [cart_run[f"stage.tip.{d}.{s}.x"][last].mean() for s in swing]
        np.testing.assert_allclose(means, np.mean(means), rtol=0.02)


def test_force_direction_must_name_a_tangent_the_contact_has():
    from contactdyn.errors import SceneError

    with pytest.raises(SceneError, match=r"phase\[1\].force\[1\].direction.*'n' or one of contact 'tip'"):
        load_scene("case1_cart", {"phase.1.force.1.direction": "t2"})


# ---- case 3: the decoupled vertical axis (item 2) ------------------------------------------
@pytest.mark.parametrize("gravity", [[0.0, 0.0, 0.0], [0.0, 0.0, -9.81]], ids=["paper_no_gravity", "gravity"])
def test_cylindrical_full_model_gives_the_reduced_axis_motion(gravity):
    """Eqs 47-49: H13 = H23 = 0 and h3 has no q1/q2 terms, so the vertical axis moves the same in
    the full 3-DOF model, even while q1 and q2 move, as in the model reduced to q3 (both runs
    with tight tolerances; they differ only by integration error). q3 keeps its elastic drive,
    q1 and q2 get ideal ones; the approach, the impact and A7's contact phase are all compared."""
    tight = {"duration": 1.7, "solver.output_rate": 500.0, "solver.rtol": 1e-12, "solver.atol": 1e-14,
             "robot.gravity": gravity}
    reduced = simulate("case3_b_position", tight)
    full = simulate("case3_b_position", {**tight, "robot.active_joints": ["q1", "q2", "q3"],
                                         "robot.q0": [0.3, 0.2, 0.0], "robot.v0": [0.5, -0.1, 0.0],
                                         "robot.drive.kind": ["torque", "torque", "elastic"]})
    assert np.ptp(full["q"][:, 0]) > 0.5 and np.ptp(full["q"][:, 1]) > 0.05  # the other axes really move
    assert len(reduced.impacts) == len(full.impacts) >= 1
    np.testing.assert_allclose(full["q"][:, 2], reduced["q"][:, 0], rtol=0, atol=1e-8)  # [m]
    np.testing.assert_allclose(full["tip"][:, 2], reduced["tip"][:, 2], rtol=0, atol=1e-8)  # [m]
    F_red = reduced["contact.tip.F_n"]
    np.testing.assert_allclose(full["contact.tip.F_n"], F_red, rtol=0, atol=1e-8 * np.abs(F_red).max())  # [N]
    for a, b in zip(full.impacts, reduced.impacts, strict=True):
        assert a["normal_impulse"] == pytest.approx(b["normal_impulse"], rel=1e-8)


@pytest.fixture(scope="module")
def case3_runs():
    return {name: simulate(name, {"solver.output_rate": 500.0}) for name in CASE3}


@pytest.mark.parametrize("name", CASE3[:4])
def test_case3_force_follows_its_ramp_to_100_N(case3_runs, name):
    """Figs. 17-19 (nominal): both laws, both surfaces bring the force to its 100 N set-point through
    the elastic transmission, without twist damping (the drive as the paper writes it): within
    0.5 N over the last 0.5 s of the 5 s run (the impact on model (b), or the continuous touch on
    model (a), overshoots first; the gains inside the stable region are slow, dominant poles
    −2.6 to −4.4 /s, so the 3 s runs of the damped scenes would not have settled)."""
    r = case3_runs[name]
    assert load_scene(name).robot.drive.values.get("twist_damping", 0.0) == 0.0
    last = r.t > r.t[-1] - 0.5
    np.testing.assert_allclose(r["contact.tip.F_n"][last], 100.0, atol=0.5)  # [N]
    assert np.all(r["contact.tip.F_d"][last] == 100.0)
    assert np.abs(r["u"]).max() > 1.0 and "drive.q3.theta" in r.channels  # through the motor and the tube
    assert len(r.impacts) == (2 if "_b_" in name else 0)  # model (b): impact and a bounce; (a): continuous


def test_case3_force_law_position_tracking_degrades_with_the_varied_surface(case3_runs):
    """Fig. 19: the force law believing k = 1e5 N/m holds the nominal surface at its 1 mm depth;
    on the varied surface (m' = 5 kg, k = 1e3 N/m, b = 0) the tip keeps sinking (tens of mm, not
    settled) and the force lags far behind its set-point. With the scenes' K_F = 3 /s (the stable
    region without twist damping) the slow pole is about −K_F k/k̂ = −0.03 /s: the tip sinks
    ~2 mm over the last second (5 mm with the former K_F = 20)."""
    nominal, varied = case3_runs["case3_b_force"], case3_runs["case3_b_force_varied"]
    last = nominal.t > nominal.t[-1] - 1.0
    depth_nominal = 0.2 - nominal["tip"][last, 2]  # [m] below the undeformed surface
    depth_varied = 0.2 - varied["tip"][last, 2]
    np.testing.assert_allclose(depth_nominal, 100.0 / 1e5, rtol=0.01)  # F_d / k = 1 mm, settled
    assert depth_varied.min() > 10 * 100.0 / 1e5 and np.ptp(depth_varied) > 1e-3  # > 10 mm, still moving > 1 mm/s
    assert np.abs(varied["contact.tip.F_n"][last] - 100.0).min() > 50.0  # [N]
