"""Scene validation: every bad value names the file, the key path, what was expected and found."""

from __future__ import annotations

import math

import pytest

from contactdyn import SceneError, load_scene, parse_scene, simulate
from contactdyn.model.system import System
from contactdyn.scene.scene_file import apply_overrides, parse_override


def b1_doc() -> dict:
    import tomllib

    from contactdyn.scene.scene_file import sims_dir

    return tomllib.loads((sims_dir() / "b1.toml").read_text())


@pytest.mark.parametrize(
    ("override", "key", "expected"),
    [
        ({"contact.tip.normal.k": -1.0}, "contact.tip.normal.k", "> 0"),
        ({"contact.tip.normal.m": math.nan}, "contact.tip.normal.m", "finite"),
        ({"contact.tip.normal.kk": 1.0}, "contact.tip.normal.kk", "did you mean 'k'"),
        ({"contact.tip.tangent.mu": "high"}, "contact.tip.tangent.mu", "a number"),
        ({"contact.tip.normal.model": "bb"}, "contact.tip.normal.model", "did you mean 'b'"),
        ({"duration": 0.0}, "duration", "> 0"),
        ({"robot.q0": [0.1]}, "robot.q0", "2 joint values"),
        ({"robot.gravity_compensation": 1.5}, "robot.gravity_compensation", "<= 1"),
        ({"contact.tip.body": "cart"}, "contact.tip.body", "one of ['ground', 'robot']"),
        ({"solver.method": "euler"}, "solver.method", "one of"),
        ({"phase.0.until": "touch:nope"}, "phase[0].until", "touch:<contact>"),
        ({"contact.tip.tangent.mu_s": 0.1}, "contact.tip.tangent.mu_s", ">= mu_k"),
        ({"phase.0.force": [{"contact": "tip", "direction": "t1", "value": 5.0}]}, "phase[0].force[0].direction",
         "contact 'tip' has tangent.model = 'friction', not 'chain'"),  # (an IndexError inside the model before)
    ],
)
def test_bad_values_name_key_expected_and_found(override, key, expected):
    with pytest.raises(SceneError) as err:
        scene = load_scene("b1", override)
        System(scene).initial_state()
    message = str(err.value)
    assert "b1.toml" in message and key in message and expected in message


def test_unknown_top_level_key_suggests_the_closest():
    with pytest.raises(SceneError, match=r"duraton.*did you mean 'duration'"):
        parse_scene({**b1_doc(), "duraton": 1.0}, file="x.toml")


def test_malformed_toml_names_the_file(tmp_path):
    bad = tmp_path / "bad.toml"
    bad.write_text("duration = = 1\n")
    with pytest.raises(SceneError, match="bad.toml.*valid TOML"):
        load_scene(bad)


def test_unknown_scene_name_lists_close_matches():
    with pytest.raises(SceneError, match="did you mean b1"):
        load_scene("b11")
    with pytest.raises(SceneError) as info:  # (nothing close: where the names are, not a list cut mid-name)
        load_scene("qq")
    assert "`contactdyn list scenes`" in str(info.value) and " ... " not in str(info.value)


def test_a_scene_path_that_is_not_there_is_said_to_be_missing(tmp_path):
    with pytest.raises(SceneError, match=r"no such file: '.*nothere\.toml'") as info:
        load_scene(tmp_path / "nothere.toml")
    assert "b1" not in str(info.value)  # (not the list of scene names: it was a path)
    with pytest.raises(SceneError, match="a directory"):
        load_scene(tmp_path)


def test_an_override_that_misspells_a_contact_is_named_not_added():
    with pytest.raises(SceneError, match="did you mean 'tip'") as info:
        load_scene("b1", {"contact.tipp.normal.k": 1e4})
    assert info.value.key == "contact.tipp"
    with pytest.raises(SceneError) as info:  # (a name nothing is close to: a new contact, read as any other)
        load_scene("b1", {"contact.wall.normal.k": 1e4})
    assert info.value.key == "contact.wall.normal.direction"


def test_unknown_robot_is_a_scene_error():
    with pytest.raises(SceneError, match="robot.*ur55.*did you mean") as info:
        System(load_scene("b1", {"robot.urdf": "ur55"}))
    assert info.value.key == "robot.urdf"
    with pytest.raises(SceneError, match="no frame named 'tipp'") as info:
        System(load_scene("b1", {"robot.tip": "tipp"}))
    assert info.value.key == "robot.tip"


def test_overrides_parse_toml_values_and_index_arrays():
    assert parse_override("contact.tip.normal.k=1e4") == ("contact.tip.normal.k", 1e4)
    assert parse_override("robot.q0=[0.1, 0.2]") == ("robot.q0", [0.1, 0.2])
    assert parse_override("solver.method=RK45") == ("solver.method", "RK45")
    doc = apply_overrides(b1_doc(), {"phase.0.force.0.value": 50.0})
    assert doc["phase"][0]["force"][0]["value"] == 50.0
    with pytest.raises(SceneError, match="phase.7"):
        apply_overrides(b1_doc(), {"phase.7.until": 1.0})
    with pytest.raises(SceneError, match=r"phase\[0\]\.until: expected an array item as a path part of its own, "
                                         r"e\.g\. phase\.0\.until"):
        apply_overrides(b1_doc(), {"phase[0].until": 1.0})


def test_override_changes_the_physics():
    soft = simulate("b1", {"duration": 0.1, "contact.tip.normal.k": 1e4, "solver.output_rate": 100.0})
    stiff = simulate("b1", {"duration": 0.1, "solver.output_rate": 100.0})
    assert soft.scene["contact"]["tip"]["normal"]["k"] == 1e4
    assert abs(soft["contact.tip.F_n"][-1] - stiff["contact.tip.F_n"][-1]) > 1.0


def test_a_scene_models_only_what_it_needs():
    """State = robot joints + what the scene names: no cart, no chain masses, no motor angles here.

    B1's contact has friction along one tangent: its impulses ∫F dt, ∫F_f dt are 2 first-order
    states (the step size follows the forces the stick/slip events watch; System.impulse_slots).
    """
    rigid = System(load_scene("b1", {"contact.tip.normal": {"direction": [0, 1, 0], "model": "rigid"}}))
    assert rigid.nQ == rigid.nv == 2 and rigid.ny == 2 and rigid.n == 6
    frictionless = System(load_scene("b1", {"contact.tip.normal": {"direction": [0, 1, 0], "model": "rigid"},
                                            "contact.tip.tangent": {"model": "free"}}))
    assert frictionless.ny == 0 and frictionless.n == 4
    model_b = System(load_scene("b1"))
    assert model_b.nQ == 3 and model_b.ny == 2  # + the surface's equivalent mass
    model_c = System(load_scene("b1", {"contact.tip.normal": {"direction": [0, 1, 0], "model": "c", "k": 1e5,
                                                               "b": 1.0}}))
    assert model_c.nQ == 2 and model_c.ny == 3  # + the damped surface end, relaxing after separation
