"""Where robots come from and what the loader makes of them: names, package:// and file:// URIs,
frames that share a name, the chain to the tip, inertia repair, the start posture solved from the task."""

from __future__ import annotations

import json
import re

import numpy as np
import pinocchio as pin
import pytest

from contactdyn import Robot, RobotError
from contactdyn.cli import EXIT_OK, EXIT_USAGE, main
from contactdyn.errors import SceneError, SimulationError
from contactdyn.hybrid.events import EventLog, start_storm_cause
from contactdyn.model.system import System
from contactdyn.robot.catalog import example_robot_data_share, example_robots
from contactdyn.robot.inertia import nearest_valid_moments
from contactdyn.robot.posture import PostureTask, solve_posture
from contactdyn.scene.scene_file import parse_scene

LINK = """<link name="{name}"><inertial><mass value="1"/><inertia ixx="{ixx}" iyy="0.01" izz="{izz}" ixy="0" ixz="0"
 iyz="0"/></inertial>{visual}</link>"""
ARM = """<?xml version="1.0"?>
<robot name="slider">
  <link name="base"/>
  <joint name="x" type="prismatic"><parent link="base"/><child link="carriage"/><axis xyz="1 0 0"/>
    <limit lower="-0.5" upper="0.5" effort="100" velocity="1"/></joint>
  {carriage}
  <joint name="z" type="prismatic"><parent link="carriage"/><child link="slide"/><axis xyz="0 0 1"/>
    <limit lower="-0.5" upper="0.5" effort="100" velocity="1"/></joint>
  {slide}
  <joint name="tip_joint" type="fixed"><parent link="slide"/><child link="tip"/></joint>
  <link name="tip"/>
</robot>
"""


def slider(path, visual: str = "", izz: str = "0.01"):
    """A 2-DOF Cartesian robot (x, z prismatic within ±0.5 m); ``visual`` on its first link."""
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(ARM.format(carriage=LINK.format(name="carriage", ixx="0.01", izz=izz, visual=visual),
                               slide=LINK.format(name="slide", ixx="0.01", izz="0.01", visual="")))
    return path


STL = ("solid t\nfacet normal 0 0 1\nouter loop\nvertex 0 0 0\nvertex 0.1 0 0\nvertex 0 0.1 0\nendloop\nendfacet\n"
       "endsolid t\n")  # one triangle


def mesh_visual(uri: str) -> str:
    return f'<visual><geometry><mesh filename="{uri}"/></geometry></visual>'


# ---- names ----------------------------------------------------------------------------------
def test_every_urdf_example_robot_data_ships_has_a_name():
    files = set((example_robot_data_share() / "robots").glob("*/**/*.urdf"))
    named = example_robots()
    assert set(named.values()) == files
    assert named["talos_arm"].name == "talos_left_arm.urdf" and named["kinova"].name == "kinova.urdf"
    assert named["ur_description/ur3"].name == "ur3.urdf" and named["ur3"].name == "ur3_robot.urdf"


def test_list_robots_gives_dof_and_tips(capsys):
    assert main(["list", "robots", "--json"]) == EXIT_OK
    robots = {r["name"]: r for r in json.loads(capsys.readouterr().out)["robots"]}
    assert robots["panda"]["dof"] == 9 and "panda_hand_tcp" in robots["panda"]["end_effectors"]
    assert robots["ur5"]["dof"] == 6 and "tool0" in robots["ur5"]["end_effectors"]
    assert robots["kinova"]["dof"] == 6  # its continuous joints are one angle each


def test_list_frames_prints_the_tree_with_types(capsys):
    assert main(["list", "frames", "z1"]) == EXIT_OK
    out = capsys.readouterr().out
    assert "7 DOF" in out
    lines = out.splitlines()
    body = next(ln for ln in lines if "gripperStator [BODY]" in ln)
    joint = next(ln for ln in lines if "gripperStator [FIXED_JOINT]" in ln)
    assert len(body) - len(body.lstrip()) > len(joint) - len(joint.lstrip())  # the body hangs below its joint
    assert re.search(r"joint1 \[JOINT RZ \[-2\.618, 2\.618\] rad\]", out), out
    assert main(["list", "frames"]) == 1 and "name a robot" in capsys.readouterr().err


