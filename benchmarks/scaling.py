"""How the cost grows: per right-hand-side call and per simulated second against the robot's DOF,
the number of touching contacts and the number of chain stages.

    PYTHONPATH=. python3 benchmarks/scaling.py [--repeats 3] [--figure docs/figures/performance/scaling.png]

Three series, each a family of scenes that differ in one thing:

- **DOF** (2, 3, 5, 6, 7): B1 (planar 2R); B1's press-and-slide task on case 3's cylindrical
  robot (3 DOF: surface below the tool, slide along x); case 2's writing task (2-D friction,
  tool-axis law) on our 5-DOF writer, the UR5 and the Panda (``tests/test_robot_swap.py``'s
  overrides), its first 1.5 s;
- **contacts** (1–4): B1 with its surface split into N parallel bonded model (b) contacts
  on the tip (each k/N, b/N, m/N, μ, pressed with F_d/N): the same motion, N times the rows;
- **chain stages** (1–4): B1 with its surface a chain of N stage–mass pairs
  (k·N, b·N, m/N each: the same static stiffness and mass, faster internal modes).

Per row: the compiled call's rhs per call (the one pipeline's; ``path``: its Python stages, if any), the same
call with all its diagnostics per call (``PipelineMode.evaluation``, an Evaluation; once System.evaluate's), the raw
Pinocchio calls of the same terms per call
(``benchmarks/robot_calls.py``; DOF series) — medians over batches on states of a short run
(``benchmarks/rhs_cost.py``), in process CPU time, the minimum over batches (contention only
adds; the medians are in the JSON) — and CPU ms per simulated second of the
whole run (``simulate``: loading and output included) with solve_ivp's DOP853 and the
compiled DOP853C (interleaved repeats, medians, after one untimed run of each: the process's one-time
loading of compiled code apart). CPU time, not wall: this 2-core machine is
shared and its load average reached 7 during these runs (wall time then measures the others).
The Pinocchio floor is ``robot_calls``' minimum over samples (wall clock). Writes
benchmarks/out/scaling.json and .csv, and the plot.
"""

from __future__ import annotations

import argparse
import copy
import csv
import json
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

import rhs_cost  # noqa: E402
import robot_calls  # noqa: E402
from timing import interleaved  # noqa: E402

from contactdyn import simulate  # noqa: E402
from contactdyn.scene.scene_file import load_scene, parse_scene  # noqa: E402

OUT = Path(__file__).parent / "out"
METHODS = ("DOP853", "DOP853C")
PANDA = {"robot.urdf": "panda", "robot.tip": "panda_hand_tcp",
         "robot.active_joints": [f"panda_joint{i}" for i in range(1, 8)],
         "robot.q_seed": [0.2999989987439, 0.4533589376897, 8.22e-07, -2.952374138562, 2.09e-07, 3.605732992723,
                          0.7849995339517]}  # as tests/test_robot_swap.py
WRITER_T = 1.5  #: [s] simulated of the writing task (0.5 s pressing + 1 s of the circle)


def _b1_doc() -> dict:
    return copy.deepcopy(load_scene("b1").document)


def _cylindrical3() -> dict:
    """B1's task on case 3's robot: tool at (1, 0, 0.9) m on the surface, sliding along −x."""
    doc = _b1_doc()
    doc["name"] = "b1_task_cylindrical3"
    doc["robot"] = {"urdf": "cylindrical3", "tip": "tip", "gravity": [0.0, 0.0, 0.0], "q0": [0.0, 0.0, 0.3],
                    "v0": [0.0, -0.15, 0.0]}
    c = doc["contact"]["tip"]
    c["point"], c["normal"]["direction"] = [0.0, 0.0, 0.9], [0.0, 0.0, 1.0]
    doc["controller"]["axes"] = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]
    doc["phase"][0]["reference"]["start"] = [0.98, 0.0, 0.9]
    return doc


def _contacts(n: int) -> dict:
    doc = _b1_doc()
    doc["name"] = f"b1_{n}_contacts"
    tip = doc["contact"].pop("tip")
    phase = doc["phase"][0]
    (force,) = phase.pop("force")
    phase["force"] = []
    for i in range(n):
        c = copy.deepcopy(tip)
        for key in ("k", "b", "m"):
            c["normal"][key] = tip["normal"][key] / n
        doc["contact"][f"tip{i + 1}"] = c
        phase["force"].append(dict(force, contact=f"tip{i + 1}", value=force["value"] / n))
    return doc


def _chain(n: int) -> dict:
    doc = _b1_doc()
    doc["name"] = f"b1_chain_{n}"
    nm = doc["contact"]["tip"]["normal"]
    stages = []
    for _ in range(n):
        stages += [{"k": nm["k"] * n, "b": nm["b"] * n}, {"m": nm["m"] / n}]
    doc["contact"]["tip"]["normal"] = {"direction": nm["direction"], "model": "chain", "environment": stages}
    return doc


