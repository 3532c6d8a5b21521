"""Robots known by name: the project's ``urdf/`` folder and every URDF example-robot-data ships.

Names are derived from the installed package: each URDF under its ``robots`` folder is known by
its file stem (``talos_left_arm``, ``ur5_gripper``), a stem shared by two files or taken by a
short name by ``<package>/<stem>`` (``anymal_c_simple_description/anymal``,
``ur_description/ur3``), and the usual arms by the short names of :data:`SHORT_NAMES`
(``panda``, ``ur5``, ``talos_arm``...).
"""

from __future__ import annotations

import functools
import sysconfig
from collections import Counter
from pathlib import Path

from ..errors import RobotError

__all__ = ["SHORT_NAMES", "TOOL_FRAMES", "URDF_JOINT_FRICTION", "example_robot_data_share", "example_robots",
           "urdf_dir"]

#: short names of the usual robots -> URDF relative to example-robot-data's ``robots`` folder
SHORT_NAMES: dict[str, str] = {
    "panda": "panda_description/urdf/panda.urdf",
    "ur3": "ur_description/urdf/ur3_robot.urdf",
    "ur5": "ur_description/urdf/ur5_robot.urdf",
    "ur10": "ur_description/urdf/ur10_robot.urdf",
    "kinova": "kinova_description/robots/kinova.urdf",
    "talos_arm": "talos_data/robots/talos_left_arm.urdf",
    "talos": "talos_data/robots/talos_reduced.urdf",
    "z1": "z1_description/urdf/z1.urdf",
    "xarm7": "xarm_description/urdf/xarm7.urdf",
    "so100": "so_arm_description/urdf/so100.urdf",
    "so101": "so_arm_description/urdf/so101.urdf",
    "double_pendulum": "double_pendulum_description/urdf/double_pendulum.urdf",
    "anymal_b": "anymal_b_simple_description/robots/anymal.urdf",
    "anymal_c": "anymal_c_simple_description/urdf/anymal.urdf",
    "tiago": "tiago_description/robots/tiago.urdf",
    "pr2": "pr2_description/urdf/pr2.urdf",
    "romeo": "romeo_description/urdf/romeo.urdf",
    "icub": "icub_description/robots/icub.urdf",
    "go2": "go2_description/urdf/go2.urdf",
    "g1": "g1_description/urdf/g1_29dof_rev_1_0.urdf",
}


#: the tool frame of the usual arms (a scene's ``robot.tip``): +z is the tool's axis on each
TOOL_FRAMES: dict[str, str] = {
    "panda": "panda_hand_tcp",
    "ur3": "tool0",
    "ur5": "tool0",
    "ur10": "tool0",
    "xarm7": "link_eef",
    "z1": "gripperStator",
    "kinova": "j2s6s200_end_effector",
    "talos_arm": "gripper_left_base_link",
    "so100": "gripper",
}
#: the usual arms whose URDF gives their joints dry friction (xarm7: 1 N·m on each): swapping the robot alone on a
#: scene tuned without it means ``robot.joint_friction = "ignore"`` (tests/test_robot_swap.py says why)
URDF_JOINT_FRICTION = frozenset({"xarm7"})


def urdf_dir() -> Path:
    """The project's ``urdf/`` folder, from a checkout or an installed wheel."""
    package = Path(__file__).resolve().parents[1]  # contactdyn/
    packaged = package / "data" / "urdf"
    return packaged if packaged.is_dir() else package.parent / "urdf"


@functools.cache
def example_robot_data_share() -> Path | None:
    """example-robot-data's share folder (holding ``robots/``), or None when not installed."""
    paths = sysconfig.get_paths()
    for base in dict.fromkeys((paths["purelib"], paths["platlib"])):
        share = Path(base) / "cmeel.prefix" / "share" / "example-robot-data"
        if (share / "robots").is_dir():
            return share
    return None


def require_example_robot_data() -> Path:
    share = example_robot_data_share()
    if share is None:
        raise RobotError("example-robot-data is not installed: pip install example-robot-data")
    return share


@functools.cache
def example_robots() -> dict[str, Path]:
    """Every example-robot-data URDF by name (short names first, then file stems); empty if not installed."""
    share = example_robot_data_share()
    if share is None:
        return {}
    robots = share / "robots"
    files = sorted(robots.glob("*/**/*.urdf"))
    stems = Counter(f.stem for f in files)
    names = {name: robots / rel for name, rel in SHORT_NAMES.items() if (robots / rel).is_file()}
    for f in files:
        unique = stems[f.stem] == 1 and names.get(f.stem, f) == f
        names.setdefault(f.stem if unique else f"{f.relative_to(robots).parts[0]}/{f.stem}", f)
    return names