# ---- package:// and file:// ---------------------------------------------------------------------
def test_package_uri_from_ros_package_path(tmp_path, monkeypatch):
    mesh = tmp_path / "ws" / "my_pkg" / "meshes" / "link.stl"
    mesh.parent.mkdir(parents=True)
    mesh.write_text(STL)
    path = slider(tmp_path / "elsewhere" / "robot.urdf", mesh_visual("package://my_pkg/meshes/link.stl"))
    monkeypatch.delenv("ROS_PACKAGE_PATH", raising=False)
    r = Robot.load(path)  # not found: drawn without it, with a note
    assert "link 'carriage' ('package://my_pkg/meshes/link.stl')" in r.visual_notes[0] and r.visual_model.ngeoms == 0
    monkeypatch.setenv("ROS_PACKAGE_PATH", str(tmp_path / "ws"))
    r = Robot.load(path)
    assert r.visual_notes == []
    assert [g.meshPath for g in r.visual_model.geometryObjects] == [str(mesh.resolve())]
    monkeypatch.setenv("ROS_PACKAGE_PATH", str(tmp_path / "ws" / "my_pkg"))  # the package folder itself
    assert Robot.load(path).visual_model.geometryObjects[0].meshPath == str(mesh.resolve())


def test_package_uri_from_the_urdfs_own_folders_and_file_uri(tmp_path, monkeypatch):
    monkeypatch.delenv("ROS_PACKAGE_PATH", raising=False)
    mesh = tmp_path / "my_pkg" / "meshes" / "link.stl"
    mesh.parent.mkdir(parents=True)
    mesh.write_text(STL)
    inside = slider(tmp_path / "my_pkg" / "urdf" / "robot.urdf", mesh_visual("package://my_pkg/meshes/link.stl"))
    assert Robot.load(inside).visual_model.geometryObjects[0].meshPath == str(mesh.resolve())
    absolute = slider(tmp_path / "other" / "robot.urdf", mesh_visual(f"file://{mesh}"))
    assert Robot.load(absolute).visual_model.geometryObjects[0].meshPath == str(mesh.resolve())


@pytest.mark.parametrize("name,nv", [("kinova", 6), ("talos_arm", 6), ("ur5_gripper", 6), ("panda", 7)])
def test_example_robots_given_by_file_path_find_their_meshes(name, nv):
    tip = {"kinova": "j2s6s200_end_effector", "talos_arm": "arm_left_7_link", "ur5_gripper": "tool0",
           "panda": "panda_link8"}[name]
    r = Robot.load(str(example_robots()[name]), tip=tip)
    assert r.nv == nv
    meshes = [g.meshPath for g in r.visual_model.geometryObjects if g.meshPath]
    assert meshes and all(not m.startswith("package://") for m in meshes)


# ---- frames and the chain to the tip ------------------------------------------------------------
def test_a_name_shared_by_a_body_and_its_joint_picks_the_body():
    r = Robot.load("z1", tip="gripperStator")
    frame = r.model.frames[r.frame_id("gripperStator")]
    assert frame.type == pin.FrameType.BODY
    with pytest.raises(RobotError, match=r"no frame named 'gripperstator'; close matches: 'gripperStator'"):
        r.frame_id("gripperstator")


