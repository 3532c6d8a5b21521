"""Per-call cost of the writer's task law: ``operational_space`` against ``task_pd`` with its tool axis.

    PYTHONPATH=. python3 benchmarks/operational_cost.py [--robots ur5,panda,writer5dof] [--calls 4000] [--runs 0]

For each robot the writing scene (``case2_writer_ur5`` with robot.urdf/robot.tip changed, or
``case2_writer5dof``) is built twice: with its ``operational_space`` law and with the ``task_pd``
law it used before (``TASK_PD``). On the states of 10 ms of the operational run (the first mode,
the press, on the compiled plan) it times, interleaved (the laws alternate batch by batch;
medians over 41 batches): the controller's ``command`` alone, on the same inputs, and each plan's
whole right-hand side. With ``--runs N``, also the whole 4.5 s run (``simulate``), N times each,
alternating, the median wall time, with the pressure each law holds while drawing (t > 0.5 s,
min / max [N]: the error it runs at). Ratios are new / old. Writes benchmarks/out/operational_cost.json.
"""

from __future__ import annotations

import argparse
import itertools
import json
import sys
import tomllib
from pathlib import Path

import numpy as np
from scipy.integrate import solve_ivp

sys.path.insert(0, str(Path(__file__).resolve().parent))

from timing import interleaved  # noqa: E402

from contactdyn.compiled.rhsplan import ModePlan  # noqa: E402
from contactdyn.laws.controllers import ControlInput  # noqa: E402
from contactdyn.model.phases import reference_at  # noqa: E402
from contactdyn.model.system import System  # noqa: E402
from contactdyn.robot.catalog import TOOL_FRAMES  # noqa: E402
from contactdyn.scene.scene_file import parse_scene, sims_dir  # noqa: E402
from contactdyn.simulate import prepare, run_system  # noqa: E402

OUT = Path(__file__).parent / "out"
BATCHES = 41
#: the writing scenes' task_pd law before operational_space
TASK_PD = {"kind": "task_pd", "kp": 800.0, "kd": 40.0, "axes": [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]],
           "tool_axis": [0.0, 0.0, 1.0], "tool_target": [0.18979606, 0.0587108, -0.98006658], "ko": 50.0, "do": 2.0,
           "kd_joint": 0.1, "kd_normal": 100.0, "feedforward": "gravity"}


def _scene(robot: str, controller: dict | None):
    name = "case2_writer5dof" if robot == "writer5dof" else "case2_writer_ur5"
    doc = tomllib.loads((sims_dir() / f"{name}.toml").read_text())
    if controller is not None:
        doc["controller"] = controller
    overrides = {} if robot == "writer5dof" else {"robot.urdf": robot, "robot.tip": TOOL_FRAMES[robot]}
    return parse_scene(doc, overrides)


def _plan(robot: str, controller: dict | None):
    system, modes, phase, x0 = prepare(_scene(robot, controller))
    plan = ModePlan(system, modes, phase)
    if not plan.ok:
        raise SystemExit(f"{robot}: not on the compiled path ({plan.reason})")
    return system, plan, phase, x0


def _input(system, phase, t: float, x: np.ndarray) -> ControlInput:
    """What the phase's controller reads at (t, x) (the readable path's terms)."""
    nQ, nv, robot = system.nQ, system.nv, system.robot
    q, v = x[:nv].copy(), x[nQ:nQ + nv].copy()
    robot.update(q, v)
    ft = robot.frame_terms(system.tip_fid)
    x_d, v_d, a_d = reference_at(system, phase, t, x)
    return ControlInput(t, q, v, robot.H.copy(), robot.h.copy(), robot.gravity_torque(q), ft.position, ft.velocity,
                        ft.jacobian, ft.drift, x_d, v_d, a_d, {}, {k: r.at(t) for k, r in phase.forces.items()},
                        system.force_directions, np.zeros(0), R_tip=ft.rotation, J_ang=ft.angular_jacobian,
                        drift_ang=ft.angular_drift)


