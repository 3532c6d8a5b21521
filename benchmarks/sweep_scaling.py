"""Scaling of a sweep: 1 vs 2 workers on a process pool and on a Dask LocalCluster, and their per-run overhead.

    python benchmarks/sweep_scaling.py [--runs 200] [--repeats 3] [--duration 0.1] [--no-dask] [--set K=V]

A sweep of RUNS short B1 runs (``duration`` seconds at 200 Hz output, contact stiffness
log-spaced over 5e4..2e5 N/m, ``--set`` overrides on every run, e.g. the integrator) is
timed end to end (``run_sweep``: results and summary
written to a temporary folder) in five ways: in this process (no pool: the baseline),
a process pool of 1 and of 2 workers, a Dask ``LocalCluster`` of 1 and of 2 worker
processes. Each is repeated REPEATS times; the median and the range are reported, with how
busy the whole machine was meanwhile (from /proc/stat: a sweep on one worker of an otherwise idle 2-core machine
keeps it about 50 % busy; more means someone else was computing too).

- runs per second = RUNS / the median sweep time;
- speed-up = time with 1 worker / time with 2 workers (the goal: >= 1.7 on 2 cores);
- per-run overhead = (time with 1 worker − time in this process) / RUNS: what the pool or
  Dask costs per run. Start-up is reported apart: the pool's workers fork from a server
  that imported the package once per process (started before timing); each Dask
  measurement starts a fresh cluster (not timed), whose workers import the package during
  a 1-run sweep (timed: "start-up of a 1-run sweep", minus the same sweep in this process).

Writes benchmarks/out/sweep_scaling.json.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from contactdyn.sweep import make_sweep, run_sweep  # noqa: E402

OUT = Path(__file__).resolve().parent / "out" / "sweep_scaling.json"


def _sweep(runs: int, duration: float, sets: tuple[str, ...] = ()):
    return make_sweep("b1", sets=[f"duration={duration}", "solver.output_rate=200", *sets],
                      ranges=[f"contact.tip.normal.k=5e4:2e5:{runs}:log"])


def _cpu_jiffies() -> tuple[int, int]:
    """(busy, total) CPU time of the whole machine from /proc/stat (0, 0 where there is none)."""
    try:
        fields = [int(v) for v in Path("/proc/stat").read_text().split("\n", 1)[0].split()[1:]]
    except (OSError, ValueError):
        return 0, 0
    idle = fields[3] + (fields[4] if len(fields) > 4 else 0)  # idle + iowait
    return sum(fields) - idle, sum(fields)


def _time(sweep, **kw) -> tuple[float, dict, float]:
    """Wall time [s], statuses, and the machine's busy fraction meanwhile (all cores, anyone's work)."""
    with tempfile.TemporaryDirectory() as tmp:
        busy0, total0 = _cpu_jiffies()
        t0 = time.perf_counter()
        report = run_sweep(sweep, tmp, check=False, **kw)
        wall = time.perf_counter() - t0
        busy1, total1 = _cpu_jiffies()
        return wall, report.counts, (busy1 - busy0) / max(total1 - total0, 1)


def _time_dask(big, one, n_workers: int) -> tuple[float, dict, float, float, float]:
    """Start a LocalCluster, run the 1-run sweep (workers import the package), time the big one, close."""
    from distributed import LocalCluster

    t0 = time.perf_counter()
    with LocalCluster(n_workers=n_workers, processes=True, threads_per_worker=1, dashboard_address=None) as cluster:
        start = time.perf_counter() - t0
        t1 = _time(one, scheduler=cluster.scheduler_address)[0]
        t, counts, busy = _time(big, scheduler=cluster.scheduler_address)
    return t, counts, busy, t1, start


def _stats(times: list[float]) -> dict:
    return {"median_s": statistics.median(times), "min_s": min(times), "max_s": max(times), "all_s": times}


def measure(modes: dict[str, dict], big, one, repeats: int, runs: int) -> dict[str, dict]:
    """Each mode's sweep times [s], 1-run sweep times [s], machine busy fractions, statuses, cluster starts [s]."""
    times: dict[str, list[float]] = {m: [] for m in modes}
    single: dict[str, list[float]] = {m: [] for m in modes}
    busy: dict[str, list[float]] = {m: [] for m in modes}
    cluster_start: dict[str, list[float]] = {m: [] for m in modes if "dask_workers" in modes[m]}
    counts = {}
    for r in range(repeats):  # interleaved, so slow drifts of the machine hit every mode alike
        for mode, kw in modes.items():
            if "dask_workers" in kw:  # a fresh cluster per measurement, so idle clusters never compete
                t, counts[mode], b, t1, start = _time_dask(big, one, kw["dask_workers"])
                cluster_start[mode].append(start)
            else:
                t, counts[mode], b = _time(big, **kw)
                t1 = _time(one, **kw)[0]
            times[mode].append(t)
            busy[mode].append(b)
            single[mode].append(t1)
            print(f"repeat {r + 1}/{repeats} {mode:>6}: {t:7.2f} s for {runs} runs, "
                  f"machine busy {100 * b:3.0f} %", flush=True)
    return {"times": times, "single": single, "busy": busy, "counts": counts, "cluster_start": cluster_start}