def test_the_chain_to_the_tip_is_active_the_rest_locked_at_neutral():
    talos = Robot.load("talos_arm", tip="arm_left_4_link")
    assert talos.joint_names == [f"arm_left_{i}_joint" for i in range(2, 5)]  # the file starts at joint 2
    assert set(talos.locked) >= {"arm_left_5_joint", "gripper_left_joint"}
    # panda joint 4 lives in [-3.07, -0.07]: locked at its neutral value, 0 clipped into the limits
    panda = Robot.load("panda", tip="panda_link3")
    assert panda.joint_names == ["panda_joint1", "panda_joint2", "panda_joint3"]
    assert panda.locked["panda_joint4"] == pytest.approx(-0.0698) and panda.locked["panda_finger_joint1"] == 0.0


# ---- inertia: check, repair, trust ----------------------------------------------------------------
def test_bad_inertia_names_the_link_and_the_options(tmp_path):
    path = slider(tmp_path / "r.urdf", izz="0.05")  # moments (0.01, 0.01, 0.05): no rigid body
    with pytest.raises(RobotError, match=r"link 'carriage'.*triangle inequality.*robot.inertia = \"repair\""):
        Robot.load(path)
    trusted = Robot.load(path, inertia="trust")
    assert len(trusted.notes) == 1 and "'carriage'" in trusted.notes[0] and "trusted" in trusted.notes[0]
    repaired = Robot.load(path, inertia="repair")
    assert len(repaired.notes) == 1 and "repaired to principal moments" in repaired.notes[0]
    fixed = repaired.model.inertias[1].inertia  # the carriage's, about its COM
    m = np.linalg.eigvalsh(fixed)
    assert m[0] >= 0 and m[0] + m[1] >= m[2] - 1e-15


@pytest.mark.parametrize("moments", [[0.01, 0.01, 0.05], [-0.01, 0.005, 0.03], [-1.0, -2.0, 0.5], [0.0, 0.0, 1.0]])
def test_repaired_moments_are_valid_and_valid_ones_stay(moments):
    m = nearest_valid_moments(np.array(moments))
    assert np.all(m >= 0) and m[0] + m[1] >= m[2] - 1e-15
    np.testing.assert_array_equal(nearest_valid_moments(np.array([0.2, 0.3, 0.4])), [0.2, 0.3, 0.4])
    np.testing.assert_allclose(nearest_valid_moments(np.array([0.01, 0.01, 0.05])), [0.02, 0.02, 0.04], rtol=1e-12)


def test_repaired_moments_are_the_nearest_valid_ones():
    """Against a general constrained minimizer (SLSQP) on random moments: never farther (to 1e-9)."""
    from scipy.optimize import minimize

    rng = np.random.default_rng(7)
    cons = [{"type": "ineq", "fun": lambda m, a=a: a @ m} for a in ([1, 1, -1], [1, -1, 1], [-1, 1, 1])]
    for _ in range(20):
        given = rng.uniform(-1.0, 2.0, 3)
        ours = nearest_valid_moments(given)
        best = minimize(lambda m, g=given: np.sum((m - g) ** 2), np.abs(given), constraints=cons,
                        bounds=[(0, None)] * 3, method="SLSQP", options={"ftol": 1e-14, "maxiter": 500}).x
        assert np.linalg.norm(ours - given) <= np.linalg.norm(best - given) + 1e-9


def test_scene_inertia_option_warns_on_the_console(tmp_path, capsys):
    path = slider(tmp_path / "r.urdf", izz="0.05")
    scene = tmp_path / "s.toml"
    scene.write_text(f'duration = 0.01\n[robot]\nurdf = "{path}"\ninertia = "repair"\n')
    assert main(["run", str(scene)]) == EXIT_OK
    err = capsys.readouterr().err
    assert "warning: inertia: link 'carriage'" in err and "repaired" in err
    scene.write_text(f'duration = 0.01\n[robot]\nurdf = "{path}"\ninertia = "fix"\n')
    assert main(["run", str(scene)]) == EXIT_USAGE and "robot.inertia" in capsys.readouterr().err


# ---- the start posture from the task ----------------------------------------------------------------
def _scene(urdf, **robot) -> dict:
    return {"duration": 0.01, "robot": {"urdf": str(urdf), **robot}}


