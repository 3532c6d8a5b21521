"""Whole runs before/after in one process: this tree's ``simulate`` against another tree's, alternated.

    PYTHONPATH=. python3 benchmarks/run_ab.py --baseline TREE [--repeats 9] [SCENE ...]

TREE's package is imported beside this one as ``contactdyn_baseline`` (``call_cycles.baseline_package``: a copy in a
temporary folder), so both run in this process and meet the machine's load alike (``scene_cost.py --baseline`` runs
them in child processes, whose own speeds differ by more than a small change). Per scene: one untimed run of each
(compiling, loading), then ``--repeats`` rounds of the two alternated; CPU time of each run, medians, the ratio
after / before and the range of the rounds' own ratios; the steps and events of each (a change of the model's
numbers shows there). Writes benchmarks/out/run_ab.json.
"""

from __future__ import annotations

import argparse
import importlib
import statistics
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from call_cycles import baseline_package  # noqa: E402
from timing import write_report  # noqa: E402

OUT = Path(__file__).parent / "out" / "run_ab.json"


def cpu_of(simulate, scene: str) -> tuple[float, object]:
    c0 = time.process_time()
    result = simulate(scene)
    return time.process_time() - c0, result


def compare(scene: str, runs: dict, repeats: int) -> dict:
    """Both trees' CPU per run of ``scene`` [s], alternated (the order swapped each round), and their ratio."""
    cpu = {label: [] for label in runs}
    last = {label: cpu_of(run, scene)[1] for label, run in runs.items()}  # (untimed: compiling, loading)
    for k in range(repeats):
        for label in (list(runs) if k % 2 == 0 else list(runs)[::-1]):
            seconds, last[label] = cpu_of(runs[label], scene)
            cpu[label].append(seconds)
    ratios = [a / b for a, b in zip(cpu["after"], cpu["before"], strict=True)]
    row = {"scene": scene, "ratio": statistics.median(cpu["after"]) / statistics.median(cpu["before"]),
           "ratio_min": min(ratios), "ratio_max": max(ratios)}
    for label in runs:
        row |= {f"{label}_cpu_s": statistics.median(cpu[label]), f"{label}_steps": last[label].stats["steps"],
                f"{label}_events": len(last[label].events)}
    return row


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("scenes", nargs="*", default=["b1", "case2_writer5dof", "case1_cart", "push_box"])
    ap.add_argument("--baseline", required=True, help="the source tree to compare against")
    ap.add_argument("--repeats", type=int, default=9)
    args = ap.parse_args()
    runs = {"before": importlib.import_module(baseline_package(args.baseline)).simulate,
            "after": importlib.import_module("contactdyn").simulate}
    rows = []
    print("scene | before [s] | after [s] | after/before (rounds' range) | steps before, after | events")
    for scene in args.scenes:
        r = compare(scene, runs, args.repeats)
        rows.append(r)
        print(f"{scene} | {r['before_cpu_s']:.3f} | {r['after_cpu_s']:.3f} | {r['ratio']:.3f} "
              f"({r['ratio_min']:.2f}–{r['ratio_max']:.2f}) | {r['before_steps']}, {r['after_steps']} | "
              f"{r['before_events']}, {r['after_events']}")
    write_report(OUT, {"baseline": args.baseline, "repeats": args.repeats}, rows)


if __name__ == "__main__":
    main()
