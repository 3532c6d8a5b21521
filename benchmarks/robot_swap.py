"""Swap the robot of case 2's writing task, full length: each arm of the swap matrix runs
``sims/case2_writer_ur5.toml`` with only ``robot.urdf`` and ``robot.tip`` changed.

For each robot the command line's outcome (exit 0, or exit 2 with its one-line reason) and, for
a run that finishes: DOF, wall time [s] (around ``simulate``, loading and the posture solve
included), steps, the pencil's normal force while drawing (t > 0.5 s: min, mean, max [N] against
the 5 N set-point), the tip's largest distance from the circle's reference in the paper plane
[mm], the pencil's largest angle from its direction [rad], and the start posture's limit margin
and smallest singular value.

    PYTHONPATH=. python3 benchmarks/robot_swap.py [robot ...]

The 5 N ± 10 % band over the full run is asserted by ``pytest --slow tests/test_robot_swap.py``.
Prints a table; writes benchmarks/out/robot_swap.json and .csv and each run as
benchmarks/out/robot_swap/<robot>.npz + .json (read by docs/make_swap_figures.py). The arms that
cannot reach the pose run again with the task moved within their reach (``MOVED``: robot.tip0).
"""

from __future__ import annotations

import argparse
import csv
import json
import time
from pathlib import Path

import numpy as np

from contactdyn import Robot, simulate
from contactdyn.errors import ContactdynError, SceneError
from contactdyn.robot.catalog import TOOL_FRAMES, URDF_JOINT_FRICTION
from contactdyn.scene.scene_file import load_scene

OUT = Path(__file__).parent / "out"
SCENE = "case2_writer_ur5"
SWAP = ["panda", "ur3", "ur5", "ur10", "xarm7", "z1", "kinova", "talos_arm", "so100"]
#: the arms that cannot reach the writer's pose, run again with the task moved within reach (robot.tip0 [m])
MOVED = {"z1": [0.25, 0.0, 0.0], "so100": [0.25, 0.0, 0.0], "talos_arm": [0.15, 0.0, 0.0]}
SET_POINT = 5.0  #: [N] the scene's pencil pressure
DRAWING = 0.5  #: [s] the circle starts here


def _tilt(result, scene) -> float:
    """Largest angle [rad] between the tool axis and its target direction over the run."""
    robot = Robot.from_spec(scene.robot)
    cfg = scene.phases[-1].controller
    target = cfg.tool_target / np.linalg.norm(cfg.tool_target)
    return max(float(np.arccos(np.clip((robot.frame_placement(q, scene.robot.tip).rotation @ cfg.tool_axis) @ target,
                                       -1, 1))) for q in result["q"])


def swap_row(robot: str, tip0: list[float] | None = None, save: Path | None = None) -> dict:
    overrides = {"robot.urdf": robot, "robot.tip": TOOL_FRAMES[robot]}
    if robot in URDF_JOINT_FRICTION:  # the robot swapped, not its joints' friction (tests/test_robot_swap.py says why)
        overrides["robot.joint_friction"] = "ignore"
    label = robot
    if tip0 is not None:
        overrides["robot.tip0"] = tip0
        label = f"{robot}_moved"
    row: dict = {"robot": label, "tip": TOOL_FRAMES[robot]}
    try:
        scene = load_scene(SCENE, overrides)
        start = time.perf_counter()
        result = simulate(scene)
        wall = time.perf_counter() - start
    except SceneError as exc:
        return {**row, "exit": 2, "reason": str(exc)}
    except ContactdynError as exc:
        return {**row, "exit": 1, "reason": str(exc)}
    drawing = result.t > DRAWING
    F = result["contact.pencil.F_n"][drawing]
    track = np.linalg.norm(result["tip"][drawing, :2] - result["tip_ref"][drawing, :2], axis=1)
    posture = result.meta.get("posture", {})
    if save is not None:
        result.save(save / label)
    return {**row, "exit": 0, "reason": "", "dof": len(result.meta["joints"]), "wall_s": wall,
            "steps": result.stats["steps"], "events": result.stats["events"],
            "separations": sum(e["kind"] == "separate" for e in result.events),
            "F_min": float(F.min()), "F_mean": float(F.mean()), "F_max": float(F.max()),
            "track_mm": 1e3 * float(track.max()), "tilt_rad": _tilt(result, scene),
            "limit_margin": posture.get("limit_margin"), "sigma_min": posture.get("sigma_min")}


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("robots", nargs="*", default=SWAP)
    args = parser.parse_args(argv)
    runs = OUT / "robot_swap"
    runs.mkdir(parents=True, exist_ok=True)
    rows = []
    print(f"{'robot':<18} {'exit':>4} {'DOF':>3} {'wall[s]':>7} {'steps':>6} {'F min/mean/max [N]':>20} "
          f"{'track[mm]':>9} {'tilt[rad]':>9} {'margin':>6}")
    cases = [(r, None) for r in args.robots] + [(r, tip0) for r, tip0 in MOVED.items() if r in args.robots]
    for robot, tip0 in cases:
        row = swap_row(robot, tip0, save=runs)
        robot = row["robot"]
        rows.append(row)
        if row["exit"]:
            print(f"{robot:<18} {row['exit']:>4}  {row['reason']}")
            continue
        print(f"{robot:<18} {row['exit']:>4} {row['dof']:>3} {row['wall_s']:>7.2f} {row['steps']:>6} "
              f"{row['F_min']:>6.2f}/{row['F_mean']:>5.2f}/{row['F_max']:>5.2f} {row['track_mm']:>11.2f} "
              f"{row['tilt_rad']:>9.4f} {row['limit_margin']:>6.3f}")
    (OUT / "robot_swap.json").write_text(json.dumps({"scene": SCENE, "rows": rows}, indent=1))
    keys = sorted({k for r in rows for k in r}, key=lambda k: list(rows[0]).index(k) if k in rows[0] else 99)
    with open(OUT / "robot_swap.csv", "w", newline="") as fh:
        writer = csv.DictWriter(fh, keys)
        writer.writeheader()
        writer.writerows(rows)


if __name__ == "__main__":
    main()