def summarise(m: dict[str, dict], runs: int) -> dict:
    """Runs per second, speed-ups 2 vs 1 workers (with their ranges), overhead per run and start-up [s]."""
    times = m["times"]
    med = {k: statistics.median(v) for k, v in times.items()}
    med1 = {k: statistics.median(v) for k, v in m["single"].items()}
    out = {
        "statuses": m["counts"], "machine_busy_fraction": m["busy"],
        "sweep": {k: _stats(v) for k, v in times.items()},
        "one_run_sweep": {k: _stats(v) for k, v in m["single"].items()},
        "dask_cluster_start_s": m["cluster_start"],  #: not in any sweep time
        "per_run_inline_s": med["inline"] / runs,
        "runs_per_s": {k: runs / v for k, v in med.items()},
        "overhead_per_run_s": {k: (med[k] - med["inline"]) / runs for k in med if k.endswith("1")},
        "startup_s": {k: med1[k] - med1["inline"] for k in med if k.endswith("1")},
    }
    for kind in ("pool", "dask"):
        if f"{kind}2" in med:
            one, two = times[f"{kind}1"], times[f"{kind}2"]
            out[f"speedup_{kind}"] = med[f"{kind}1"] / med[f"{kind}2"]
            out[f"speedup_{kind}_range"] = [min(one) / max(two), max(one) / min(two)]
    return out


def print_report(report: dict, sets: list[str]) -> None:
    n, sweep = report["runs"], report["sweep"]
    load0, load1 = report["loadavg_before"], report["loadavg_after"]
    print(f"\n{n} runs of b1 ({report['duration_s']} s simulated each{', ' + ' '.join(sets) if sets else ''}), "
          f"median of {report['repeats']} "
          f"(load average {load0[0]:.1f} -> {load1[0]:.1f} on {os.cpu_count()} cores)")
    print(f"{'mode':>8} {'median [s]':>11} {'range [s]':>17} {'per run [ms]':>13} {'runs/s':>8} {'machine busy':>13}")
    for m, st in sweep.items():
        print(f"{m:>8} {st['median_s']:11.2f} {st['min_s']:8.2f}-{st['max_s']:<8.2f} "
              f"{1e3 * st['median_s'] / n:13.2f} {n / st['median_s']:8.1f} "
              f"{100 * statistics.median(report['machine_busy_fraction'][m]):12.0f}%")
    print(f"(machine busy: all cores, anyone's work; a quiet {os.cpu_count()}-core machine shows about "
          f"{100 / (os.cpu_count() or 1):.0f}% for one worker, 100% for two)")
    print(f"speed-up 2 vs 1 workers: pool {report['speedup_pool']:.2f} (range {report['speedup_pool_range'][0]:.2f}-"
          f"{report['speedup_pool_range'][1]:.2f})", end="")
    if "speedup_dask" in report:
        print(f", Dask {report['speedup_dask']:.2f} (range {report['speedup_dask_range'][0]:.2f}-"
              f"{report['speedup_dask_range'][1]:.2f})", end="")
    print()
    for m, o in report["overhead_per_run_s"].items():
        print(f"overhead per run, {m}: {1e3 * o:.2f} ms (start-up of a 1-run sweep: {report['startup_s'][m]:.2f} s)")
    if report["dask_cluster_start_s"]:
        print("Dask LocalCluster start (not in the sweep times): "
              + ", ".join(f"{m} {statistics.median(t):.2f} s" for m, t in report["dask_cluster_start_s"].items()))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=200)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--duration", type=float, default=0.1, help="simulated seconds per run")
    ap.add_argument("--no-dask", action="store_true")
    ap.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                    help="a scene override for every run (e.g. solver.method=DOP853C)")
    args = ap.parse_args()

    big, one = _sweep(args.runs, args.duration, tuple(args.set)), _sweep(1, args.duration, tuple(args.set))
    modes: dict[str, dict] = {"inline": {"workers": 0}, "pool1": {"workers": 1}, "pool2": {"workers": 2}}
    if not args.no_dask:
        import logging

        logging.getLogger("distributed").setLevel(logging.ERROR)
        modes.update({"dask1": {"dask_workers": 1}, "dask2": {"dask_workers": 2}})
    _time(one, workers=0)  # warm this process up (imports, first URDF parse) before the baseline is timed
    first_pool = _time(one, workers=1)[0]  # starts the fork server (once per process: not charged to a mode)
    load0 = os.getloadavg()
    measured = measure(modes, big, one, args.repeats, args.runs)
    report = {"runs": args.runs, "repeats": args.repeats, "duration_s": args.duration, "sets": args.set,
              "cpu_count": os.cpu_count(), "loadavg_before": load0, "loadavg_after": os.getloadavg(),
              "python": platform.python_version(),
              "first_pool_1_run_sweep_s": first_pool,  #: includes starting the fork server (imports the package)
              **summarise(measured, args.runs)}
    OUT.parent.mkdir(exist_ok=True)
    OUT.write_text(json.dumps(report, indent=1))
    print_report(report, args.set)
    print(f"wrote {OUT}")

if __name__ == "__main__":
    main()
