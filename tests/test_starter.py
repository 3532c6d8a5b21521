"""`contactdyn new`: the starter scene runs as written, presses 20 N and slides 10 cm."""

from __future__ import annotations

import numpy as np
import pytest

from contactdyn.cli import EXIT_OK, EXIT_USAGE, main
from contactdyn.sanity import scene_warnings, system_warnings
from contactdyn.scene import load_scene
from contactdyn.simulate import simulate
from contactdyn.system import System


@pytest.mark.parametrize("contact, friction", [("b", True), ("a", False), ("c", True), ("rigid", False)])
def test_the_starter_presses_then_slides(tmp_path, monkeypatch, capsys, contact, friction):
    monkeypatch.chdir(tmp_path)
    argv = ["new", "mine", "--contact", contact] + (["--friction"] if friction else [])
    assert main(argv) == EXIT_OK
    assert "wrote sims/mine.toml; run it: contactdyn run mine" in capsys.readouterr().out
    scene = load_scene("mine")  # found in ./sims
    assert scene_warnings(scene) + system_warnings(System(scene)) == []
    r = simulate(scene)
    F, t, tip = r["contact.table.F_n"], r.t, r["tip"]
    assert abs(F[-1] - 20.0) < 0.5  # [N] the set-point, held while sliding
    assert np.all(np.abs(F[t > 2.6] - 20.0) < 1.0)
    slide = tip[-1, 0] - tip[np.searchsorted(t, 1.5), 0]  # [m] along x from the slide's start
    lag = 0.3 * 20.0 / 2000.0 if friction else 0.0  # friction lag mu F / kp at the end [m]
    assert abs(slide - 0.10) < 0.002 + lag
    assert abs(tip[-1, 2] - scene.contacts["table"].point[2]) < 0.005  # on the (deformed) table


def test_new_refuses_to_overwrite_and_checks_its_options(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    assert main(["new", "mine"]) == EXIT_OK
    assert main(["new", "mine"]) == EXIT_USAGE
    assert capsys.readouterr().err.startswith("contactdyn: error: NAME: expected a file that does not exist yet "
                                              "(or --force), found 'sims")  # no --out was given: not named
    assert main(["new", "mine", "--force", "--out", "elsewhere/x.toml"]) == EXIT_OK
    assert (tmp_path / "elsewhere" / "x.toml").is_file()
    assert main(["new", "mine", "--contact", "z"]) == EXIT_USAGE
    assert main(["new", "arm", "--robot", "nosuchrobot"]) == EXIT_USAGE
    assert "nosuchrobot" in capsys.readouterr().err


def test_the_starter_writes_valid_toml_for_a_name_with_quotes():
    import tomllib

    from contactdyn.starter import starter_scene

    name = 'my "best" \\ scene'
    assert tomllib.loads(starter_scene(name))["name"] == name


@pytest.mark.parametrize("robot", ["panda", "xarm7"])
def test_the_starter_finds_the_tool_frame_and_a_posture_of_an_example_robot(tmp_path, monkeypatch, robot):
    monkeypatch.chdir(tmp_path)
    assert main(["new", "arm", "--robot", robot]) == EXIT_OK  # tip: the catalog's tool frame, q0 inside limits
    r = simulate("arm", {"duration": 1.0})
    assert abs(r["contact.table.F_n"][-1] - 20.0) < 1.0  # [N] pressing by the end of the press phase
