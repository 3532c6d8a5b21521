"""Sanity warnings: each check fires on the mistake it names and stays quiet on the shipped scenes."""

from __future__ import annotations

import json
import math
import tomllib
import warnings

import pytest

from contactdyn.cli import EXIT_OK, main
from contactdyn.errors import SceneError
from contactdyn.model.system import System
from contactdyn.scene.sanity import SanityWarning, scene_warnings, system_warnings
from contactdyn.scene.scene_file import load_scene, parse_scene, sims_dir
from contactdyn.simulate import simulate

B1 = sims_dir() / "b1.toml"


def _b1(drop: tuple[str, ...] = (), **overrides):
    """B1 with overrides and without the ``drop`` keys (``table.key``)."""
    doc = tomllib.loads(B1.read_text())
    for key in drop:
        table, _, name = key.rpartition(".")
        node = doc
        for part in table.split("."):
            node = node[part]
        del node[name]
    return parse_scene(doc, overrides, str(B1))


def _all(scene):
    return scene_warnings(scene) + system_warnings(System(scene))


@pytest.mark.parametrize("name", sorted(p.stem for p in sims_dir().glob("*.toml")))
def test_shipped_scenes_are_sane(name):
    assert _all(load_scene(name)) == []


def test_a_force_set_point_nobody_applies():
    (note,) = scene_warnings(_b1(("controller.axes",), **{"controller.kind": "joint_pd"}))
    assert "phase[0] (slide): force set-point 100 N on contact 'tip'" in note and "'joint_pd' does not apply" in note


def test_a_task_pd_fighting_its_set_point_along_the_normal():
    # default axes: x, y, z, so y (the normal) is position-controlled too
    (note,) = scene_warnings(_b1(("controller.axes",)))
    assert "controls the position along its direction [0.0, 1.0, 0.0]" in note


def test_no_contact_and_a_huge_friction_coefficient():
    doc = tomllib.loads(B1.read_text())
    doc.pop("contact")
    doc["phase"][0].pop("force")
    assert [n for n in scene_warnings(parse_scene(doc)) if "no contacts" in n]
    assert scene_warnings(_b1(**{"contact.tip.tangent.mu": 2.0})) == []
    (note,) = scene_warnings(_b1(**{"contact.tip.tangent.mu": 1e4}))
    assert "contact.tip.tangent: friction coefficient 10000 > 2" in note


def test_a_contact_period_below_the_output_step():
    """B1's model (b): m' = 10 kg on k. The period 2π√(m/k) crosses 1 ms at k = 4π² 10 / 1e-6 ≈ 3.95e8 N/m."""
    k_edge = 4 * math.pi**2 * 10.0 / 1e-6
    assert system_warnings(System(_b1(**{"contact.tip.normal.k": 0.99 * k_edge}))) == []
    (note,) = system_warnings(System(_b1(**{"contact.tip.normal.k": 1.01 * k_edge})))
    assert note.startswith("contact.tip.normal: stage 1") and "10 kg" in note and "solver.output_rate = 1000" in note
    # a massless stage (model c) oscillates with the robot's effective mass at the tip
    (note,) = system_warnings(System(_b1(("contact.tip.normal.m",), **{"contact.tip.normal.model": "c",
                                                                      "contact.tip.normal.k": 1e9})))
    assert "stiffness 1e+09 N/m" in note


def test_a_bonded_tip_starting_off_its_surface():
    (note,) = system_warnings(System(_b1(**{"contact.tip.point": [0.0, -0.16, 0.0]})))
    assert note.startswith("contact.tip: bonded, but the tip starts +0.01 m off the surface")


def _pressed_in(model: str, depth: float):
    """B1 unbonded, its surface moved ``depth`` [m] above the tip's start (the tip starts inside it)."""
    normal = {"b": {}, "c": {"contact.tip.normal.model": "c", "contact.tip.normal.k": 2e4, "contact.tip.normal.b": 5.0},
              "rigid": {"contact.tip.normal.model": "rigid"}}[model]
    drop = ("contact.tip.normal.m",) if model != "b" else ()
    if model == "rigid":
        drop += ("contact.tip.normal.k", "contact.tip.normal.b")
    return _b1(drop, **{"contact.tip.bonded": False, "contact.tip.point": [0.0, -0.15 + depth, 0.0],
                        "duration": 0.01, **normal})


def test_a_tip_starting_inside_a_compliant_surface_is_a_warning_and_starts_pressed():
    """Model (c), k = 2e4 N/m, 1 mm deep, at rest: the run starts with F_n = k d = 20 N (the damper idle)."""
    scene = _pressed_in("c", 1e-3)
    (note,) = system_warnings(System(scene))
    assert note.startswith("contact.tip: the tip starts 0.001 m inside the surface (contact.tip.point")
    with pytest.warns(SanityWarning, match="inside the surface"):
        r = simulate(scene)
    assert r["contact.tip.touching"][0] == 1.0 and r["contact.tip.F_n"][0] == pytest.approx(2e4 * 1e-3, rel=1e-9)
    assert note in r.meta["warnings"]
    # model (b): the surface mass starts with the tip, its stage compressed by the depth: the tip is pushed out
    with pytest.warns(SanityWarning, match="inside the surface"):
        r = simulate(_pressed_in("b", 1e-3))
    assert r["mass.tip.n.m1.x"][0] == pytest.approx(r["tip"][0, 1], abs=1e-15)  # [m] along the normal, with the tip
    assert r["stage.tip.n.env1.x"][0] == pytest.approx(1e-3, abs=1e-12)  # [m] compressed by the depth
    assert r["stage.tip.n.env1.F"][0] == pytest.approx(1e5 * 1e-3, rel=1e-9)  # [N] k d (B1: k = 1e5 N/m)
    assert system_warnings(System(_pressed_in("c", 0.0))) == []  # on the surface: nothing to say


def test_a_tip_starting_inside_a_rigid_surface_is_an_error():
    with pytest.raises(SceneError, match=r"contact.tip: expected a start with the tip on or above the rigid surface "
                                         r"\(gap >= 0\), found 'gap -0.001 m'"):
        System(_pressed_in("rigid", 1e-3)).initial_state()


def test_warnings_are_issued_stored_and_printed(tmp_path, capsys):
    scene = _b1(**{"contact.tip.tangent.mu": 50.0, "duration": 0.02})
    with pytest.warns(SanityWarning, match="friction coefficient 50"):
        result = simulate(scene)
    assert len(result.meta["warnings"]) == 1
    result.save(tmp_path / "run")
    assert json.loads((tmp_path / "run.json").read_text())["meta"]["warnings"] == result.meta["warnings"]
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # the command prints its own line, not Python's
        assert main(["run", "b1", "--set", "duration=0.02", "--set", "contact.tip.tangent.mu=50"]) == EXIT_OK
    err = capsys.readouterr().err
    assert err.count("contactdyn: warning: contact.tip.tangent: friction coefficient 50 > 2") == 1
