"""A tool pushes a box along a table (issue 32, item 4: ``sims/push_box.toml``).

The box is a body from a URDF with two orthogonal prismatic joints (x along the table, z up), its bottom a
contact with the ground (a body's point touching, with Coulomb friction μ = 0.3), its left face the surface the
tool pushes. Once the tool stops (faster than μ g) the box slides alone, decelerating at μ g exactly, and sticks
after v / (μ g) [s] and v² / (2 μ g) [m]: at every sample of the slide, its speed is μ g (t_stop − t) and the
distance still to go μ g (t_stop − t)² / 2, both to the event tolerance.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from contactdyn import load_scene, parse_scene, simulate
from contactdyn.errors import SceneError
from contactdyn.model.paths import INTERPRETED, PIPELINE
from contactdyn.output.physics_checks import violations

MU, G, M_BOX = 0.3, 9.81, 1.0  #: the scene's μ, gravity [m/s²] and the box's mass [kg]
BAND = 1e-9  #: [m/s] the stick band v_ε (solver.stick_velocity's default): a stop event is where |v_t| falls to it


@pytest.fixture(scope="module")
def run():
    return simulate("push_box")


def _instant(r, kind: str, name: str, after: float = 0.0) -> float:
    return next(e["t"] for e in r.events if e["kind"] == kind and e["name"] == name and e["t"] > after)


def test_the_released_box_slides_and_stops_where_the_closed_form_says(run):
    r = run
    t_release = _instant(r, "separate", "push")
    t_stop = _instant(r, "stick", "floor", t_release)
    x, v = r["body.box.slide.x"], r["body.box.slide.v"]
    x_stop = x[-1]
    sliding = (r.t > t_release) & (r.t < t_stop)
    assert sliding.sum() >= 5
    tau = t_stop - r.t[sliding]  # [s] still to go (the stop event: at the stick band v_ε, then held)
    np.testing.assert_allclose(v[sliding], BAND + MU * G * tau, rtol=0, atol=1e-12)  # v = μ g (t_stop − t)
    np.testing.assert_allclose(x_stop - x[sliding], BAND * tau + MU * G * tau ** 2 / 2, rtol=0,
                               atol=1e-12)  # v² / (2 μ g)
    stopped = r.t > t_stop
    assert np.all(v[stopped] == 0.0) and np.all(x[stopped] == x_stop)  # stuck: exactly at rest
    v_release = MU * G * (t_stop - t_release)  # [m/s] what the box left the tool with
    assert 0.15 < v_release < 0.21  # the tool's cruise: 0.2 m / 0.98 s
    assert np.all(r["contact.push.gap"][stopped] > 0.0)  # the tool stopped behind it


def test_the_table_carries_the_weight_and_friction_is_mu_times_it(run):
    r = run
    np.testing.assert_allclose(r["contact.floor.F_n"], M_BOX * G, rtol=1e-9)
    assert np.abs(r["body.box.lift.x"]).max() < 1e-12  # the box stays on the table
    slid = r["contact.floor.v_slip"][:, 0] > 1e-6
    assert slid.sum() >= 100
    np.testing.assert_allclose(r["contact.floor.F_f"][slid, 0], -MU * M_BOX * G, rtol=1e-12)
    cruise = (r.t > 0.6) & (r.t < 0.95)  # the tool at constant speed (its transient gone): it pushes with the friction
    np.testing.assert_allclose(r["contact.push.F_n"][cruise], MU * M_BOX * G, rtol=1e-6)  # force


def test_the_push_runs_on_the_compiled_call(run):
    assert {row["path"] for row in run.stats["paths"].values()} == {PIPELINE}
    assert run.stats["compiled_modes"] >= 3


def _doc():
    scene = load_scene("push_box")
    return dict(scene.document), scene.file


@pytest.mark.parametrize("edit, key, words", [
    (lambda d: d["contact"]["push"].update(frame_point=[0.0, 0.0, 0.0]), "contact.push.frame",
     "a body beside frame_point"),
    (lambda d: d["contact"]["floor"].pop("frame_point"), "contact.floor.frame", "with frame_point"),
    (lambda d: d["contact"]["floor"].update(body="box"), "contact.floor.frame", "other than the surface"),
    (lambda d: d["contact"]["floor"].update(frame_point=[0.3, float("nan"), 0.0]), "contact.floor.frame_point",
     "finite"),
    (lambda d: d["body"]["box"].update(servo={"velocity": 0.1}), "body.box.servo", "2 coordinates"),
    (lambda d: d["body"]["box"].update(position0=0.1), "body.box.position0", "a list of 2 numbers"),
    (lambda d: d["phase"][0].update(force=[{"contact": "floor", "value": 5.0}]), "phase[0].force[0].contact",
     "a contact the robot touches"),
    (lambda d: d["contact"]["floor"].update(normal={"direction": [0.0, 1.0, 0.0]}, tangent={"model": "free"}),
     "contact.floor.normal.direction", "nothing would carry its force"),
    (lambda d: d["phase"][0]["reference"].update(body="box"), "phase[0].reference.body", "one coordinate"),
])
def test_a_body_contact_or_coordinate_given_wrong_is_one_clear_error(edit, key, words):
    doc, file = _doc()
    doc = {**doc, "contact": {k: dict(v) for k, v in doc["contact"].items()}, "body": {"box": dict(doc["body"]["box"])},
           "phase": [{**p, "reference": dict(p["reference"])} for p in doc["phase"]]}
    edit(doc)
    with pytest.raises(SceneError) as err:
        simulate(parse_scene(doc, None, file))  # (a robot frame is resolved with the robot: at the run's start)
    assert key in str(err.value) and words in str(err.value), str(err.value)


def test_a_body_with_two_coordinates_has_their_masses_axes_and_channels(run):
    box = load_scene("push_box").bodies["box"]
    assert [c.joint for c in box.coordinates] == ["slide", "lift"] and box.mass == 1.0
    assert box.axes.tolist() == [[1.0, 0.0, 0.0], [0.0, 0.0, 1.0]] and [c.mass for c in box.coordinates] == [1.0, 1.0]
    assert {"body.box.slide.x", "body.box.lift.v"} <= set(run.channels) and "body.box.x" not in run.channels


def _stacked(tmp_path, mu_top: float):
    """push_box with a second 1 kg box on top of the first (a contact between two bodies: the top's bottom point
    on the lower box's top face, friction ``mu_top``)."""
    sims = Path(__file__).parent.parent / "sims"
    urdf = tmp_path / "top.urdf"
    urdf.write_text((sims / "box_xz.urdf").read_text().replace('<origin xyz="0.3 0 0" rpy="0 0 0"/>',
                                                               '<origin xyz="0.3 0 0.1" rpy="0 0 0"/>'))
    doc, file = _doc()
    doc = {**doc, "body": {**doc["body"], "top": {"urdf": str(urdf)}},
           "contact": {**doc["contact"], "stack": {
               "frame": "top", "frame_point": [0.3, 0.0, 0.1], "body": "box", "point": [0.3, 0.0, 0.1],
               "normal": {"direction": [0.0, 0.0, 1.0]},
               "tangent": {"model": "friction", "directions": [[1.0, 0.0, 0.0]], "mu": mu_top}}}}
    return parse_scene(doc, None, file)


def test_a_box_on_a_box_is_left_behind_by_the_impact_dragged_at_mu_g_then_rides_stuck(tmp_path):
    """Two bodies in contact. The tool's impact on the lower box passes no impulse to the top one (friction with a
    finite normal force m g carries none): the top stays at rest, is dragged at μ_top g exactly until it sticks,
    then rides stuck (its place on the lower box fixed) through the stop (the pair decelerates at μ g = 2.94 m/s²
    < μ_top g). The lower box's top carries m g, the table 2 m g, and the pair stops v² / (2 μ g) after the
    release as one box would."""
    r = simulate(_stacked(tmp_path, 0.5))
    assert {row["path"] for row in r.stats["paths"].values()} == {PIPELINE}
    (impact,) = r.impacts
    assert impact["v_after"][2] > 0.05 and impact["v_after"][4] == 0.0  # [robot x, z, box x, z, top x, z]
    t_impact, t_ride = impact["t"], _instant(r, "stick", "stack", impact["t"])
    dragged = (r.t > t_impact) & (r.t < t_ride)
    assert dragged.sum() >= 5
    np.testing.assert_allclose(r["body.top.slide.v"][dragged], 0.5 * G * (r.t[dragged] - t_impact), rtol=0,
                               atol=1e-9)
    riding = r.t > t_ride
    offset = r["body.top.slide.x"][riding] - r["body.box.slide.x"][riding]
    assert np.ptp(offset) < 1e-12 and r["contact.stack.stuck"][riding].all()
    np.testing.assert_allclose(r["contact.stack.F_n"], M_BOX * G, rtol=1e-9)
    np.testing.assert_allclose(r["contact.floor.F_n"], 2 * M_BOX * G, rtol=1e-9)
    t_release = _instant(r, "separate", "push")
    t_stop = _instant(r, "stick", "floor", t_release)
    sliding = (r.t > t_release) & (r.t < t_stop)
    tau = t_stop - r.t[sliding]
    x = r["body.box.slide.x"]
    np.testing.assert_allclose(x[-1] - x[sliding], BAND * tau + MU * G * tau ** 2 / 2, rtol=0, atol=1e-12)


def test_a_box_on_a_slippery_box_slides_off_at_the_stop_decelerating_at_mu_top_g(tmp_path):
    """μ_top = 0.1: when the tool stops, the lower box decelerates faster than μ_top g; the top slides forward on
    it with friction −μ_top m g the whole way, on the moving box and then on the stopped one: its speed is
    μ_top g (t_end − t) from its slip to its stop."""
    r = simulate(_stacked(tmp_path, 0.1))
    t_slip = _instant(r, "slip", "stack", 0.5)
    t_end = _instant(r, "stop", "stack", t_slip)
    assert _instant(r, "stick", "floor", t_slip) < t_end  # the lower box stopped first
    sliding = (r.t > t_slip) & (r.t < t_end)
    assert sliding.sum() >= 20
    np.testing.assert_allclose(r["body.top.slide.v"][sliding], BAND + 0.1 * G * (t_end - r.t[sliding]), rtol=0,
                               atol=1e-12)
    np.testing.assert_allclose(r["contact.stack.F_f"][sliding, 0], -0.1 * M_BOX * G, rtol=1e-9)  # on the top


def test_two_bodies_in_contact_run_the_same_interpreted(tmp_path):
    """The slippery stack (impact, slides, sticks, body on body) on the compiled call and interpreted,
    the whole run at rtol 1e-11: the same events, each channel within 1e-9 of its largest value (+1e-10)."""
    scene = _stacked(tmp_path, 0.1)
    scene = parse_scene({**scene.document, "solver": {**scene.document["solver"], "rtol": 1e-11, "atol": 1e-13}},
                        None, scene.file)
    fast, interpreted = simulate(scene), simulate(scene, compiled=False)
    assert {row["path"] for row in fast.stats["paths"].values()} == {PIPELINE}
    assert {row["path"] for row in interpreted.stats["paths"].values()} == {INTERPRETED}
    assert [(e["kind"], e["name"]) for e in fast.events] == [(e["kind"], e["name"]) for e in interpreted.events]
    np.testing.assert_allclose([e["t"] for e in fast.events], [e["t"] for e in interpreted.events], rtol=0, atol=1e-9)
    for key, ref in interpreted.channels.items():
        ref, got = np.asarray(ref, float), np.asarray(fast.channels[key], float)
        scale = float(np.nanmax(np.abs(ref))) if ref.size and not np.all(np.isnan(ref)) else 0.0
        np.testing.assert_allclose(got, ref, rtol=0, atol=1e-9 * scale + 1e-10, err_msg=key)


def _compliant(floor: dict | None = None, push: dict | None = None):
    """push_box with a deformation model on the floor's normal (the box's point touching: its chain's tip is the
    box) or on the push's (its anchor on the box's face)."""
    doc, file = _doc()
    contact = {k: dict(v) for k, v in doc["contact"].items()}
    for name, model in (("floor", floor), ("push", push)):
        if model:
            contact[name]["normal"] = {**contact[name]["normal"], **model}
    return parse_scene({**doc, "contact": contact}, None, file)


def test_a_box_on_a_compliant_table_sinks_m_g_over_k_and_slides_on_the_chain_s_force():
    """The floor a Kelvin–Voigt surface (model c, k = 2e5 N/m): the box (the chain's touching side) rests
    m g / k = 49 µm deep, its friction while sliding is −μ F_n of the chain's force at every sample, and it still
    stops where the closed form says."""
    k = 2e5
    r = simulate(_compliant(floor={"model": "c", "k": k, "b": 400.0}))
    assert {row["path"] for row in r.stats["paths"].values()} == {PIPELINE}
    z, F_n = r["body.box.lift.x"], r["contact.floor.F_n"]
    np.testing.assert_allclose(z[-5:], -M_BOX * G / k, rtol=1e-9)  # at rest, stuck, at the end
    np.testing.assert_allclose(F_n[-5:], M_BOX * G, rtol=1e-9)
    slid = r["contact.floor.v_slip"][:, 0] > 1e-6
    assert slid.sum() >= 100
    np.testing.assert_allclose(r["contact.floor.F_f"][slid, 0], -MU * F_n[slid], rtol=1e-12)


@pytest.mark.parametrize("floor, push", [
    ({"model": "c", "k": 2e5, "b": 400.0}, None),
    (None, {"model": "b", "k": 5e4, "b": 50.0, "m": 0.01}),  # the pad's mass between the tool and the box
], ids=["compliant_floor", "padded_tool"])
def test_chains_on_a_body_s_contacts_run_the_same_interpreted(floor, push):
    """A chain whose tip is a body's point, and one whose anchor is on a body with two coordinates: the compiled
    call and the interpreted one agree over the whole run (rtol 1e-12; events, every channel within 1e-9 of its
    largest value, plus 1e-12 (SI units), 1e-7 for forces and the chains' channels: the step control amplifies the
    two paths' rounding to a few rtol·|x| in the states (~1e-12 m), which the pad's 5e4 N/m makes ~5e-8 N and its
    2.2e3 rad/s ~2e-9 m/s)."""
    scene = _compliant(floor, push)
    scene = parse_scene({**scene.document, "solver": {**scene.document["solver"], "rtol": 1e-12, "atol": 1e-14}},
                        None, scene.file)
    fast, interpreted = simulate(scene), simulate(scene, compiled=False)
    assert {row["path"] for row in fast.stats["paths"].values()} == {PIPELINE}
    assert {row["path"] for row in interpreted.stats["paths"].values()} == {INTERPRETED}
    assert [(e["kind"], e["name"]) for e in fast.events] == [(e["kind"], e["name"]) for e in interpreted.events]
    for key, ref in interpreted.channels.items():
        ref, got = np.asarray(ref, float), np.asarray(fast.channels[key], float)
        scale = float(np.nanmax(np.abs(ref))) if ref.size and not np.all(np.isnan(ref)) else 0.0
        stiff = key.startswith(("stage.", "mass.")) or key.endswith((".F_n", ".F_f", ".force")) or key == "tau"
        floor = 1e-7 if stiff else 1e-12
        np.testing.assert_allclose(got, ref, rtol=0, atol=1e-9 * scale + floor, err_msg=key)


def test_the_energy_audit_closes_with_bodies_rubbing_on_bodies(tmp_path):
    """The slippery stack with the audit on: the drives' work, the impact's loss and the friction between the boxes
    and on the table balance the bodies' and the tool's energy to 1e-9 J."""
    scene = _stacked(tmp_path, 0.1)
    r = simulate(parse_scene({**scene.document, "solver": {**scene.document["solver"], "record_energy": True}},
                             None, scene.file))
    audit = r.meta["checks"]["energy_residual"]
    assert audit["value"] is not None and audit["value"] < 1e-9 and violations(r.meta["checks"]) == []
    assert r.impacts and r.impacts[0]["energy_loss"] > 1e-3  # the impact's loss is in it


def test_a_frame_named_like_a_body_and_a_robot_frame_is_one_clear_error():
    doc, file = _doc()
    doc = {**doc, "body": {"tip": doc["body"]["box"]},
           "contact": {k: {**v, "body": "tip"} if v.get("body") == "box" else
                       {**v, "frame": "tip"} if v.get("frame") == "box" else v for k, v in doc["contact"].items()}}
    with pytest.raises(SceneError) as err:
        simulate(parse_scene(doc, None, file))
    assert "contact.floor.frame" in str(err.value) and "both" in str(err.value), str(err.value)


def test_the_body_velocity_figure_has_a_line_per_coordinate(run):
    from contactdyn.output.plots import FIGURES

    (panel,) = next(s for s in FIGURES if s.name == "fig10b_body_velocity").build(run)
    assert [line.label for line in panel.lines] == ["v_box.lift", "v_box.slide"]
    assert np.array_equal(panel.lines[1].y, run["body.box.slide.v"])


def test_a_box_on_three_slides_pushed_sideways_slides_in_2d_and_stops(tmp_path):
    """A body with three orthogonal coordinates (x, y, z) and 2-D Coulomb friction on the table, pushed along x by
    a tool moving along x and y: the table carries m g, the friction is μ m g against the slip, and the box ends
    stuck; both paths agree."""
    sims = Path(__file__).parent.parent / "sims"
    text = (sims / "box_xz.urdf").read_text().replace(
        '<child link="carriage"/>', '<child link="carriage_y"/>').replace(
        '<!-- massless carriage between the two slides -->',
        '<link name="carriage_y"/>\n  <joint name="side" type="prismatic">\n    <parent link="carriage_y"/>\n'
        '    <child link="carriage"/>\n    <origin xyz="0 0 0" rpy="0 0 0"/>\n    <axis xyz="0 1 0"/>\n'
        '    <limit lower="-10.0" upper="10.0" effort="1e4" velocity="100.0"/>\n  </joint>')
    (tmp_path / "box3.urdf").write_text(text)
    doc, file = _doc()
    doc = {**doc, "body": {"box": {"urdf": str(tmp_path / "box3.urdf")}},
           "contact": {**doc["contact"], "floor": {**doc["contact"]["floor"], "tangent": {
               "model": "friction", "directions": [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]], "mu": MU}}},
           "phase": [{**doc["phase"][0], "reference": {"moves": [{"kind": "trapezoid", "delta": [0.2, 0.0, 0.0],
                                                                 "duration": 1.0, "accel_fraction": 0.02}]}}]}
    r = simulate(parse_scene(doc, None, file))
    assert {"body.box.slide.x", "body.box.side.x", "body.box.lift.x"} <= set(r.channels)
    assert {row["path"] for row in r.stats["paths"].values()} == {PIPELINE}
    np.testing.assert_allclose(r["contact.floor.F_n"], M_BOX * G, rtol=1e-9)
    slip = r["contact.floor.v_slip"]
    sliding = np.linalg.norm(slip, axis=1) > 1e-6
    assert sliding.sum() >= 100
    F_f = r["contact.floor.F_f"][sliding]
    np.testing.assert_allclose(np.linalg.norm(F_f, axis=1), MU * M_BOX * G, rtol=1e-9)  # |F_f| = μ F_n
    np.testing.assert_allclose(np.einsum("ij,ij->i", F_f, slip[sliding]),  # against the slip
                               -np.linalg.norm(F_f, axis=1) * np.linalg.norm(slip[sliding], axis=1), rtol=1e-9)
    assert r["contact.floor.stuck"][-1] and np.abs(r["body.box.slide.v"][-1]) == 0.0


