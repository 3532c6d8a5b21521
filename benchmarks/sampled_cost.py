"""What a sampled controller costs: each scene continuous against its controller sampled at a rate (1 kHz).

    PYTHONPATH=. python3 benchmarks/sampled_cost.py [--repeats 5] [--rate 1000] [--method M] [--profile] [scene ...]

Per scene (default: b1, case1_cart, case3_a_force, stiff_force), the continuous run and the same scene with
``controller.sample_rate`` set (every phase's controller sampled: a zero-order hold), interleaved repeat by repeat in
this process; cost = the median process CPU time around ``simulate`` (loading and output included; CPU because the
machine is shared), and the ratio sampled / continuous. Also: steps, right-hand-side calls, segments, samples, the
paths the modes ran on, the CPU per sample beyond the continuous run, and the sampled run's difference from the
continuous one (tip [m] and contact force [N], max over the output samples: the hold's own effect, first order in
1/rate, not an error of the integration).

With the compiled DOP853 a sample instant is a step boundary inside one segment (numerics.held_steps: the step
that reaches it is clipped to land on it, the held command jumps, f is evaluated again there); with other methods
it ends a segment. Either way a scene whose continuous steps are longer than the sample period takes at least one
step per period (B1: 243 steps over 2 s continuous, >= 2000 at 1 kHz): its ratio is bound by that. Only where the
continuous steps are already about as short as the period (``stiff_force``: B1 on a 1e7 N/m surface with a 0.1 kg
surface mass, benchmarks/stiff_force.toml) can a sampled run cost little more than the continuous one.

The CPU per sample beyond the continuous run is split into: ``steps`` (the extra steps at the continuous run's CPU
per step: output and set-up included, so an upper estimate), ``take`` (the sample itself: the measurement through
the compiled call, the sensors, the law; timed around SampledPhases.take) and ``rest`` (what
remains: the re-evaluation of f after the jump, the events across it, the pieces' bookkeeping and output).
Every mode runs on the one pipeline's compiled call (the paths column says so).
``floor``: the continuous run with ``solver.max_step`` = one period, timed with the others: the CPU a sampled run
cannot go below while it takes at least one DOP853 step per period (its ratio to the continuous run, and its steps).
``--method M``: every run with ``solver.method`` = M (``auto``: the stiff scenes of benchmarks/hard, ``hard_stiff``
and ``hard_fast_mass``, switch to Radau continuous; sampled, DOP853 carries the samples unless a period spans
HOLD_SWITCH of its steps, contactdyn.numerics.integrators); the segments per method are in the JSON.
``--profile``: cProfile of the first scene's sampled run (the 25 costliest functions, cumulative).

Writes benchmarks/out/sampled_cost.json and .csv (sampled_cost_<method>.* with ``--method``).
"""

from __future__ import annotations

import argparse
import cProfile
import csv
import pstats
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from timing import interleaved, write_report  # noqa: E402

from contactdyn import simulate  # noqa: E402
from contactdyn.hybrid.sampling import SampledPhases  # noqa: E402

OUT = Path(__file__).parent / "out"
HERE = Path(__file__).parent
SCENES = ("b1", "case1_cart", "case3_a_force", "stiff_force")
FILES = {"stiff_force": str(HERE / "stiff_force.toml"), "hard_stiff": str(HERE / "hard" / "stiff.toml"),
         "hard_fast_mass": str(HERE / "hard" / "fast_mass.toml")}  #: scenes of benchmarks/ by name
_TAKEN = [0.0]  #: [s] CPU inside SampledPhases.take since the last reset


def _timed_take(take):
    def timed(self, *args, **kwargs):
        c0 = time.process_time()
        try:
            return take(self, *args, **kwargs)
        finally:
            _TAKEN[0] += time.process_time() - c0
    return timed


def _call(name: str, overrides: dict):
    def run():
        _TAKEN[0] = 0.0
        result = simulate(FILES.get(name, name), overrides)
        result.stats["take_cpu_s"] = _TAKEN[0]
        return result
    return run


def _difference(a, b) -> dict:
    """Max |a − b| of the tip [m] and of every contact's normal force [N] over the output samples."""
    forces = [k for k in a.channels if k.endswith(".F_n")]
    return {"tip_m": float(abs(a["tip"] - b["tip"]).max()),
            "force_N": max((float(abs(a[k] - b[k]).max()) for k in forces), default=0.0)}


