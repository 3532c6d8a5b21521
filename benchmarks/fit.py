"""Validation of ``contactdyn fit`` on benchmark B1 (issue 17, item 4).

    PYTHONPATH=. python benchmarks/fit.py [--realisations 20] [--workers 0] [--out benchmarks/out/fit.json]
    PYTHONPATH=. python benchmarks/fit.py --pool 3     # the pool's speed-up on one fit (fit_pool.json)

Truth: B1 with k = 1.3e5 N/m, m′ = 8 kg, μ = 0.35 (the scene has 1e5, 10, 0.4), simulated
at rtol 1e-11; 1 % Gaussian noise = σ of 1 % of each channel's RMS value (F_n ≈ 100 N:
σ ≈ 1 N; tip x: σ ≈ 3.1 mm; tip y: σ ≈ 1.5 mm). The fit starts from the scene's values
and estimates the noise from the data. Four checks, each printed and written to the JSON:

1. recovery: each of k, m′, μ within 2 % and inside its 95 % interval (noise seed 0);
2. coverage: over ``--realisations`` noise seeds, how often each 95 % interval holds the truth;
3. the surface damping b (truth 1 N·s/m) fitted as a fourth parameter: reported as not determined?
4. an independent model: data from the closed-form B1 of ``b1_reference.py`` with the same
   changed k, m′, μ (F_n and tip x, the same noise rule), fitted within 2 %;

and the cost of each fit: wall time and number of simulations.
"""

from __future__ import annotations

import argparse
import csv
import json
import os
import statistics
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

import b1_reference  # noqa: E402
from timing import interleaved  # noqa: E402

import contactdyn  # noqa: E402

K, M, MU = "contact.tip.normal.k", "contact.tip.normal.m", "contact.tip.tangent.mu"
B = "contact.tip.normal.b"
TRUTH = {K: 1.3e5, M: 8.0, MU: 0.35}
NOISE = 0.01  #: σ as a fraction of each channel's RMS value
TRUTH_RTOL, TRUTH_ATOL = 1e-11, 1e-13


def simulated_channels() -> dict[str, np.ndarray]:
    r = contactdyn.simulate("b1", {**TRUTH, "solver.rtol": TRUTH_RTOL, "solver.atol": TRUTH_ATOL})
    return {"t": r.t, "contact.tip.F_n": r["contact.tip.F_n"], "tip[0]": r["tip"][:, 0], "tip[1]": r["tip"][:, 1]}


def reference_channels() -> dict[str, np.ndarray]:
    """The hand-written B1 model with the true k, m′, μ (its reference lead δ stays the scene's 0.02 m)."""
    saved = (b1_reference.K, b1_reference.ME, b1_reference.MU)
    b1_reference.K, b1_reference.ME, b1_reference.MU = TRUTH[K], TRUTH[M], TRUTH[MU]
    try:
        ref = b1_reference.reference(1e-12, 1e-13)
    finally:
        b1_reference.K, b1_reference.ME, b1_reference.MU = saved
    return {"t": ref["t"], "contact.tip.F_n": ref["F_n"], "tip[0]": ref["x_tip"]}