def _prismatic_urdf(joints) -> str:
    """A URDF of prismatic joints (name, parent link, child link, axis), each child a 1 kg link."""
    inertial = ('<inertial><mass value="1.0"/><inertia ixx="1e-3" ixy="0" ixz="0" iyy="1e-3" iyz="0" izz="1e-3"/>'
                '</inertial>')
    links = "".join(f'<link name="{child}">{inertial}</link>' for _, _, child, _ in joints)
    body = "".join(f'<joint name="{name}" type="prismatic"><parent link="{parent}"/><child link="{child}"/>'
                   f'<origin xyz="0 0 0" rpy="0 0 0"/><axis xyz="{axis}"/>'
                   '<limit lower="-1" upper="1" effort="1" velocity="1"/></joint>'
                   for name, parent, child, axis in joints)
    return f'<?xml version="1.0"?><robot name="bad"><link name="base"/>{links}{body}</robot>'


@pytest.mark.parametrize("joints, words", [
    ([("a", "base", "l1", "1 0 0"), ("b", "l1", "l2", "0 1 0"), ("c", "l2", "l3", "0 0 1"),
      ("d", "l3", "l4", "1 0 0")], "one to three prismatic joints"),
    ([("a", "base", "l1", "1 0 0"), ("b", "base", "l2", "0 0 1")], "joint b's parent is universe, not a"),
])
def test_a_body_urdf_with_a_fourth_or_branching_joint_is_one_clear_error(tmp_path, joints, words):
    (tmp_path / "bad.urdf").write_text(_prismatic_urdf(joints))
    doc, file = _doc()
    with pytest.raises(SceneError) as err:
        parse_scene({**doc, "body": {"box": {"urdf": str(tmp_path / "bad.urdf")}}}, None, file)
    assert "body.box.urdf" in str(err.value) and words in str(err.value), str(err.value)


def test_a_body_named_with_a_dot_keeps_its_channels():
    doc, file = _doc()
    doc = {**doc, "body": {"my.box": doc["body"]["box"]},
           "contact": {k: {**v, "body": "my.box"} if v.get("body") == "box" else
                       {**v, "frame": "my.box"} if v.get("frame") == "box" else v for k, v in doc["contact"].items()}}
    r = simulate(parse_scene(doc, {"duration": 0.1}, file))
    assert {"body.my.box.slide.x", "body.my.box.lift.x"} <= set(r.channels)
