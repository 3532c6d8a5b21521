"""Cost per simulated second of whole scene runs, as a ratio to the hand-written B1 model.

    PYTHONPATH=. python3 benchmarks/scene_cost.py [SCENE ...] [--repeats 3] [--baseline TREE] [--out FILE.json]

Per repeat and scene, interleaved in one process: the hand-written closed-form B1 model
(:mod:`b1_reference`, 2 s simulated) and the scene's full run (``simulate``: loading,
building, output), after one untimed run of the scene whose CPU time is reported apart
(``first_run_cpu_s``: it also carries the process's one-time costs, e.g. loading the compiled
kernels). CPU time per simulated second [ms/s], medians over the repeats, and the ratio scene /
hand-written; also each repeat's own ratio (the two runs side by side), their median and range
(``x_paired``, ``x_paired_min``, ``x_paired_max``): on this shared machine the hand-written run alone moves by
up to 1.8× between repeats (34–63 ms/s in one process), so the range says how far one ratio can be trusted.
With ``--baseline TREE`` the same runs alternate between child
processes importing ``contactdyn`` from TREE and from this tree (:mod:`before_after`).
Default scenes: those with motors (DC motors, elastic transmissions, force-reading laws).
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from before_after import HERE, alternate, use_tree  # noqa: E402
from timing import interleaved  # noqa: E402

use_tree()

import b1_reference  # noqa: E402

from contactdyn import simulate  # noqa: E402
from contactdyn.scene.scene_file import load_scene  # noqa: E402

SCENES = ["case1_cart", "case2_writer_motors", "case3_a_position", "case3_a_force", "case3_b_position",
          "case3_b_force", "case3_b_force_varied"]


def measure(scenes: list[str], repeats: int) -> list[dict]:
    """Per scene: median CPU ms per simulated second of the scene and of the hand-written B1, interleaved."""
    rows = []
    for name in scenes:
        c0 = time.process_time()  # the first run apart: one-time costs of a process (compiled kernels' loading)
        simulate(load_scene(name))
        first = time.process_time() - c0
        times = interleaved({"hand": b1_reference.run, "scene": lambda name=name: simulate(load_scene(name))},
                            repeats)
        r = times["scene"].last
        span = float(r.t[-1] - r.t[0])  # [s] simulated
        c = times["scene"].cpu / span * 1e3
        h = times["hand"].cpu / b1_reference.T_END * 1e3
        paired = sorted((sc / span) / (hc / b1_reference.T_END)  # each repeat's own ratio
                        for sc, hc in zip(times["scene"].cpu_s, times["hand"].cpu_s, strict=True))
        rows.append({"scene": name, "ms_per_s": c, "hand_written_ms_per_s": h, "x_hand_written": c / h,
                     "x_paired": statistics.median(paired), "x_paired_min": paired[0], "x_paired_max": paired[-1],
                     "steps": r.stats.get("steps"), "rhs_evals": r.stats.get("rhs_evals"),
                     "first_run_cpu_s": first})
    return rows


def compare(scenes: list[str], repeats: int, baseline: str) -> list[dict]:
    """Before/after, alternating child processes; medians over the repeats of each child's medians."""
    got = alternate(__file__, [*scenes, "--repeats", "1"], {"baseline": baseline, "this": str(HERE)}, repeats)
    rows = []
    for i, name in enumerate(scenes):
        row = {"scene": name}
        for label, runs in got.items():
            row[f"{label}_ms_per_s"] = statistics.median(run[i]["ms_per_s"] for run in runs)
            row[f"{label}_x_hand_written"] = statistics.median(run[i]["x_hand_written"] for run in runs)
            row[f"{label}_steps"] = runs[-1][i]["steps"]
            row[f"{label}_first_run_s"] = statistics.median(run[i]["first_run_cpu_s"] for run in runs)
        row["speedup"] = row["baseline_ms_per_s"] / row["this_ms_per_s"]
        rows.append(row)
    return rows


def report(rows: list[dict], out: str | None) -> None:
    """Print the rows as a table (floats to 3 digits); write them to the JSON file ``out`` if given."""
    cols = list(rows[0])
    print(" | ".join(cols))
    for r in rows:
        print(" | ".join(f"{r[c]:.3g}" if isinstance(r[c], float) else str(r[c]) for c in cols))
    if out:
        Path(out).parent.mkdir(parents=True, exist_ok=True)
        Path(out).write_text(json.dumps(rows, indent=1))


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("scenes", nargs="*", default=SCENES)
    p.add_argument("--repeats", type=int, default=3)
    p.add_argument("--baseline", help="source tree to compare against (before/after)")
    p.add_argument("--out", help="JSON file to write")
    p.add_argument("--json", action="store_true", help=argparse.SUPPRESS)  # a child's output
    args = p.parse_args(argv)
    rows = compare(args.scenes, args.repeats, args.baseline) if args.baseline else measure(args.scenes, args.repeats)
    if args.json:
        print(json.dumps(rows))
        return 0
    report(rows, args.out)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
