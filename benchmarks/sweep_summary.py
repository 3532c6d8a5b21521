"""What keeping a sweep's summary current costs: a full rewrite after every chunk (before) against
one part file per chunk and rewrites by elapsed time (after, :mod:`contactdyn.sweep.summary`).

    python benchmarks/sweep_summary.py [--rows 10000,100000] [--repeats 5] [--chunk 32]

Synthetic records (the columns of a B1 run's row, random values; two swept parameters),
ROWS finished runs, in one process, interleaved, medians over REPEATS:

1. per chunk of CHUNK runs, with ROWS rows already finished: before, ``write_summary`` of the
   whole table (parquet, as every chunk did); after, ``Summary.add`` (a part file; no rewrite
   is due in the benchmark's few seconds);
2. a whole sweep of ROWS runs in chunks of CHUNK, summary work only: after, measured end to
   end (start rewrite, every chunk's part file, end rewrite); before, measured end to end at
   the smallest size only when it takes under a minute, else the sum over the chunks of the
   linear fit of (1) in the rows (a projection, marked so);
3. the rewrites during a real sweep (after): at most one per REFRESH_S = 30 s and per
   COST_FACTOR = 20 times its cost; for runs of RUN_S = 11 ms (22 ms of B1 on 2 workers) the
   bound of their cost, projected from (1).
4. resuming after a SIGKILL: reading the rows back (``cached_rows``) from the table alone
   against from part files alone.

Writes benchmarks/out/sweep_summary.json.
"""

from __future__ import annotations

import argparse
import json
import math
import shutil
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks"))

from timing import interleaved  # noqa: E402

from contactdyn.sweep.summary import COST_FACTOR, REFRESH_S, Summary, cached_rows, write_summary  # noqa: E402

OUT = ROOT / "benchmarks" / "out" / "sweep_summary.json"
KEYS = ["contact.tip.normal.k", "controller.kp"]
METRICS = ["contact.tip.F_peak", "contact.tip.F_final", "contact.tip.impacts", "contact.tip.impulse_n",
           "contact.tip.impulse_n_first", "contact.tip.impulse_t", "contact.tip.force_rms", "tracking_rms",
           "max_deformation", "events"]  #: a B1 run's metrics
RUN_S = 0.011  #: [s] per run: 22 ms of B1 (0.1 s) on 2 workers