def series() -> list[tuple[str, str, int, object, tuple | None]]:
    """(series, label, x, scene, (robot source, frame, options) for the Pinocchio cost or None)."""
    writer = load_scene("case2_writer5dof", {"duration": WRITER_T})
    rows = [("dof", "b1 (planar 2R)", 2, load_scene("b1"), ("planar2r_b1", "tip", {})),
            ("dof", "B1 task, cylindrical3", 3, parse_scene(_cylindrical3()), ("cylindrical3", "tip", {})),
            ("dof", "writer, writer5dof", 5, writer, ("writer5dof", "tip", {})),
            ("dof", "writer, UR5", 6, load_scene("case2_writer_ur5", {"duration": WRITER_T}), ("ur5", "tool0", {})),
            ("dof", "writer, Panda", 7, load_scene("case2_writer5dof", {"duration": WRITER_T, **PANDA}),
             ("panda", "panda_hand_tcp", {"active_joints": PANDA["robot.active_joints"]}))]
    rows += [("contacts", f"B1, {n} contacts", n, parse_scene(_contacts(n)), None) for n in (1, 2, 3, 4)]
    rows += [("stages", f"B1, chain of {n} stages", n, parse_scene(_chain(n)), None) for n in (1, 2, 3, 4)]
    return rows


def measure(scene, repeats: int, robot: tuple | None) -> dict:
    cost = rhs_cost.measure(scene, 8000)
    row = {"path": cost["path"], "n_states": cost["n_states"], "rhs_us": cost["rhs_cpu_min_us"],
           "evaluation_us": cost["evaluation_cpu_min_us"], "rhs_cpu_median_us": cost["rhs_cpu_median_us"],
           "evaluation_cpu_median_us": cost["evaluation_cpu_median_us"]}
    if robot is not None:
        source, frame, options = robot
        calls = robot_calls.measure(source, frame, options, 30, 300)
        row["pinocchio_us"] = calls["raw pinocchio, same calls"]["min"]  # (wall clock: the minimum on a busy machine)
    runs = {m: lambda m=m: simulate(scene, {"solver.method": m}) for m in METHODS}
    for run in runs.values():  # untimed: the process's one-time loading of each method's compiled code
        run()
    times = interleaved(runs, repeats)
    for m in METHODS:
        stats = times[m].last.stats
        row[f"{m}_steps"], row[f"{m}_rhs_evals"] = stats["steps"], stats["rhs_evals"]
        row[f"{m}_ms_per_s"] = times[m].cpu / scene.duration * 1e3
    return row


def plot(rows: list[dict], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(2, 3, figsize=(13, 7), sharey="row")
    for k, (name, xlabel) in enumerate((("dof", "robot DOF"), ("contacts", "touching contacts"),
                                        ("stages", "chain stages (masses)"))):
        sel = [r for r in rows if r["series"] == name]
        x = [r["x"] for r in sel]
        ax = axes[0, k]
        ax.plot(x, [r["rhs_us"] for r in sel], "o-", label="rhs call (compiled call)")
        ax.plot(x, [r["evaluation_us"] for r in sel], "s--", label="the call with its diagnostics")
        if name == "dof":
            ax.plot(x, [r["pinocchio_us"] for r in sel], "^:", label="Pinocchio terms alone")
        ax.set_yscale("log")
        ax.set_title(f"CPU µs per call vs {xlabel}")
        ax.set_xticks(x)
        ax.grid(True, which="both", alpha=0.3)
        ax = axes[1, k]
        for m, style in zip(METHODS, ("o-", "s-"), strict=True):
            ax.plot(x, [r[f"{m}_ms_per_s"] for r in sel], style, label=m)
        ax.set_yscale("log")
        ax.set_xlabel(xlabel)
        ax.set_xticks(x)
        ax.set_title("CPU ms per simulated second")
        ax.grid(True, which="both", alpha=0.3)
    axes[0, 0].set_ylabel("µs per call")
    axes[1, 0].set_ylabel("ms per simulated s")
    axes[0, 0].legend(fontsize=8)
    axes[1, 0].legend(fontsize=8)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--repeats", type=int, default=3)
    p.add_argument("--figure", default=str(OUT / "scaling.png"))
    args = p.parse_args(argv)
    rows = []
    print("| series | scene | x | states | path | rhs [µs] | evaluation [µs] | Pinocchio [µs] | "
          + " | ".join(f"{m} [ms/sim-s] | {m} steps" for m in METHODS) + " |")
    print("|---|---|---|---|---|---|---|---|" + "---|---|" * len(METHODS))
    for name, label, x, scene, robot in series():
        row = {"series": name, "scene": label, "x": x, **measure(scene, args.repeats, robot)}
        rows.append(row)
        pin_us = f"{row['pinocchio_us']:.1f}" if "pinocchio_us" in row else ""
        print(f"| {name} | {label} | {x} | {row['n_states']} | {row['path']} | {row['rhs_us']:.1f} | "
              f"{row['evaluation_us']:.1f} | {pin_us} | "
              + " | ".join(f"{row[f'{m}_ms_per_s']:.0f} | {row[f'{m}_steps']}" for m in METHODS) + " |", flush=True)
    OUT.mkdir(parents=True, exist_ok=True)
    (OUT / "scaling.json").write_text(json.dumps({"repeats": args.repeats, "rows": rows}, indent=1))
    keys = [*rows[0], "pinocchio_us"]
    with open(OUT / "scaling.csv", "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=list(dict.fromkeys(keys)), extrasaction="ignore")
        w.writeheader()
        w.writerows(rows)
    plot(rows, Path(args.figure))
    print(f"wrote {OUT / 'scaling.json'}, {OUT / 'scaling.csv'}, {args.figure}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