def test_posture_within_limits_reaches_the_target(tmp_path):
    path = slider(tmp_path / "r.urdf")
    x = System(parse_scene(_scene(path, tip0=[0.3, 0.0, -0.2], q_seed=[1.0, 2.0, 3.0]))).initial_state()[0]
    q = x[:2]
    np.testing.assert_allclose(q, [0.3, -0.2], atol=1e-12)  # the seed of another robot is ignored


def test_unreachable_task_says_by_how_much_it_misses(tmp_path):
    path = slider(tmp_path / "r.urdf")
    with pytest.raises(SceneError) as info:
        System(parse_scene(_scene(path, tip0=[1.0, 0.0, 0.2]))).initial_state()
    message = str(info.value)
    assert "robot.tip0" in message and "\n" not in message
    assert float(re.search(r"misses by ([0-9.e-]+) m", message).group(1)) == pytest.approx(0.5, rel=1e-9)


def test_tool_direction_is_solved_with_the_position():
    r = Robot.load("ur5", tip="tool0")
    target = np.array([0.1, 0.05, -1.0]) / np.linalg.norm([0.1, 0.05, -1.0])
    task = PostureTask("tool0", np.array([0.4, 0.1, 0.05]), np.array([0.0, 0.0, 1.0]), target)
    p = solve_posture(r, task)
    placement = r.frame_placement(p.q, "tool0")
    np.testing.assert_allclose(placement.translation, task.position, atol=1e-10)
    np.testing.assert_allclose(placement.rotation[:, 2], target, atol=1e-9)
    assert np.all(p.q >= r.lower) and np.all(p.q <= r.upper) and not p.from_seed
    assert solve_posture(r, task).q.tolist() == p.q.tolist()  # deterministic


def test_start_posture_outside_the_limits_is_bad_input(tmp_path):
    path = slider(tmp_path / "r.urdf")
    with pytest.raises(SceneError, match=r"robot.q0: expected a start posture within the joint limits \(joint 'z'"):
        System(parse_scene(_scene(path, q0=[0.0, 0.7]))).initial_state()
    x = System(parse_scene(_scene(path, q0=[0.0, 0.7], joint_limits="ignore"))).initial_state()[0]
    assert x[1] == 0.7


def test_event_storm_at_the_start_names_the_posture():
    events = [{"t": 0.0, "kind": "phase", "name": "main"}] + [{"t": 1e-12 * k, "kind": k % 2 and "touch" or "separate",
                                                              "name": "pen"} for k in range(60)]
    cause = start_storm_cause(events, "pen")
    assert "contact 'pen' began at t = 0 s" in cause and "robot.tip0" in cause and "initial penetration" in cause
    late = [{"t": 0.5 + 1e-12 * k, "kind": "touch", "name": "pen"} for k in range(60)]
    assert start_storm_cause(late, "pen") is None
    calm_then_storm = events[:3] + late  # (the run's first events at t = 0, its storm at 0.5 s: not the posture's)
    assert start_storm_cause(calm_then_storm, "pen", since=late[0]["t"]) is None


@pytest.mark.parametrize("max_events, storm_count", [(20, 1000), (10**6, 30)])
def test_the_run_stops_a_start_storm_naming_the_posture_not_max_events(max_events, storm_count):
    """Both guards of the run's event log (too many events; too many too close together) give the cause."""
    from types import SimpleNamespace

    log = EventLog("scene", SimpleNamespace(max_events=max_events, storm_count=storm_count, storm_window=1e-3),
                   {"events": 0})
    log.log(0.0, "phase", "main", check_storm=False)
    with pytest.raises(SimulationError) as info:
        for k in range(10**4):
            log.log(1e-9 * k, "touch" if k % 2 else "separate", "pen")
    message = str(info.value)
    assert "contact 'pen' began at t = 0 s, with the run" in message and "robot.tip0" in message
    assert "raise solver.max_events" not in message and "storm_count" not in message
