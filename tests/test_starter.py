"""`contactdyn new`: the starter scene runs as written, presses 20 N and slides 10 cm."""

from __future__ import annotations

import numpy as np
import pytest

from contactdyn.cli import EXIT_OK, EXIT_USAGE, main
from contactdyn.model.system import System
from contactdyn.scene.sanity import scene_warnings, system_warnings
from contactdyn.scene.scene_file import load_scene
from contactdyn.simulate import simulate


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
    # xarm7's URDF gives every joint 2-10 N·m·s/rad of damping and 1 N·m of dry friction: stuck joints and a stuck
    # contact together over-constrain the arm (a statically indeterminate hold, contactdyn.model.joint_friction), and
    # the press settles inside the friction band (18.2 N). This test is about the starter: without the URDF's friction
    r = simulate("arm", {"duration": 1.0, "robot.joint_friction": "ignore"})
    assert abs(r["contact.table.F_n"][-1] - 20.0) < 1.0  # [N] pressing by the end of the press phase


@pytest.mark.parametrize("robot, tip", [("ur10", None), ("solo12", "FL_FOOT"), ("finger_edu", "finger_tip_link")])
def test_the_starter_posture_is_well_conditioned_and_its_run_presses(robot, tip, tmp_path):
    """The robots whose starters stood stretched (q0 = 0: singular, never touching) start where the tip's
    linear Jacobian is well conditioned, and the scene presses its 20 N without a warning."""
    import tomllib
    import warnings

    from contactdyn import parse_scene, simulate
    from contactdyn.robot.robot import Robot
    from contactdyn.starter import PRESS, starter_scene

    doc = tomllib.loads(starter_scene("s", robot, "b", True, tip))
    arm = Robot.load(robot, tip=doc["robot"]["tip"])
    J = arm.frame_jacobian(np.array(doc["robot"]["q0"]), doc["robot"]["tip"])[:3]
    assert np.linalg.svd(J, compute_uv=False).min() > 0.02  # [m/rad] (the stretched UR10: 0.15; a leg at 0: ~0)
    doc["duration"] = 1.6
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        r = simulate(parse_scene(doc))
    assert r.meta["warnings"] == [] and r.meta["check_warnings"] == []
    end_of_press = np.searchsorted(r.t, 1.49)  # the press phase ends at 1.5 s (its ramp: 0.2 s)
    assert r["contact.table.F_n"][end_of_press] == pytest.approx(PRESS, rel=0.1)


def test_a_robot_whose_tip_cannot_press_and_slide_is_refused_with_a_sentence(capsys):
    """The double pendulum's link2 frame sits on its second joint's axis: one direction of motion only."""
    from contactdyn.cli import main

    assert main(["new", "x", "--robot", "double_pendulum", "--tip", "link2", "--out", "/dev/null", "--force"]) == 2
    err = capsys.readouterr().err
    assert "a robot whose tip can move along two world directions" in err and "'link2' (2 active joints)" in err
    assert main(["new", "x", "--robot", "double_pendulum", "--tip", "nope", "--out", "/dev/null", "--force"]) == 2
    assert "choose the pressing frame with --tip" in capsys.readouterr().err


def test_a_planar_arm_of_three_joints_gets_a_starter(tmp_path):
    """A 3R arm in the x-z plane: its tip moves in two directions only (rank 2), which is enough to press and
    slide (the table's normal and the slide both in the plane)."""
    from contactdyn.robot.robot import Robot
    from contactdyn.starter import working_posture

    links = "".join(f'<link name="l{i}"><inertial><mass value="1"/><inertia ixx="0.01" ixy="0" ixz="0" '
                    f'iyy="0.01" iyz="0" izz="0.01"/></inertial></link>' for i in range(1, 4))
    joints = "".join(f'<joint name="j{i}" type="revolute"><parent link="{"base" if i == 1 else f"l{i - 1}"}"/>'
                     f'<child link="l{i}"/><origin xyz="{0 if i == 1 else 0.3} 0 0"/><axis xyz="0 1 0"/>'
                     f'<limit lower="-2.5" upper="2.5" effort="100" velocity="10"/></joint>' for i in range(1, 4))
    tip = '<link name="tip"/><joint name="tj" type="fixed"><parent link="l3"/><child link="tip"/>' \
          '<origin xyz="0.3 0 0"/></joint>'
    (tmp_path / "planar3r.urdf").write_text(f'<robot name="p3"><link name="base"/>{links}{joints}{tip}</robot>')
    arm = Robot.load(str(tmp_path / "planar3r.urdf"), tip="tip")
    q, n, t, quality = working_posture(arm, "tip")
    assert quality > 1e-2 and abs(n @ np.array([0, 1, 0])) < 1e-12 and abs(t @ np.array([0, 1, 0])) < 1e-12


def test_the_help_example_with_imports_runs_as_printed(capsys, tmp_path):
    """``contactdyn new --help``'s example with --imports, typed as printed in the folder of the law's module (by the
    console script: that folder is not on sys.path), writes a scene whose printed run command finds the law (before:
    the module was looked up beside sims/NAME.toml, and not found)."""
    import os
    import shlex
    import subprocess
    import sys
    from pathlib import Path

    root = Path(__file__).resolve().parent.parent
    assert main(["new", "--help"]) == EXIT_OK
    example = next(line.strip() for line in capsys.readouterr().out.splitlines() if "--imports" in line
                   and line.strip().startswith("contactdyn new"))
    (tmp_path / "cubic_stage.py").write_text((root / "examples" / "cubic_stage.py").read_text())
    env = {**os.environ, "PYTHONPATH": str(root)}

    def contactdyn(*args: str) -> subprocess.CompletedProcess:  # (-P: the working directory not on sys.path)
        code = "import sys; from contactdyn.cli import main; sys.exit(main(sys.argv[1:]))"
        return subprocess.run([sys.executable, "-P", "-c", code, *args], cwd=tmp_path, env=env, capture_output=True,
                              text=True, timeout=300)

    new = contactdyn(*shlex.split(example)[1:])
    assert new.returncode == EXIT_OK, new.stderr
    run = shlex.split(new.stdout.split("run it: ", 1)[1].strip())
    load = "import sys; from contactdyn import load_scene; print(load_scene(sys.argv[1]).document['contact'])"
    loaded = subprocess.run([sys.executable, "-P", "-c", load, run[2]], cwd=tmp_path, env=env, capture_output=True,
                            text=True, timeout=300)
    assert run[:2] == ["contactdyn", "run"] and loaded.returncode == 0, loaded.stderr
    assert f"Run: contactdyn run {run[2]}\n" in (tmp_path / run[2]).read_text()  # (the scene's own comment too)
    assert "'law': 'cubic'" in loaded.stdout