def compare(name: str, rate: float, repeats: int, base: dict | None = None) -> dict:
    base = base or {}
    times = interleaved({"continuous": _call(name, base),
                         "sampled": _call(name, {**base, "controller.sample_rate": rate}),
                         "bounded": _call(name, {**base, "solver.max_step": 1.0 / rate})}, repeats)
    row: dict = {"scene": name, "rate_hz": rate}
    for label, timing in times.items():
        r = timing.last
        row[label] = {"cpu_s": timing.cpu, "steps": r.stats["steps"], "rhs_evals": r.stats["rhs_evals"],
                      "segments": r.stats["segments"], "samples": r.stats.get("samples", 0),
                      "segments_by_method": r.stats.get("segments_by_method", {}),
                      "paths": sorted({p["path"] for p in r.stats["paths"].values()})}
    c, s = row["continuous"], row["sampled"]
    row["ratio"] = s["cpu_s"] / c["cpu_s"]
    row["floor_ratio"] = row["bounded"]["cpu_s"] / c["cpu_s"]  # no sampling, steps of at most one period
    row["us_per_sample"] = (s["cpu_s"] - c["cpu_s"]) / max(s["samples"], 1) * 1e6
    per_step = c["cpu_s"] / max(c["steps"], 1)  # [s] the continuous run's CPU per step, all included
    n = max(s["samples"], 1)
    steps_us = (s["steps"] - c["steps"]) * per_step / n * 1e6
    take_us = times["sampled"].last.stats["take_cpu_s"] / n * 1e6
    row["per_sample_us"] = {"steps": steps_us, "take": take_us, "rest": row["us_per_sample"] - steps_us - take_us}
    row["rhs_per_sample"] = (s["rhs_evals"] - c["rhs_evals"]) / max(s["samples"], 1)
    row["difference"] = _difference(times["sampled"].last, times["continuous"].last)
    return row


def profile(name: str, rate: float) -> None:
    overrides = {"controller.sample_rate": rate}
    simulate(FILES.get(name, name), overrides)  # compiled and cached first
    prof = cProfile.Profile()
    prof.runcall(simulate, FILES.get(name, name), overrides)
    pstats.Stats(prof).sort_stats("cumulative").print_stats(25)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("scenes", nargs="*", default=list(SCENES))
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--rate", type=float, default=1000.0, help="[Hz] the sample rate")
    ap.add_argument("--method", help="solver.method for every run (default: each scene's)")
    ap.add_argument("--profile", action="store_true")
    args = ap.parse_args()
    stem = f"sampled_cost_{args.method}" if args.method else "sampled_cost"
    base = {"solver.method": args.method} if args.method else {}
    SampledPhases.take = _timed_take(SampledPhases.take)
    rows = []
    print(f"{'scene':16s} {'cont. CPU [s]':>13s} {'sampled [s]':>11s} {'ratio':>6s} {'steps c/s':>11s} "
          f"{'us/sample':>9s} {'(steps':>6s} {'take':>5s} {'rest)':>6s} {'calls/sample':>12s} {'tip diff [m]':>12s} "
          f"{'F diff [N]':>10s} {'floor':>6s} {'steps':>6s}  sampled paths")
    for name in args.scenes:
        simulate(FILES.get(name, name), {**base, "controller.sample_rate": args.rate})  # (compiled and cached first)
        row = compare(name, args.rate, args.repeats, base)
        rows.append(row)
        c, s, part = row["continuous"], row["sampled"], row["per_sample_us"]
        print(f"{name:16s} {c['cpu_s']:13.3f} {s['cpu_s']:11.3f} {row['ratio']:6.2f} "
              f"{c['steps']:5d}/{s['steps']:<5d} {row['us_per_sample']:9.0f} {part['steps']:6.0f} {part['take']:5.0f} "
              f"{part['rest']:6.0f} {row['rhs_per_sample']:12.1f} "
              f"{row['difference']['tip_m']:12.3g} {row['difference']['force_N']:10.3g} {row['floor_ratio']:6.2f} "
              f"{row['bounded']['steps']:6d}  {', '.join(s['paths'])}")
    write_report(OUT / f"{stem}.json", {"rate_hz": args.rate, "repeats": args.repeats, "method": args.method}, rows)
    with (OUT / f"{stem}.csv").open("w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["scene", "rate_hz", "cpu_continuous_s", "cpu_sampled_s", "ratio", "steps_continuous",
                    "steps_sampled", "samples", "us_per_sample", "rhs_per_sample", "tip_diff_m", "force_diff_N",
                    "floor_ratio", "steps_bounded"])
        for row in rows:
            c, s = row["continuous"], row["sampled"]
            w.writerow([row["scene"], row["rate_hz"], c["cpu_s"], s["cpu_s"], row["ratio"], c["steps"], s["steps"],
                        s["samples"], row["us_per_sample"], row["rhs_per_sample"], row["difference"]["tip_m"],
                        row["difference"]["force_N"], row["floor_ratio"], row["bounded"]["steps"]])
    if args.profile:
        profile(args.scenes[0], args.rate)


if __name__ == "__main__":
    main()
