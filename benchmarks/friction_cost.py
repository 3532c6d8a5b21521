"""Cost of Coulomb stick/slip: each scene with friction against the same scene with
``tangent.model = "free"``, at the same tolerance.

Scenes (defined below, all on a rigid surface):

- ``writer2r drag``: the planar writer (case 2's robot) presses 50 N on a table and a
  light task-space PD drags its tip along x at 5 cm/s; μ_s = 0.5, μ_k = 0.3 make it
  stick and slip (about 8 stick–slip cycles in 3 s);
- ``point mass, oscillating push``: a 2 kg mass pushed by 16 sin(2π t) N along x and
  pressed by its weight + 5 N, μ_s = 0.6, μ_k = 0.35 (slip, stop, stick every half period);
- ``point mass 2-D, rotating push``: circular sliding (no stops), 2-D friction and its
  ``turn`` events.

For each: wall time (the minimum of REPEATS runs, friction and free interleaved: the machine
is shared, noise only adds), right-hand-side evaluations, steps, segments, events, and the ratio friction/free.
The load average is recorded.

    PYTHONPATH=. python3 benchmarks/friction_cost.py [--repeats 5]

Prints a table and writes benchmarks/out/friction_cost.json.
"""

from __future__ import annotations

import argparse
import copy
import math
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from timing import interleaved, write_report  # noqa: E402

from contactdyn import Robot, parse_scene, simulate  # noqa: E402

OUT = Path(__file__).parent / "out" / "friction_cost.json"
SOLVER = {"rtol": 1e-8, "atol": 1e-10, "output_rate": 100.0}


def writer_drag() -> tuple[dict, str]:
    q0 = [0.6, 1.2]
    robot = Robot.load("writer2r")
    p = robot.frame_position(np.array(q0), robot.frame_id("tip"))
    doc = {
        "name": "writer2r_drag", "duration": 3.0, "solver": dict(SOLVER),
        "robot": {"urdf": "writer2r", "q0": q0},
        "contact": {"table": {"point": [0.0, 0.0, float(p[2])], "normal": {"direction": [0.0, 0.0, 1.0]},
                              "tangent": {"model": "friction", "directions": [[1.0, 0.0, 0.0]],
                                          "mu_s": 0.5, "mu_k": 0.3}}},
        "controller": {"kind": "task_pd", "kp": 2000.0, "kd": 5.0, "axes": [[1.0, 0.0, 0.0]],
                       "feedforward": "gravity"},
        "phase": [{"name": "drag",
                   "reference": {"start": p.tolist(), "moves": [
                       {"kind": "constant_velocity", "delta": [-0.2, 0.0, 0.0], "duration": 4.0}]},
                   "force": [{"contact": "table", "value": 50.0, "kind": "step"}]}],
    }
    return doc, "table"


def point_mass_push() -> tuple[dict, str]:
    doc = {
        "name": "point_mass_push", "duration": 3.0, "solver": dict(SOLVER),
        "robot": {"urdf": "point_mass_xz", "q0": [0.0, 0.0]},
        "contact": {"ground": {"point": [0.0, 0.0, 0.0], "normal": {"direction": [0.0, 0.0, 1.0]},
                               "tangent": {"model": "friction", "directions": [[1.0, 0.0, 0.0]],
                                           "mu_s": 0.6, "mu_k": 0.35}}},
        "controller": {"kind": "task_force", "force": [0.0, 0.0, -5.0], "amplitude": [16.0, 0.0, 0.0],
                       "frequency": 1.0},
    }
    return doc, "ground"


def point_mass_circle() -> tuple[dict, str]:
    mu, P, w, m, g = 0.4, 10.0, 2 * math.pi, 2.0, 9.81
    alpha = math.acos(mu * m * g / P)
    s = P * math.sin(alpha) / (m * w)
    doc = {
        "name": "point_mass_circle", "duration": 3.0, "solver": dict(SOLVER),
        "robot": {"urdf": "point_mass_xyz", "q0": [0.0, 0.0, 0.0],
                  "v0": [s * math.cos(alpha), -s * math.sin(alpha), 0.0]},
        "contact": {"ground": {"point": [0.0, 0.0, 0.0], "normal": {"direction": [0.0, 0.0, 1.0]},
                               "tangent": {"model": "friction", "directions": [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]],
                                           "mu": mu}}},
        "controller": {"kind": "task_force", "amplitude": [P, P, 0.0], "frequency": 1.0,
                       "phase": [math.pi / 2, 0.0, 0.0]},
    }
    return doc, "ground"


SCENES = [("writer2r drag (stick-slip)", writer_drag), ("point mass, oscillating push", point_mass_push),
          ("point mass 2-D, rotating push", point_mass_circle)]


def measure(docs: dict[str, dict], repeats: int) -> dict[str, dict]:
    """Each scene document run ``repeats`` times, interleaved: wall times [s], counters, events."""
    scenes = {key: parse_scene(copy.deepcopy(doc)) for key, doc in docs.items()}
    times = interleaved({key: lambda scene=scene: simulate(scene) for key, scene in scenes.items()}, repeats)
    rows = {}
    for key, timing in times.items():
        result, st = timing.last, timing.last.stats
        rows[key] = {"wall_s_min": min(timing.wall_s), "wall_s_median": timing.wall, "rhs_evals": st["rhs_evals"],
                     "steps": st["steps"], "segments": st["segments"], "events": len(result.events),
                     "event_kinds": sorted({e["kind"] for e in result.events})}
    return rows


def main(argv: list[str] | None = None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=5)
    args = ap.parse_args(argv)
    rows = []
    for label, make in SCENES:
        doc, contact = make()
        free = copy.deepcopy(doc)
        free["contact"][contact]["tangent"] = {"model": "free"}
        fr, fe = measure({"friction": doc, "free": free}, args.repeats).values()
        rows.append({"scene": label, "friction": fr, "free": fe,
                     "wall_ratio": fr["wall_s_min"] / fe["wall_s_min"],
                     "rhs_ratio": fr["rhs_evals"] / fe["rhs_evals"]})
    print(f"{'scene':32s} {'wall fr/free [s]':>20s} {'ratio':>6s} {'rhs fr/free':>14s} {'ratio':>6s} "
          f"{'segments':>9s} {'events':>7s}")
    for r in rows:
        fr, fe = r["friction"], r["free"]
        print(f"{r['scene']:32s} {fr['wall_s_min']:9.3f}/{fe['wall_s_min']:<9.3f} {r['wall_ratio']:6.2f} "
              f"{fr['rhs_evals']:6d}/{fe['rhs_evals']:<7d} {r['rhs_ratio']:6.2f} {fr['segments']:9d} {fr['events']:7d}")
    return write_report(OUT, {"solver": SOLVER, "repeats": args.repeats}, rows)


if __name__ == "__main__":
    main()
