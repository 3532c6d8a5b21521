"""A surface carried by a robot frame: it moves and turns with the robot (issue 32; ``sims/tilt_tray.toml``).

A 0.2 kg part rests on a tray on its rotation axis (a body with y and z coordinates, its bottom point touching;
``body = "robot"``, ``surface_frame = "tray"``: the surface's point and directions in the tray frame's own
coordinates). The robot tilts the tray at a constant rate. The tray under the part does not move (the part sits on
the axis), so while it sticks the part is exactly at rest: normal force m g cos θ and friction m g sin θ at every
sample, until tan θ = μ, where it slips; then it slides, the energy audit closing. The rows' directions and γ of a
turning surface (:func:`contactdyn.model.contact.turning_surface`) are checked by finite differences along a
smooth motion of a 5-joint arm.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from contactdyn import load_scene, parse_scene, simulate
from contactdyn.errors import SceneError
from contactdyn.model.contact import turning_surface
from contactdyn.model.paths import INTERPRETED, PIPELINE, LivePipelines
from contactdyn.model.system import System

MU, G, M_PART = 0.4, 9.81, 0.2  #: the scene's μ, gravity [m/s²] and the part's mass [kg]


@pytest.fixture(scope="module")
def run():
    return simulate("tilt_tray")


def _stuck(r) -> np.ndarray:
    return r["contact.rest.stuck"].astype(bool)


def test_the_part_sticks_exactly_at_rest_with_the_closed_form_forces(run):
    r = run
    theta, stuck = r["q"][:, 0], _stuck(run)
    assert stuck.sum() > 300 and stuck[0]
    np.testing.assert_allclose(r["contact.rest.F_n"][stuck], M_PART * G * np.cos(theta[stuck]), rtol=0, atol=1e-9)
    np.testing.assert_allclose(r["contact.rest.F_f"][stuck, 0], M_PART * G * np.sin(theta[stuck]), rtol=0, atol=1e-9)
    for coord in ("slide", "lift"):  # exactly at rest, where it started (on the axis)
        assert np.all(r[f"body.part.{coord}.v"][stuck] == 0.0) and np.all(r[f"body.part.{coord}.x"][stuck] == 0.0)
    assert np.all(np.tan(theta[stuck]) <= MU * (1 + 1e-12))


def test_it_slips_where_tan_theta_is_mu(run):
    """The slip event is located where μ_s F − |F_f| = m g (μ cos θ − sin θ) crosses zero, to the event locator's
    tolerance in time (δt ≲ 1e-10 s; θ̇ = 0.1 rad/s: δθ ≲ 1e-11 rad). θ at the event comes from the samples around
    it by cubic Hermite interpolation (q and q̇; 10 ms apart, θ nearly linear: an error ≪ 1e-9 rad), so the tilt
    at the slip matches arctan μ well inside 1e-6 rad."""
    r = run
    (t_slip,) = [e["t"] for e in r.events if e["kind"] == "slip" and e["name"] == "rest"]
    k = int(np.searchsorted(r.t, t_slip))
    t0, t1 = r.t[k - 1], r.t[k]
    q0, q1, v0, v1 = r["q"][k - 1, 0], r["q"][k, 0], r["v"][k - 1, 0], r["v"][k, 0]
    h, s = t1 - t0, (t_slip - t0) / (t1 - t0)
    theta = (2 * s**3 - 3 * s**2 + 1) * q0 + (s**3 - 2 * s**2 + s) * h * v0 + (-2 * s**3 + 3 * s**2) * q1 \
        + (s**3 - s**2) * h * v1
    assert abs(theta - np.arctan(MU)) < 1e-6, theta - np.arctan(MU)
    assert not _stuck(r)[k:].any()  # it slides on (the tray keeps tilting)


def test_it_slides_down_on_the_tray_with_mu_times_the_normal_force_and_the_energy_closes(run):
    r = run
    theta, sliding = r["q"][:, 0], ~_stuck(run)
    y, z = r["body.part.slide.x"], r["body.part.lift.x"]
    n = np.stack([-np.sin(theta), np.cos(theta)], axis=1)  # the tray's normal in (y, z)
    np.testing.assert_allclose(n[:, 0] * y + n[:, 1] * z, 0.0, rtol=0, atol=1e-9)  # on the turning tray
    down = np.cos(theta) * y + np.sin(theta) * z  # [m] along the tray's y: up the slope
    assert down[-1] < -0.05 and np.all(np.diff(down[sliding]) <= 0.0)
    assert np.all(r["contact.rest.v_slip"][sliding][1:, 0] < 0.0)
    np.testing.assert_allclose(r["contact.rest.F_f"][sliding, 0], MU * r["contact.rest.F_n"][sliding], rtol=1e-12)
    residual = r.meta["checks"]["energy_residual"]
    assert residual["value"] <= residual["tol"], residual


def test_the_tilt_runs_on_the_compiled_call_and_the_interpreted_run_agrees_through_the_slide(run, monkeypatch):
    """The whole run (test_both_ways runs 0.2 s: the stick only) compiled and interpreted, at test_both_ways' tight
    tolerances (rtol 1e-11): every channel to 1e-8 of its largest value (measured: 5.4e-10, the tray's joint
    velocity just after the slip, t ≈ 3.9 s, where the step control amplifies the two paths' rounding; the
    contact's forces and slip to 1e-11), the events' times to 1e-9 s."""
    assert {row["path"] for row in run.stats["paths"].values()} == {PIPELINE}
    tight = {"solver.rtol": 1e-11, "solver.atol": 1e-13}
    fast = simulate("tilt_tray", tight)
    monkeypatch.setattr(LivePipelines, "use", False)
    interpreted = simulate("tilt_tray", tight)
    assert {row["path"] for row in interpreted.stats["paths"].values()} == {INTERPRETED}
    for key, ref in interpreted.channels.items():
        ref, got = np.asarray(ref, float), np.asarray(fast.channels[key], float)
        if ref.size and not np.all(np.isnan(ref)):
            assert float(np.nanmax(np.abs(got - ref))) <= 1e-8 * float(np.nanmax(np.abs(ref))) + 1e-10, key
    assert [(e["kind"], e["name"]) for e in fast.events] == [(e["kind"], e["name"]) for e in interpreted.events]
    np.testing.assert_allclose([e["t"] for e in fast.events], [e["t"] for e in interpreted.events], rtol=0,
                               atol=1e-9)


# ---- the rows of a turning surface, by finite differences ----------------------------------------------------------

def _motion(t: float, q0: np.ndarray, a: np.ndarray, w: np.ndarray, phi: np.ndarray):
    """q, q̇, q̈ of a smooth motion q0 + a sin(w t + φ) [rad, rad/s, rad/s²]."""
    s, c = np.sin(w * t + phi), np.cos(w * t + phi)
    return q0 + a * s, a * w * c, -a * w * w * s


def _relative(robot, fid_touch: int, fid_surface: int, q, v, p0, n0, T0):
    robot.update(q, v)
    ft, fs = robot.frame_terms(fid_touch), robot.frame_terms(fid_surface)
    out = turning_surface(ft.position, ft.velocity, ft.jacobian, ft.drift, fs.position, fs.velocity, fs.jacobian,
                          fs.drift, fs.rotation, fs.angular_jacobian @ v, fs.angular_jacobian, fs.angular_drift,
                          p0, n0, T0)
    return ft.position, out  # (J_rel, a_rel, p_s, v_m, n, T)


def test_the_rows_and_their_gamma_are_the_derivatives_of_the_gap_and_the_relative_velocity():
    """Along a random smooth motion of a 5-joint arm, its tip touching a surface carried by its 3rd link: ġ equals
    n·(J_rel q̇) (g = n·(p − p_s)), and d/dt (u·v_rel) equals u·(J_rel q̈) + u·a_rel for u = n and T (central
    differences, h = 1e-5 s: truncation ~1e-10, round-off ~1e-11)."""
    robot = System(load_scene("case2_writer5dof")).robot
    tip, link = robot.frame_id("tip"), robot.frame_id("link3")
    rng = np.random.default_rng(32)
    q0 = rng.uniform(-1.0, 1.0, robot.nv)
    a, w, phi = rng.uniform(0.2, 0.6, robot.nv), rng.uniform(1.0, 3.0, robot.nv), rng.uniform(0, 6.3, robot.nv)
    p0 = rng.normal(size=3) * 0.1
    n0 = rng.normal(size=3)
    n0 /= np.linalg.norm(n0)
    t0 = np.cross(n0, rng.normal(size=3))
    T0 = (t0 / np.linalg.norm(t0))[None]
    h = 1e-5

    def at(t: float):
        q, v, acc = _motion(t, q0, a, w, phi)
        p, (J_rel, a_rel, p_s, v_m, n, T) = _relative(robot, tip, link, q, v, p0, n0, T0)
        v_rel = J_rel @ v
        gap = float(n @ (p - p_s))
        rates = np.concatenate([[n @ v_rel], T @ v_rel])  # u·v_rel for u = n, T
        accelerations = np.concatenate([[n @ (J_rel @ acc + a_rel)], T @ (J_rel @ acc + a_rel)])
        return gap, rates, accelerations

    for t in rng.uniform(0.0, 5.0, 8):
        (g_minus, r_minus, _), (g_plus, r_plus, _) = at(t - h), at(t + h)
        _, rates, accelerations = at(t)
        np.testing.assert_allclose((g_plus - g_minus) / (2 * h), rates[0], rtol=0, atol=1e-8)
        np.testing.assert_allclose((r_plus - r_minus) / (2 * h), accelerations, rtol=0, atol=1e-7)


# ---- a surface carried by the robot, given wrong: one clear error ----------------------------------------------------

def _doc():
    scene = load_scene("tilt_tray")
    return dict(scene.document), scene.file


@pytest.mark.parametrize("edit, key, words", [
    (lambda c: c.pop("surface_frame"), "contact.rest.surface_frame", "required"),
    (lambda c: c.update(body="ground"), "contact.rest.surface_frame", 'body = "robot"'),
    (lambda c: c.update(surface_frame="nowhere"), "contact.rest.surface_frame", "a frame of the robot"),
])
def test_a_robot_carried_surface_given_wrong_or_unsupported_is_one_clear_error(edit, key, words):
    doc, file = _doc()
    contact = {k: (dict(v) if isinstance(v, dict) else v) for k, v in doc["contact"]["rest"].items()}
    doc = {**doc, "contact": {"rest": contact}}
    edit(contact)
    with pytest.raises(SceneError) as err:
        simulate(parse_scene(doc, None, file))  # (the frame is resolved with the robot: at the run's start)
    assert key in str(err.value) and words in str(err.value), str(err.value)


def test_the_viewer_turns_the_force_arrows_with_the_tray():
    """The normal force's arrow on the part stays along the tray's normal as the tray tilts: from its tail to the
    contact point it points along the tray frame's z turned by the joint's angle θ, (0, −sin θ, cos θ)."""
    from contactdyn.viewer.build import build_scene

    r = simulate("tilt_tray", {"solver.output_rate": 20.0, "duration": 3.0})
    scene = build_scene(r)
    tracks = {a["path"]: {t["name"][1:]: np.array([k["value"] for k in t["keys"]]) for t in a["clip"]["tracks"]}
              for a in scene.commands[-1]["animations"]}
    tail = tracks["/meshcat/forces/rest_normal"]["position"]
    tip = tracks["/meshcat/tool/rest/ball"]["position"] if "/meshcat/tool/rest/ball" in tracks else \
        np.zeros_like(tail)  # (the part rests on the axis: its ball may not move)
    theta = np.interp(np.linspace(0.0, 3.0, len(tail)), r.t, r["q"][:, 0])
    arrow = (tip - tail) / np.linalg.norm(tip - tail, axis=1)[:, None]
    np.testing.assert_allclose(arrow, np.column_stack([0 * theta, -np.sin(theta), np.cos(theta)]), atol=1e-5)
    assert theta[-1] > 0.25  # it did turn


def test_a_force_set_point_on_a_turning_surface_is_one_clear_error():
    doc, file = _doc()
    rest = {k: v for k, v in doc["contact"]["rest"].items() if k != "frame_point"}
    doc = {**doc, "contact": {"rest": {**rest, "frame": "tip"}},  # a robot frame on a surface the robot carries
           "phase": [{**doc["phase"][0], "force": [{"contact": "rest", "value": 1.0}]}]}
    with pytest.raises(SceneError) as err:
        parse_scene(doc, None, file)
    assert "phase[0].force[0].contact" in str(err.value) and "does not turn" in str(err.value), str(err.value)


def test_with_2d_friction_the_part_slides_straight_down_the_slope_as_with_1d():
    """The tray's x and y both friction directions: the part slips at the same instant (1e-9 s) and slides straight
    down the slope, its slip and friction along the tray's x exactly 0, its motion the 1-D run's to 1e-9 m; the slide
    launching from rest runs on the compiled call (its slip and acceleration along the turning tangents,
    ``pipeline.contacts.tangential_motion``) and the interpreted run agrees to 1e-9."""
    doc, file = _doc()
    rest = {**doc["contact"]["rest"], "tangent": {**doc["contact"]["rest"]["tangent"],
                                                  "directions": [[0.0, 1.0, 0.0], [1.0, 0.0, 0.0]]}}
    scene = parse_scene({**doc, "contact": {"rest": rest}}, None, file)
    two, one = simulate(scene), simulate("tilt_tray")
    assert {row["path"] for row in two.stats["paths"].values()} == {PIPELINE}
    interpreted = simulate(scene, compiled=False)
    assert {row["path"] for row in interpreted.stats["paths"].values()} == {INTERPRETED}
    for key in ("body.part.slide.x", "body.part.lift.x", "contact.rest.F_n", "contact.rest.F_f", "q"):
        ref = np.asarray(interpreted[key], float)
        np.testing.assert_allclose(two[key], ref, rtol=0, atol=1e-9 * np.abs(ref).max(), err_msg=key)
    assert [(e["kind"], e["name"]) for e in two.events] == [(e["kind"], e["name"]) for e in one.events]
    assert abs(two.events[-1]["t"] - one.events[-1]["t"]) < 1e-9
    for key in ("body.part.slide.x", "body.part.lift.x"):
        np.testing.assert_allclose(two[key], one[key], rtol=0, atol=1e-9)
    assert np.all(two["contact.rest.v_slip"][:, 1] == 0.0) and np.all(two["contact.rest.F_f"][:, 1] == 0.0)


PART_XYZ = (Path(__file__).resolve().parents[1] / "sims" / "part_yz.urdf").read_text().replace(
    '<joint name="slide"', '<joint name="across" type="prismatic"><parent link="base"/><child link="sled"/>'
    '<axis xyz="1 0 0"/><limit lower="-10" upper="10" effort="1e4" velocity="100"/></joint><link name="sled"/>'
    '<joint name="slide"').replace('<parent link="base"/>\n    <child link="carriage"/>',
                                   '<parent link="sled"/>\n    <child link="carriage"/>')


def test_with_2d_friction_along_turned_tangents_the_launch_finds_the_slope_on_both_paths(tmp_path):
    """The part on three slides (x too) and tangents at 53° to the slope, (0.6, 0.8, 0) and (−0.8, 0.6, 0) in the
    tray's frame: the slide launching from rest must find d = (0.8, 0.6) (down the slope) by its Newton over the
    turning tangents. The compiled run and the interpreted one agree to 1e-9, and the part's motion is the 1-D
    run's to 1e-9 m (the same physics; nothing pushes it along x). At rtol 1e-11, as the 1-D comparison above. The
    friction force to 1e-7 of its largest value (measured: 5e-11; against the readable model's run it was 3e-8 at
    the sample inside the launch, slip within the stick band, d the Newton's, each Newton stopping at its own
    tolerance)."""
    (tmp_path / "part_xyz.urdf").write_text(PART_XYZ)
    doc, _ = _doc()
    doc["solver"] = {**doc["solver"], "rtol": 1e-11, "atol": 1e-13}
    rest = {**doc["contact"]["rest"], "tangent": {**doc["contact"]["rest"]["tangent"],
                                                  "directions": [[0.6, 0.8, 0.0], [-0.8, 0.6, 0.0]]}}
    body = {"part": {**doc["body"]["part"], "urdf": "part_xyz.urdf"}}
    scene = parse_scene({**doc, "contact": {"rest": rest}, "body": body}, None, tmp_path / "tray.toml")
    two, one, interpreted = simulate(scene), simulate("tilt_tray"), simulate(scene, compiled=False)
    assert {row["path"] for row in two.stats["paths"].values()} == {PIPELINE}
    assert {row["path"] for row in interpreted.stats["paths"].values()} == {INTERPRETED}
    for key, tol in (("body.part.slide.x", 1e-9), ("body.part.lift.x", 1e-9), ("contact.rest.F_n", 1e-9),
                     ("contact.rest.F_f", 1e-7), ("q", 1e-9)):
        ref = np.asarray(interpreted[key], float)
        np.testing.assert_allclose(two[key], ref, rtol=0, atol=tol * np.abs(ref).max(), err_msg=key)
    for key in ("body.part.slide.x", "body.part.lift.x"):
        np.testing.assert_allclose(two[key], one[key], rtol=0, atol=1e-9)
    np.testing.assert_allclose(two["body.part.across.x"], 0.0, atol=1e-12)
    sliding = ~two["contact.rest.stuck"].astype(bool)
    slip = two["contact.rest.v_slip"][sliding]
    moving = np.linalg.norm(slip, axis=1) > 1e-6
    assert moving.sum() > 50
    directions = slip[moving] / np.linalg.norm(slip[moving], axis=1)[:, None]
    np.testing.assert_allclose(directions, np.tile([-0.8, -0.6], (len(directions), 1)), rtol=0,
                               atol=1e-8)  # down the slope: −y of the tray (just launched: the Newton's 3e-9)
