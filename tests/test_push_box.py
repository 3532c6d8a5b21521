"""A tool pushes a box along a table (issue 32, item 4: ``sims/push_box.toml``).

The box is a body from a URDF with two orthogonal prismatic joints (x along the table, z up), its bottom a
contact with the ground (a body's point touching, with Coulomb friction μ = 0.3), its left face the surface the
tool pushes. Once the tool stops (faster than μ g) the box slides alone, decelerating at μ g exactly, and sticks
after v / (μ g) [s] and v² / (2 μ g) [m]: at every sample of the slide, its speed is μ g (t_stop − t) and the
distance still to go μ g (t_stop − t)² / 2, both to the event tolerance.
"""

from __future__ import annotations

import numpy as np
import pytest

from contactdyn import load_scene, parse_scene, simulate
from contactdyn.errors import SceneError
from contactdyn.model.paths import PIPELINE

MU, G, M_BOX = 0.3, 9.81, 1.0  #: the scene's μ, gravity [m/s²] and the box's mass [kg]


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
    tau = t_stop - r.t[sliding]  # [s] still to go
    np.testing.assert_allclose(v[sliding], MU * G * tau, rtol=0, atol=1e-8)  # v = μ g (t_stop − t)
    np.testing.assert_allclose(x_stop - x[sliding], MU * G * tau ** 2 / 2, rtol=0, atol=1e-9)  # v² / (2 μ g)
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
    (lambda d: d["contact"]["push"].update(frame_point=[0.0, 0.0, 0.0]), "contact.push.frame_point",
     "robot frame"),
    (lambda d: d["contact"]["floor"].pop("frame_point"), "contact.floor.frame_point", "required"),
    (lambda d: d["contact"]["floor"].update(body="box"), "contact.floor.frame", "another body"),
    (lambda d: d["body"]["box"].update(servo={"velocity": 0.1}), "body.box.servo", "2 coordinates"),
    (lambda d: d["body"]["box"].update(position0=0.1), "body.box.position0", "2"),
    (lambda d: d["phase"][0]["reference"].update(body="box"), "phase[0].reference.body", "one coordinate"),
])
def test_a_body_contact_or_coordinate_given_wrong_is_one_clear_error(edit, key, words):
    doc, file = _doc()
    doc = {**doc, "contact": {k: dict(v) for k, v in doc["contact"].items()}, "body": {"box": dict(doc["body"]["box"])},
           "phase": [{**p, "reference": dict(p["reference"])} for p in doc["phase"]]}
    edit(doc)
    with pytest.raises(SceneError) as err:
        parse_scene(doc, None, file)
    assert key in str(err.value) and words in str(err.value), str(err.value)


def test_a_body_with_two_coordinates_has_their_masses_axes_and_channels(run):
    box = load_scene("push_box").bodies["box"]
    assert [c.joint for c in box.coordinates] == ["slide", "lift"] and box.mass == 1.0
    assert box.axes.tolist() == [[1.0, 0.0, 0.0], [0.0, 0.0, 1.0]] and [c.mass for c in box.coordinates] == [1.0, 1.0]
    assert {"body.box.slide.x", "body.box.lift.v"} <= set(run.channels) and "body.box.x" not in run.channels
