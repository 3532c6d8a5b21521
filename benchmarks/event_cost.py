"""What a located event costs: the one-call interpolant and the stick-or-reverse decision against their old ways,
interleaved in one process.

    PYTHONPATH=. python3 benchmarks/event_cost.py [SCENE ...] [--repeats 9] [--out FILE.json]

Per scene (default: the real cell, sims/force_loop_real_cell.toml, 692 joint events in 3 s; the hard stick-slip
case; the 5-DOF writer; the lever), the whole run (``simulate``: loading, building, output) three ways, interleaved
repeat by repeat in this process, CPU medians:

- ``now``: as the package runs it (a located event's step interpolant in one compiled call,
  ``hybrid.steps.interpolant``; a joint's stick-or-reverse decision off one plain call, ``LastEvaluation.joint_hold``);
- ``old interpolant``: the step's interpolant by three calls of the right-hand side in Python and NumPy's arithmetic
  (``build_interpolants`` through ``fun``, what ``_Steps.at`` did before);
- ``old both``: that, and the decision off a whole ``Evaluation`` of the stuck trial.

Each variant's outputs are checked equal to ``now``'s, bit for bit (the same numbers by other routes); the table
gives the CPU per simulated second [ms/s], the ratios old / now and the located events. The machine is shared:
only ratios within one run mean anything. Writes benchmarks/out/event_cost.json.
"""

from __future__ import annotations

import argparse
import sys
import warnings
from contextlib import contextmanager
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from timing import interleaved, write_report  # noqa: E402

from contactdyn import simulate  # noqa: E402
from contactdyn.hybrid.transitions import LastEvaluation  # noqa: E402
from contactdyn.numerics import dop853  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent
SCENES = ["sims/force_loop_real_cell.toml", "benchmarks/hard/stickslip.toml", "sims/case2_writer5dof.toml",
          "sims/lever.toml"]


def _old_at(self, i, t, derivatives=None):
    """_Steps.at as it was: the step's interpolant by ``derivatives`` or by ``fun``, one Python call per stage."""
    if i not in self.coef:
        dop853.build_interpolants([(self, i)], derivatives)
    t_old = self.t[i]
    return dop853.horner_at(self.coef[i], (t - t_old) / (self.t[i + 1] - t_old), self.y_old(i))


def _old_hold(self, t, x, modes, phase):
    """LastEvaluation.joint_hold as it was: the whole Evaluation's."""
    return self(t, x, modes, phase).joint_hold


@contextmanager
def _patched(interpolant: bool, decision: bool):
    saved = dop853._Steps.at, LastEvaluation.joint_hold
    try:
        if interpolant:
            dop853._Steps.at = _old_at
        if decision:
            LastEvaluation.joint_hold = _old_hold
        yield
    finally:
        dop853._Steps.at, LastEvaluation.joint_hold = saved


def _run(path: str, interpolant: bool = False, decision: bool = False):
    def run():
        with _patched(interpolant, decision), warnings.catch_warnings():
            warnings.simplefilter("ignore")
            return simulate(str(ROOT / path))
    return run


def _same(a, b) -> bool:
    """Bit for bit the same channels and events."""
    return all(np.array_equal(np.asarray(a.channels[k]), np.asarray(b.channels[k]), equal_nan=True)
               for k in a.channels) and [(e["kind"], e["t"]) for e in a.events] == \
        [(e["kind"], e["t"]) for e in b.events]


def measure(path: str, repeats: int) -> dict:
    variants = {"now": _run(path), "old interpolant": _run(path, True), "old both": _run(path, True, True)}
    for run in variants.values():
        run()  # untimed: compiles, caches
    times = interleaved(variants, repeats)
    now = times["now"]
    T = now.last.channels["t"][-1]
    row = {"scene": path, "events": len(now.last.events), "steps": now.last.stats["steps"], "duration_s": float(T)}
    for key, timing in times.items():
        row[f"{key} ms/s"] = 1e3 * timing.cpu / T
        row[f"{key} same"] = _same(timing.last, now.last)
    row["old interpolant / now"] = times["old interpolant"].cpu / now.cpu
    row["old both / now"] = times["old both"].cpu / now.cpu
    return row


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("scenes", nargs="*", default=SCENES)
    p.add_argument("--repeats", type=int, default=9)
    p.add_argument("--out", default=str(ROOT / "benchmarks" / "out" / "event_cost.json"))
    args = p.parse_args(argv)
    rows = []
    print("| scene | events | now [ms/s] | old interpolant / now | old both / now | outputs the same |\n"
          "|---|---|---|---|---|---|")
    for path in args.scenes:
        r = measure(path, args.repeats)
        rows.append(r)
        same = all(r[f"{k} same"] for k in ("old interpolant", "old both"))
        print(f"| {Path(path).stem} | {r['events']} | {r['now ms/s']:.1f} | {r['old interpolant / now']:.3f} | "
              f"{r['old both / now']:.3f} | {'yes' if same else 'NO'} |", flush=True)
    write_report(Path(args.out), {"repeats": args.repeats, "cpu": "process_time, median"}, rows)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