def records(n: int, seed: int = 0) -> tuple[dict, dict]:
    """``n`` synthetic rows (1 % failed, with an error) and their parameters, by run id."""
    rng = np.random.default_rng(seed)
    values = rng.random((n, len(METRICS)))
    rows, params = {}, {}
    for i in range(n):
        rid = f"{i:012x}"
        failed = i % 100 == 0
        rows[rid] = {"run_id": rid, "status": "failed" if failed else "ok",
                     "error": "SimulationError: step size too small at t = 0.0123 s" if failed else "",
                     "wall_s": 0.02 + 0.01 * values[i, 0], **dict(zip(METRICS, values[i].tolist(), strict=True))}
        params[rid] = {KEYS[0]: 1e4 * (1 + i % 317), KEYS[1]: 100.0 * (1 + i // 317)}
    return rows, params


def whole_sweep_after(out: Path, rows: dict, params: dict, chunk: int) -> tuple[float, float]:
    """[s] the summary work of a whole sweep: (start rewrite and one part per chunk, end rewrite)."""
    shutil.rmtree(out, ignore_errors=True)
    out.mkdir()
    t0 = time.perf_counter()
    summary = Summary(out, {}, params, KEYS, False)
    summary.rewrite()
    ids = list(rows)
    for i in range(0, len(ids), chunk):
        summary.add([rows[r] for r in ids[i:i + chunk]])
    t1 = time.perf_counter()
    summary.rewrite()
    assert summary.rewrites == 2, "a rewrite fell due during the benchmark"
    return t1 - t0, time.perf_counter() - t1


def whole_sweep_before(out: Path, rows: dict, params: dict, chunk: int) -> float:
    """[s] the old summary work: the whole table rewritten after every chunk."""
    done: dict = {}
    t0 = time.perf_counter()
    write_summary(out, done, params, KEYS, False)
    ids = list(rows)
    for i in range(0, len(ids), chunk):
        done.update((r, rows[r]) for r in ids[i:i + chunk])
        write_summary(out, done, params, KEYS, False)
    return time.perf_counter() - t0


def per_chunk(tmp: Path, n: int, chunk: int, repeats: int) -> dict[str, float]:
    rows, params = records(n + chunk)
    ids = list(rows)
    table = {r: rows[r] for r in ids[:n]}
    new = [rows[r] for r in ids[n:]]
    out = tmp / f"chunk{n}"
    out.mkdir()
    summary = Summary(out, dict(table), params, KEYS, False)
    times = interleaved({"before": lambda: write_summary(out, {**table, **{r["run_id"]: r for r in new}}, params,
                                                         KEYS, False),
                         "after": lambda: summary.add(new)}, repeats)
    assert summary.rewrites == 0
    return {"before_s": times["before"].wall, "after_s": times["after"].wall}


def resume_read(tmp: Path, n: int, chunk: int, repeats: int) -> dict[str, float]:
    rows, params = records(n)
    table, parts = tmp / f"table{n}", tmp / f"parts{n}"
    for d in (table, parts):
        d.mkdir()
    write_summary(table, rows, params, KEYS, False)
    summary = Summary(parts, {}, params, KEYS, False)
    ids = list(rows)
    for i in range(0, n, chunk):
        summary.add([rows[r] for r in ids[i:i + chunk]])
    times = interleaved({"table": lambda: cached_rows(table), "parts": lambda: cached_rows(parts)}, repeats)
    assert len(times["table"].last) == len(times["parts"].last) == n
    return {"table_s": times["table"].wall, "parts_s": times["parts"].wall}


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rows", default="10000,100000")
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--chunk", type=int, default=32)
    args = ap.parse_args(argv)
    sizes = [int(s) for s in args.rows.split(",")]
    report: dict = {"chunk": args.chunk, "repeats": args.repeats, "refresh_s": REFRESH_S, "cost_factor": COST_FACTOR,
                    "run_s": RUN_S, "sizes": {}}
    with tempfile.TemporaryDirectory() as tmp_name:
        tmp = Path(tmp_name)
        warm, warm_params = records(100)
        write_summary(tmp, warm, warm_params, KEYS, False)  # pandas and pyarrow loaded before any timing
        chunks = {n: per_chunk(tmp, n, args.chunk, args.repeats) for n in sizes}
        # cost of a rewrite [s] = a + b * rows: the line through the two extreme sizes
        (n0, c0), (n1, c1) = (sizes[0], chunks[sizes[0]]["before_s"]), (sizes[-1], chunks[sizes[-1]]["before_s"])
        b = (c1 - c0) / (n1 - n0) if n1 != n0 else c0 / n0
        a = c0 - b * n0
        for n in sizes:
            rows, params = records(n)
            n_chunks = math.ceil(n / args.chunk)
            after = [whole_sweep_after(tmp / "after", rows, params, args.chunk) for _ in range(args.repeats)]
            projected = sum(a + b * min(n, args.chunk * (j + 1)) for j in range(n_chunks)) + a
            entry = {"per_chunk": chunks[n], "chunks": n_chunks,
                     "sweep_after_s": float(np.median([sum(t) for t in after])),
                     "sweep_after_parts_s": float(np.median([t[0] for t in after])),
                     "sweep_after_end_rewrite_s": float(np.median([t[1] for t in after])),
                     "sweep_before_projected_s": projected}
            if projected < 60.0:
                (tmp / "before").mkdir(exist_ok=True)
                entry["sweep_before_s"] = whole_sweep_before(tmp / "before", rows, params, args.chunk)
            runs_s = n * RUN_S
            rewrite_s = a + b * n
            entry["runs_s"] = runs_s
            entry["refresh_bound_s"] = rewrite_s * runs_s / max(REFRESH_S, COST_FACTOR * rewrite_s)
            entry["resume_read"] = resume_read(tmp, n, args.chunk, max(1, args.repeats // 2))
            report["sizes"][str(n)] = entry
    report["rewrite_fit"] = {"a_s": a, "b_s_per_row": b}
    OUT.parent.mkdir(parents=True, exist_ok=True)
    OUT.write_text(json.dumps(report, indent=1))
    print(f"summary cost per chunk of {args.chunk} runs and per sweep (medians of {args.repeats}, interleaved)")
    print(f"{'rows':>8} {'rewrite [s]':>12} {'part [ms]':>10} {'sweep before [s]':>18} "
          f"{'sweep after: parts+end [s]':>26} "
          f"{'refresh bound [s]':>18} {'runs [s]':>9} {'resume: table/parts [s]':>24}")
    for n, e in report["sizes"].items():
        before = (f"{e['sweep_before_s']:.1f}" if "sweep_before_s" in e else
                  f"~{e['sweep_before_projected_s']:.0f} (proj.)")
        print(f"{n:>8} {e['per_chunk']['before_s']:>12.3f} {1e3 * e['per_chunk']['after_s']:>10.2f} {before:>18} "
              f"{e['sweep_after_s']:>7.2f} ({e['sweep_after_parts_s']:.2f}+{e['sweep_after_end_rewrite_s']:.2f})"
              f" {e['refresh_bound_s']:>18.1f} {e['runs_s']:>9.0f} "
              f"{e['resume_read']['table_s']:>11.2f}/{e['resume_read']['parts_s']:<.2f}")
    print(f"rewrite cost fit: {a * 1e3:.1f} ms + {b * 1e6:.2f} µs per row; wrote {OUT.relative_to(ROOT)}")


if __name__ == "__main__":
    main()
