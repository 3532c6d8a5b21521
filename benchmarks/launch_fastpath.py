"""The writers' 2-D launch from rest on the compiled path: cost per simulated second against B1 by hand.

    PYTHONPATH=. python3 benchmarks/launch_fastpath.py [--repeats 5] [scene ...]

For each scene (default: the two writers, whose pencil sticks, then breaks away into a 2-D
slide from rest): the run as it is (every mode on the one pipeline's compiled call, the launch
direction solved per call on its KKT system), the run with the launch not compiled ("before": the same, but the
launching modes on the same call interpreted, :func:`motor_fastpath.run` with ``interpret``; once the readable
model integrated them, a path that no longer exists), and the hand-written closed-form B1
(``benchmarks/b1_reference.py`` at rtol 1e-8), interleaved after an untimed run of each,
``--repeats`` times each. Reported: the median wall per simulated second [ms/s] (building the
system and the output included), its ratio to the hand-written B1's, and the force error
max |F_n − F_n,ref| [N] of both runs against a compiled reference at rtol 1e-11, atol 1e-13
(away from ±2 samples of every event, :func:`motor_fastpath.force_error`).
Writes benchmarks/out/launch_fastpath.json.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))
sys.path.insert(0, str(Path(__file__).resolve().parent))

import b1_reference  # noqa: E402
import motor_fastpath  # noqa: E402
from motor_fastpath import force_error  # noqa: E402
from timing import interleaved, write_report  # noqa: E402

from contactdyn.model.friction import launching  # noqa: E402
from contactdyn.model.paths import INTERPRETED  # noqa: E402
from contactdyn.scene.scene_file import load_scene  # noqa: E402

SCENES = ["case2_writer5dof", "case2_writer_ur5"]
OUT = Path(__file__).resolve().parent / "out" / "launch_fastpath.json"


def launches(modes, phase) -> bool:
    """A mode with a 2-D slide launching from rest (once off the compiled call: the gap a former branch removed)."""
    return any(launching(m) for m in modes)


def run(scene: str, before: bool, overrides: dict | None = None):
    """The Result of building and running the scene (``before``: the launching modes interpreted)."""
    return motor_fastpath.run(scene, before, overrides, interpret=launches)


def measure(scene: str, repeats: int) -> dict:
    duration = load_scene(scene).duration
    variants = {"after": lambda: run(scene, False), "before": lambda: run(scene, True), "b1_hand": b1_reference.run}
    for call in variants.values():
        call()  # untimed: numba's compile (or cache load) of the pipeline for this scene's laws
    times = interleaved(variants, repeats)
    ref = run(scene, False, {"solver.rtol": 1e-11, "solver.atol": 1e-13})
    row: dict = {"scene": scene, "duration_s": duration, "repeats": repeats}
    for key, span in (("after", duration), ("before", duration), ("b1_hand", b1_reference.T_END)):
        row[f"{key}_ms_per_s"] = 1e3 * times[key].wall / span
    for key in ("after", "before"):
        result = times[key].last
        row[f"{key}_x_b1_hand"] = row[f"{key}_ms_per_s"] / row["b1_hand_ms_per_s"]
        row[f"{key}_F_err_N"] = force_error(result, ref)
        row[f"{key}_interpreted_modes"] = sum(r["path"] == INTERPRETED for r in result.stats["paths"].values())
        row[f"{key}_rhs_evals"] = result.stats["rhs_evals"]
    row["speedup"] = row["before_ms_per_s"] / row["after_ms_per_s"]
    return row


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("scenes", nargs="*", default=SCENES)
    ap.add_argument("--repeats", type=int, default=5)
    args = ap.parse_args(argv)
    rows = []
    print(f"{'scene':18s} {'before [ms/s]':>13s} {'after [ms/s]':>12s} {'B1 hand':>8s} {'before/B1':>9s} "
          f"{'after/B1':>8s} {'speed-up':>8s}  F_n err before / after [N]   interpreted modes before / after")
    for scene in args.scenes:
        row = measure(scene, args.repeats)
        rows.append(row)
        print(f"{scene:18s} {row['before_ms_per_s']:13.1f} {row['after_ms_per_s']:12.1f} "
              f"{row['b1_hand_ms_per_s']:8.1f} {row['before_x_b1_hand']:9.1f} {row['after_x_b1_hand']:8.1f} "
              f"{row['speedup']:7.2f}x  {row['before_F_err_N']:.3g} / {row['after_F_err_N']:.3g}"
              f"   {row['before_interpreted_modes']} / {row['after_interpreted_modes']}")
    write_report(OUT, {"repeats": args.repeats}, rows)
    return 0


if __name__ == "__main__":
    sys.exit(main())
