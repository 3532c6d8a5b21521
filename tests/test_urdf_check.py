"""The URDF tree check (before Pinocchio) and the forked probe that turns a crash into an error."""

from __future__ import annotations

import os
import signal
from pathlib import Path

import pytest

from contactdyn.errors import RobotError
from contactdyn.robot.robot import Robot
from contactdyn.robot.urdf_check import MAX_URDF_LINKS, MAX_URDF_MOVING_JOINTS, check_urdf_tree, isolated_build

INERTIAL = '<inertial><mass value="1"/><inertia ixx="1" iyy="1" izz="1" ixy="0" ixz="0" iyz="0"/></inertial>'


def urdf(tmp_path: Path, joints: list[tuple[str, str, str]], links: list[str], kind: str = "revolute") -> Path:
    body = "".join(f'<link name="{n}">{INERTIAL}</link>' for n in links)
    body += "".join(f'<joint name="{n}" type="{kind}"><parent link="{p}"/><child link="{c}"/><axis xyz="0 0 1"/>'
                    '<limit lower="-1" upper="1" effort="1" velocity="1"/></joint>' for n, p, c in joints)
    path = tmp_path / "r.urdf"
    path.write_text(f'<robot name="r">{body}</robot>')
    return path


# each of these ended the process with SIGSEGV inside Pinocchio 4.1 (buildGeomFromUrdf) before the check
CASES = {
    "cycle with a second parent": ([("j1", "base", "a"), ("j2", "a", "b"), ("j3", "b", "a")], ["base", "a", "b"],
                                   "revolute", "child of two joints"),
    "own parent": ([("j1", "base", "a"), ("j2", "a", "a")], ["base", "a"], "revolute", "'a' is its own parent"),
    "own parent, fixed": ([("j1", "base", "a"), ("j2", "a", "a")], ["base", "a"], "fixed", "its own parent"),
    "detached cycle": ([("j1", "base", "a"), ("j2", "b", "c"), ("j3", "c", "b")], ["base", "a", "b", "c"],
                       "revolute", "cycle through links"),
    "no root": ([("j1", "a", "b"), ("j2", "b", "a")], ["a", "b"], "revolute", "found none"),
    "two roots": ([("j1", "base", "a")], ["base", "a", "b"], "revolute", "found 2 ('base', 'b')"),
    "undefined child": ([("j1", "base", "zz")], ["base"], "revolute", "child link 'zz' is not defined"),
    "duplicate joint": ([("j1", "base", "a"), ("j1", "a", "b")], ["base", "a", "b"], "revolute", "two joints named"),
    "duplicate link": ([("j1", "base", "a")], ["base", "a", "a"], "revolute", "two links named 'a'"),
    "no link at all": ([], [], "revolute", "expected <link> elements in <robot>, found none"),
}


@pytest.mark.parametrize("name", sorted(CASES))
def test_non_tree_urdf_is_refused_before_pinocchio(tmp_path, name):
    joints, links, kind, expected = CASES[name]
    path = urdf(tmp_path, joints, links, kind)
    with pytest.raises(RobotError) as info:
        Robot.load(path)
    assert str(path) in str(info.value) and expected in str(info.value)


def test_a_tree_passes(tmp_path):
    path = urdf(tmp_path, [("j1", "base", "a"), ("j2", "a", "b"), ("j3", "a", "c")], ["base", "a", "b", "c"])
    assert check_urdf_tree(path).tag == "robot"


def test_too_many_links(tmp_path):
    n = MAX_URDF_LINKS + 1
    links = [f"l{i}" for i in range(n)]
    path = urdf(tmp_path, [(f"j{i}", f"l{i}", f"l{i + 1}") for i in range(n - 1)], links)
    with pytest.raises(RobotError, match=f"{n} links; at most {MAX_URDF_LINKS}"):
        check_urdf_tree(path)


def test_too_many_moving_joints(tmp_path):
    n = MAX_URDF_MOVING_JOINTS + 1
    path = urdf(tmp_path, [(f"j{i}", f"l{i}", f"l{i + 1}") for i in range(n)], [f"l{i}" for i in range(n + 1)])
    with pytest.raises(RobotError, match=f"{n} moving joints; at most {MAX_URDF_MOVING_JOINTS}"):
        check_urdf_tree(path)
    fixed = urdf(tmp_path, [(f"j{i}", f"l{i}", f"l{i + 1}") for i in range(n)], [f"l{i}" for i in range(n + 1)],
                 kind="fixed")
    assert check_urdf_tree(fixed).tag == "robot"  # fixed joints cost nothing


def test_not_a_robot(tmp_path):
    path = tmp_path / "x.urdf"
    path.write_text("<html/>")
    with pytest.raises(RobotError, match="expected a <robot> element at the top, found <html>"):
        check_urdf_tree(path)


def test_a_crash_in_the_probe_is_an_error_and_this_process_lives(tmp_path):
    path = tmp_path / "any.urdf"
    path.write_text("<robot/>")
    with pytest.raises(RobotError, match=r"crashed .*SIGSEGV \(11\)"):
        isolated_build(path, "crash-test", lambda: os.kill(os.getpid(), signal.SIGSEGV))
    isolated_build(path, "fine-test", lambda: None)  # a child that exits normally: no error
    isolated_build(path, "fine-test", lambda: os.kill(os.getpid(), signal.SIGSEGV))  # cached: not run again


@pytest.mark.parametrize("extra, message", [
    ('<dynamic damping="0.5"/>', "joint 'j1': unknown <dynamic> (did you mean 'dynamics'?)"),
    ('<dynamics frcition="3"/>', "joint 'j1' <dynamics>: unknown attribute frcition= (did you mean 'friction'?)"),
    ('<limit lowr="-1" upper="1" effort="1" velocity="1"/>', "unknown attribute lowr= (did you mean 'lower'?)"),
])
def test_a_misspelt_element_or_attribute_of_a_joint_is_named(tmp_path, extra, message):
    """The URDF's parsers drop what they do not know without a word: a misspelt <dynamics> is friction lost."""
    path = urdf(tmp_path, [("j1", "base", "a")], ["base", "a"])
    path.write_text(path.read_text().replace("</joint>", f"{extra}</joint>"))
    with pytest.raises(RobotError, match="did you mean") as info:
        check_urdf_tree(path)
    assert message in str(info.value) and str(path) in str(info.value)


def test_an_unknown_element_or_attribute_far_from_any_known_name_passes(tmp_path):
    """Extensions (a gear_velocity limit, a <transmission> or <gazebo> tag) are not misspellings."""
    path = urdf(tmp_path, [("j1", "base", "a")], ["base", "a"])
    path.write_text(path.read_text().replace('velocity="1"/>', 'velocity="1" gear_velocity="2"/><gazebo/>'))
    check_urdf_tree(path)