def write_log(channels: dict[str, np.ndarray], seed: int, path: Path) -> dict[str, float]:
    """Add the noise and write the CSV; return σ per column."""
    rng = np.random.default_rng(seed)
    names = [k for k in channels if k != "t"]
    sigma = {k: NOISE * float(np.sqrt(np.mean(channels[k] ** 2))) for k in names}
    noisy = {k: channels[k] + rng.normal(0.0, sigma[k], channels[k].size) for k in names}
    with path.open("w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["t", *names])
        for i, t in enumerate(channels["t"]):
            w.writerow([repr(float(t)), *(repr(float(noisy[k][i])) for k in names)])
    return sigma


def one_fit(log: Path, params: list[str], workers: int) -> dict:
    cpu0 = time.process_time()
    res = contactdyn.fit("b1", log, ",".join(params), workers=workers)
    out = {"runs": res.runs, "wall_s": res.wall_s, "cpu_s": time.process_time() - cpu0, "chi2_red": res.chi2_red,
           "channels": {c.name: {"rms_over_noise": c.ratio, "noise": c.sigma} for c in res.channels},
           "estimates": {}}
    for e in res.estimates:
        truth = TRUTH.get(e.key, 1.0 if e.key == B else None)
        out["estimates"][e.key] = {
            "truth": truth, "value": e.value, "se": e.se, "ci95": [e.low, e.high], "determined": e.determined,
            "warnings": list(e.warnings),
            "error_pct": 100 * (e.value - truth) / truth if truth else None,
            "in_ci": bool(e.low <= truth <= e.high) if truth else None}
    return out


def _print_fit(title: str, fit: dict) -> None:
    print(f"{title}: {fit['runs']} simulations, {fit['wall_s']:.1f} s, reduced chi2 {fit['chi2_red']:.3f}")
    for key, e in fit["estimates"].items():
        print(f"  {key:<24} truth {e['truth']:<9g} fit {e['value']:<11.6g} error {e['error_pct']:+7.3f} %  "
              f"95 % [{e['ci95'][0]:.6g}, {e['ci95'][1]:.6g}] {'in' if e['in_ci'] else 'OUT'}"
              f"{'' if e['determined'] else '  (not determined: ' + e['warnings'][0] + ')'}")


def pool_ratio(log: Path, repeats: int, workers: int) -> dict:
    """Wall time of the same fit in this process and on ``workers`` pool processes, interleaved; medians."""
    times = interleaved({w: lambda w=w: contactdyn.fit("b1", log, f"{K},{M},{MU}", workers=w) for w in (0, workers)},
                        repeats)
    walls = {w: t.wall_s for w, t in times.items()}
    here, pooled = times[0].wall, times[workers].wall
    print(f"pool: {workers} workers {pooled:.1f} s, this process {here:.1f} s (medians of {repeats}, interleaved): "
          f"speed-up {here / pooled:.2f}; load average {os.getloadavg()[0]:.1f}")
    return {"workers": workers, "wall_s": walls, "speedup": here / pooled, "load_average": os.getloadavg()[0]}


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--realisations", type=int, default=20)
    p.add_argument("--workers", type=int, default=0)
    p.add_argument("--out", default="benchmarks/out/fit.json")
    p.add_argument("--tmp", default="benchmarks/out/fit_logs")
    p.add_argument("--pool", type=int, default=0, metavar="REPEATS",
                   help="only time one fit in this process against 2 pool workers, REPEATS times each")
    args = p.parse_args(argv)
    tmp = Path(args.tmp)
    tmp.mkdir(parents=True, exist_ok=True)
    if args.pool:
        log = tmp / "b1_seed0.csv"
        write_log(simulated_channels(), 0, log)
        out = Path(args.out).with_name("fit_pool.json")
        out.write_text(json.dumps(pool_ratio(log, args.pool, 2), indent=1))
        return 0
    three = [K, M, MU]
    report: dict = {"truth": TRUTH, "noise": "1 % of each channel's RMS", "workers": args.workers}

    sim = simulated_channels()
    fits = []
    for seed in range(args.realisations):
        log = tmp / f"b1_seed{seed}.csv"
        write_log(sim, seed, log)
        fits.append(one_fit(log, three, args.workers))
        e = fits[-1]["estimates"]
        print(f"seed {seed:2d}: " + "  ".join(f"{k.split('.')[-1]} {v['error_pct']:+.3f} % "
                                              f"{'in' if v['in_ci'] else 'OUT'}" for k, v in e.items())
              + f"  ({fits[-1]['runs']} runs, {fits[-1]['wall_s']:.1f} s wall, {fits[-1]['cpu_s']:.1f} s CPU)",
              flush=True)
    _print_fit("1. recovery (seed 0)", fits[0])
    report["recovery"] = fits[0]
    report["recovery_ok"] = all(abs(e["error_pct"]) < 2 and e["in_ci"] for e in fits[0]["estimates"].values())
    coverage = {k: sum(f["estimates"][k]["in_ci"] for f in fits) for k in three}
    report["coverage"] = {"realisations": len(fits), "in_ci": coverage,
                          "max_abs_error_pct": {k: max(abs(f["estimates"][k]["error_pct"]) for f in fits)
                                                for k in three}}
    print(f"2. coverage over {len(fits)} realisations (target >= {0.8 * len(fits):g}): {coverage}; "
          f"max |error| %: {report['coverage']['max_abs_error_pct']}")
    walls, runs, cpus = [f["wall_s"] for f in fits], [f["runs"] for f in fits], [f["cpu_s"] for f in fits]
    report["cost"] = {"wall_s_median": statistics.median(walls), "wall_s_max": max(walls),
                      "cpu_s_median": statistics.median(cpus), "cpu_s_max": max(cpus),
                      "cpu_s_per_run_median": statistics.median(c / r for c, r in zip(cpus, runs, strict=True)),
                      "runs_median": statistics.median(runs), "runs_max": max(runs)}

    with_b = one_fit(tmp / "b1_seed0.csv", [*three, B], args.workers)
    _print_fit("3. with the surface damping b", with_b)
    report["damping"] = with_b
    report["damping_not_determined"] = not with_b["estimates"][B]["determined"]

    ref_log = tmp / "b1_reference_seed0.csv"
    write_log(reference_channels(), 0, ref_log)
    independent = one_fit(ref_log, three, args.workers)
    _print_fit("4. data from the closed-form model (b1_reference.py)", independent)
    report["independent"] = independent
    report["independent_ok"] = all(abs(e["error_pct"]) < 2 for e in independent["estimates"].values())
    c = report["cost"]
    print(f"cost per fit (B1, 3 parameters, {len(fits)} fits): wall median {c['wall_s_median']:.1f} s "
          f"(max {c['wall_s_max']:.1f}), CPU median {c['cpu_s_median']:.1f} s (max {c['cpu_s_max']:.1f}; "
          f"{c['cpu_s_per_run_median'] * 1e3:.0f} ms per simulation), simulations median {c['runs_median']:g} "
          f"(max {c['runs_max']}); load average at the end {os.getloadavg()[0]:.1f}")
    report["load_average_end"] = os.getloadavg()[0]
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    Path(args.out).write_text(json.dumps(report, indent=1))
    print(f"-> {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