def _per_call(fns: dict, args: dict, calls: int) -> dict[str, float]:
    """Median seconds per call of each function over BATCHES batches, the functions alternating batch by
    batch (benchmarks/timing.py); each batch calls its function on the next of its argument tuples."""
    per_batch = max(calls // BATCHES, 1)

    def batch(fn, cycle):
        def run():
            a = next(cycle)
            for _ in range(per_batch):
                fn(*a)
        return run

    times = interleaved({k: batch(fn, itertools.cycle(args[k])) for k, fn in fns.items()}, BATCHES)
    return {k: t.wall / per_batch for k, t in times.items()}


def _runs(robot: str, repeats: int) -> dict:
    """Whole runs of both laws, alternating: median wall [s] (the System built, integrated, sampled) and
    the pressure while drawing [N]."""
    scenes = {"new": _scene(robot, None), "old": _scene(robot, TASK_PD)}
    times = interleaved({k: (lambda sc=sc: run_system(System(sc))) for k, sc in scenes.items()}, repeats)
    out: dict = {}
    for name, t in times.items():
        F = t.last["contact.pencil.F_n"][t.last.t > 0.5]
        out.update({f"run_{name}_s": t.wall, f"F_{name}": [float(F.min()), float(F.max())],
                    f"steps_{name}": t.last.stats["steps"]})
    out["run_ratio"] = out["run_new_s"] / out["run_old_s"]
    return out


def measure(robot: str, calls: int) -> dict:
    new, old = _plan(robot, None), _plan(robot, TASK_PD)
    sol = solve_ivp(new[1].rhs, (new[2].t_start, new[2].t_start + 0.01), new[3], method="DOP853", rtol=1e-8,
                    atol=1e-10)
    states = [(float(t), sol.y[:, i].copy()) for i, t in enumerate(sol.t)]
    inputs = {k: [(_input(s, ph, t, x),) for t, x in states] for k, (s, _, ph, _) in (("new", new), ("old", old))}
    law = _per_call({"new": new[2].controller.command, "old": old[2].controller.command}, inputs, calls)
    rhs = _per_call({"new": new[1].rhs, "old": old[1].rhs}, {"new": states, "old": states}, calls)
    law_new, law_old, rhs_new, rhs_old = law["new"], law["old"], rhs["new"], rhs["old"]
    return {"robot": robot, "dof": new[0].nv, "states": len(states), "law_new_us": 1e6 * law_new,
            "law_old_us": 1e6 * law_old, "law_ratio": law_new / law_old, "rhs_new_us": 1e6 * rhs_new,
            "rhs_old_us": 1e6 * rhs_old, "rhs_ratio": rhs_new / rhs_old}


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--robots", default="ur5,panda,writer5dof")
    parser.add_argument("--calls", type=int, default=4000)
    parser.add_argument("--runs", type=int, default=0, help="whole runs of each law (0: none)")
    args = parser.parse_args(argv)
    rows = []
    print(f"{'robot':<11} {'DOF':>3} {'law new / old [µs]':>19} {'ratio':>6} {'rhs new / old [µs]':>19} {'ratio':>6}")
    for robot in args.robots.split(","):
        r = measure(robot, args.calls)
        if args.runs:
            r.update(_runs(robot, args.runs))
        rows.append(r)
        print(f"{r['robot']:<11} {r['dof']:>3} {r['law_new_us']:>9.1f} / {r['law_old_us']:<7.1f} "
              f"{r['law_ratio']:>6.2f} {r['rhs_new_us']:>9.1f} / {r['rhs_old_us']:<7.1f} {r['rhs_ratio']:>6.2f}",
              flush=True)
        if args.runs:
            print(f"{'':<11} whole run new / old: {r['run_new_s']:.2f} / {r['run_old_s']:.2f} s (ratio "
                  f"{r['run_ratio']:.2f}), steps {r['steps_new']} / {r['steps_old']}, pressure while drawing "
                  f"{r['F_new'][0]:.2f}-{r['F_new'][1]:.2f} / {r['F_old'][0]:.2f}-{r['F_old'][1]:.2f} N", flush=True)
    OUT.mkdir(exist_ok=True)
    (OUT / "operational_cost.json").write_text(json.dumps(rows, indent=1))


if __name__ == "__main__":
    main()
