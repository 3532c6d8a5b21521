"""A grasp that never creeps (issue 32, sims/pinch_hold.toml): two pads hold a 45 g part by true stick, its velocity
0 to rounding for 10 s; a grip lowered below m g / (2 μ) per pad lets it slip at the closed-form instant; a body's
weight m g·axis acts on it (free fall, and the energy audit)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from contactdyn import load_scene, parse_scene, simulate
from contactdyn.model.paths import PIPELINE
from contactdyn.output.physics_checks import violations

M, G, MU, KP, KD = 0.045, 9.81, 0.7, 1200.0, 20.0  #: the scene's part [kg], g [m/s²], μ, the fingers' PD


def _scene(overrides: dict | None = None, **doc_changes):
    base = load_scene("pinch_hold")
    return parse_scene({**base.document, **doc_changes}, overrides, base.file)


def test_the_part_is_held_without_creeping_for_ten_seconds():
    r = simulate("pinch_hold")
    assert violations(r.meta["checks"]) == []
    assert {row["path"] for row in r.stats["paths"].values()} == {PIPELINE}
    assert [e["kind"] for e in r.events] == ["stick", "stick"]  # both pads stick at the start and never slip
    v, x = r["body.part.v"], r["body.part.x"]
    assert r.t[-1] == pytest.approx(10.0)
    assert np.abs(v).max() < 1e-9 and np.abs(x - x[0]).max() < 1e-9  # [m/s], [m] (issue 32's bounds)
    for pad in ("left", "right"):  # the part's weight split evenly (the least-norm forces of two equal sticks)
        assert r[f"contact.{pad}.F_n"] == pytest.approx(KP * 0.01, rel=1e-9)
        assert r[f"contact.{pad}.F_f"][:, 0] == pytest.approx(-M * G / 2.0, rel=1e-9)


def test_a_grip_lowered_below_the_cone_slips_where_the_closed_form_says():
    """q_d opens at r = 1 mm/s: the pad force F(t) = KP (0.01 − r t) − KD r (the fingers rest on the part) meets
    m g / (2 μ) at t* = (KP 0.01 − KD r − m g / (2 μ)) / (KP r); both pads slip there, then the part falls."""
    rate = 1e-3  # [m/s]
    moves = [{"kind": "constant_velocity", "delta": [-0.01, -0.01], "duration": 10.0}]
    scene = _scene({"duration": 10.0}, phase=[{"name": "open", "reference": {"space": "joint", "start": [0.03, 0.03],
                                                                              "moves": moves}}])
    r = simulate(scene)
    t_star = (KP * 0.01 - KD * rate - M * G / (2.0 * MU)) / (KP * rate)
    slips = {e["name"]: e["t"] for e in r.events if e["kind"] == "slip"}
    assert set(slips) == {"left", "right"}
    for t in slips.values():
        assert t == pytest.approx(t_star, abs=1e-9)
    before = r.t < t_star
    assert np.abs(r["body.part.v"][before]).max() < 1e-9
    assert r["body.part.v"][-1] < 0.0  # falling after it


def test_a_part_let_go_falls_freely_with_its_weight():
    """The fingers open (q0 = 0: 10 mm off the part): x(t) = −g t² / 2, and the energy audit closes."""
    scene = _scene({"duration": 0.2, "robot.q0": [0.0, 0.0], "solver.record_energy": True},
                   phase=[{"name": "open", "reference": {"space": "joint", "start": [0.0, 0.0]}}])
    r = simulate(scene)
    assert r["body.part.x"] == pytest.approx(-0.5 * G * r.t ** 2, rel=1e-9, abs=1e-12)
    assert violations(r.meta["checks"]) == []
    audit = r.meta["checks"]["energy_residual"]  # the weight's potential −W x in the stored energy: closes to 1e-7 J
    assert audit["value"] is not None and audit["value"] <= audit["tol"]


def test_the_part_is_a_body_read_off_its_urdf():
    """[body.part] urdf = "part_cylinder.urdf" (beside the scene): the mass of its links after the joint, the joint's
    axis in the world; the run equals the one with that mass and axis given as keys, bit for bit."""
    scene = load_scene("pinch_hold")
    part = scene.bodies["part"]
    assert part.mass == 0.045 and part.axis.tolist() == [0.0, 0.0, 1.0]
    assert part.urdf.endswith("sims/part_cylinder.urdf")
    doc = dict(scene.document)
    doc["body"] = {"part": {"mass": 0.045, "axis": [0.0, 0.0, 1.0]}}
    keys = simulate(parse_scene(doc, {"duration": 0.5}, scene.file))
    urdf = simulate("pinch_hold", {"duration": 0.5})
    assert np.array_equal(keys["body.part.x"], urdf["body.part.x"])
    assert np.array_equal(keys["contact.left.F_f"], urdf["contact.left.F_f"])


@pytest.mark.parametrize("body, key, words", [
    ({"urdf": "SKEWED"}, "body.part.urdf", "mutually orthogonal"),  # two prismatic joints at 45°
    # a revolute joint makes it an articulated body (tests/test_lever.py): its surfaces then name its frame
    ({"urdf": "REVOLUTE"}, "contact.left.surface_frame", "required with body = 'part'"),
    ({"urdf": "part_cylinder.urdf", "mass": 1.0}, "body.part.mass", "no mass or axis beside urdf"),
    ({"urdf": "no_such_body"}, "body.part.urdf", "no_such_body"),
])
def test_a_body_urdf_that_is_not_orthogonal_prismatic_joints_is_one_clear_error(tmp_path, body, key, words):
    from contactdyn.errors import SceneError

    sims = Path(__file__).parent.parent / "sims"
    if body["urdf"] == "REVOLUTE":
        text = (sims / "part_cylinder.urdf").read_text()
        body = {"urdf": str(tmp_path / "spun.urdf")}
        Path(body["urdf"]).write_text(text.replace('type="prismatic"', 'type="revolute"'))
    elif body["urdf"] == "SKEWED":
        text = (sims / "box_xz.urdf").read_text()
        body = {"urdf": str(tmp_path / "skewed.urdf")}
        Path(body["urdf"]).write_text(text.replace('<axis xyz="0 0 1"/>', '<axis xyz="1 0 1"/>'))
    doc = dict(load_scene("pinch_hold").document)
    doc["body"] = {"part": body}
    with pytest.raises(SceneError) as err:
        parse_scene(doc, None, load_scene("pinch_hold").file)
    assert key in str(err.value) and words in str(err.value)
