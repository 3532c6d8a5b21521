"""Plans compiled and CPU time with a plan per 2-D reference direction (before issue 13) and a
plan per mode structure (a ``turn`` event reuses the plan), in one run.

"Before" is the same code with :func:`contactdyn.compiled.rhsplan.structure` replaced by ``tuple``: the
plan key is then the full modes, direction included, as it was, and :meth:`ModePlan.use` never
rebinds (the modes it is given are its own). Scenes: ``benchmarks/friction_cost.py``'s three
and the 2-D writers ``case2_writer5dof``, ``case2_writer_ur5`` at their own settings. Each run
starts with an empty plan cache (the system is built once per scene, outside the timing); the
two variants are interleaved (``benchmarks/timing.py``) and their CPU medians reported, with
the largest relative difference of any channel between them (max |a − b| / max |b| per channel).

    PYTHONPATH=. python3 benchmarks/turn_plans.py [--repeats 3] [SCENE ...]

Prints a table and writes benchmarks/out/turn_plans.json.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from friction_cost import SCENES  # noqa: E402
from timing import interleaved, write_report  # noqa: E402

from contactdyn import load_scene, parse_scene  # noqa: E402
from contactdyn.compiled import rhsplan  # noqa: E402
from contactdyn.hybrid import loop as hybrid  # noqa: E402
from contactdyn.model.system import System  # noqa: E402
from contactdyn.simulate import run_system  # noqa: E402

OUT = Path(__file__).parent / "out" / "turn_plans.json"
WRITERS = ("case2_writer5dof", "case2_writer_ur5")
STRUCTURE = rhsplan.structure


def run(system: System, per_direction: bool):
    """One run from an empty plan cache: (result, plans compiled)."""
    key = tuple if per_direction else STRUCTURE
    rhsplan.structure = hybrid.structure = key
    try:
        rhsplan._PLANS.pop(system, None)
        result = run_system(system)
        return result, len(rhsplan._PLANS[system])
    finally:
        rhsplan.structure = hybrid.structure = STRUCTURE


def channel_difference(a, b) -> tuple[float, str]:
    """max over channels of max |a − b| / max |b| (NaN equal to NaN), and that channel."""
    worst, where = 0.0, ""
    for key in b.channels:
        x, y = np.asarray(a[key], float), np.asarray(b[key], float)
        if x.shape != y.shape:
            return float("inf"), key
        d = np.where(np.isnan(x) & np.isnan(y), 0.0, np.abs(x - y))
        rel = float(np.nanmax(d, initial=0.0)) / max(float(np.nanmax(np.abs(y), initial=0.0)), 1e-300)
        if rel > worst:
            worst, where = rel, key
    return worst, where


def measure(label: str, system: System, repeats: int) -> dict:
    times = interleaved({"per_direction": lambda: run(system, True), "per_structure": lambda: run(system, False)},
                        repeats)
    (before, n_before), (after, n_after) = times["per_direction"].last, times["per_structure"].last
    diff, channel = channel_difference(after, before)
    same_events = [(e["kind"], e.get("contact"), e["t"]) for e in before.events] == \
                  [(e["kind"], e.get("contact"), e["t"]) for e in after.events]
    return {"scene": label, "turns": sum(e["kind"] == "turn" for e in after.events), "events": len(after.events),
            "plans_before": n_before, "plans_after": n_after,
            "cpu_before_s": times["per_direction"].cpu, "cpu_after_s": times["per_structure"].cpu,
            "cpu_ratio": times["per_structure"].cpu / times["per_direction"].cpu,
            "rhs_evals": [before.stats["rhs_evals"], after.stats["rhs_evals"]],
            "max_rel_diff": diff, "worst_channel": channel, "same_events": same_events}


def main(argv: list[str] | None = None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("scenes", nargs="*", help="a subset: friction_cost labels' first word or writer scene names")
    args = ap.parse_args(argv)
    systems = {label: (lambda make=make: System(parse_scene(make()[0]))) for label, make in SCENES}
    systems.update({name: (lambda name=name: System(load_scene(name))) for name in WRITERS})
    if args.scenes:
        systems = {k: v for k, v in systems.items() if any(k.startswith(s) for s in args.scenes)}
    rows = [measure(label, build(), args.repeats) for label, build in systems.items()]
    print(f"{'scene':32s} {'turns':>5s} {'plans before/after':>18s} {'CPU before/after [s]':>21s} {'ratio':>6s} "
          f"{'max rel diff':>12s} {'events same':>11s}")
    for r in rows:
        print(f"{r['scene']:32s} {r['turns']:5d} {r['plans_before']:9d}/{r['plans_after']:<8d} "
              f"{r['cpu_before_s']:10.3f}/{r['cpu_after_s']:<10.3f} {r['cpu_ratio']:6.2f} {r['max_rel_diff']:12.1e} "
              f"{str(r['same_events']):>11s}")
    return write_report(OUT, {"repeats": args.repeats}, rows)


if __name__ == "__main__":
    main()
