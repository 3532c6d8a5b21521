"""Every scene in sims/, run in full: cost at default settings and error against a tight run.

For each ``sims/*.toml``:

- **default run**: the scene as it is, ``REPEATS`` times (default 3); wall time = the median
  (measured around ``simulate``: loading, building and output included), real-time factor =
  duration / wall, steps, rhs evaluations and events of the run;
- **reference run**: the same scene at rtol 1e-11, atol 1e-13; it is **checked** by a run at
  half those tolerances, and the reference-vs-check difference is reported (the reference's own
  error, which must be well below the errors it measures);
- **errors** of the default run against the reference, on the common output grid (same
  ``output_rate``): force = max |F_n − F_n,ref| over all contacts [N], tip = max
  |tip − tip_ref| (Euclidean) [m], stage = max |x − x_ref| over all deformation stages [m].
  Where the two runs switch mode at slightly different times (touch, separation, slip, ...)
  the outputs differ by a jump for a sample or two, which is not integration error: each
  error is given away from ±2 samples of every event of either run ("away") and over all
  samples ("all"). ``turn`` events (a 2-D friction direction refresh) are not mode switches
  and are not excluded. An error below the reference's check difference is not resolved and is
  printed as "< (that difference)".

    PYTHONPATH=. /work/venv/bin/python benchmarks/scenes.py [--repeats 3] [scene ...]

Prints a table and writes benchmarks/out/scenes.json and benchmarks/out/scenes.csv.
"""

from __future__ import annotations

import argparse
import csv
import json
import os
import platform
import statistics
import time
from pathlib import Path

import numpy as np

from contactdyn import simulate
from contactdyn.errors import ContactdynError
from contactdyn.scene.scene_file import load_scene, sims_dir

OUT = Path(__file__).parent / "out"
#: the reference and its check: solve_ivp's DOP853 (whatever the default method) at tight tolerances
REFERENCE = {"solver.method": "DOP853", "solver.rtol": 1e-11, "solver.atol": 1e-13}
CHECK = {"solver.method": "DOP853", "solver.rtol": 5e-12, "solver.atol": 5e-14}
GUARD = 2  #: samples excluded on each side of an event
NOT_SWITCHES = ("turn",)  #: event kinds that are no mode switch


def _event_mask(t: np.ndarray, *runs) -> np.ndarray:
    """True at samples farther than GUARD samples from every event of the given runs."""
    keep = np.ones(len(t), bool)
    dt = (t[-1] - t[0]) / max(len(t) - 1, 1)
    for r in runs:
        for e in r.events:
            if e["kind"] not in NOT_SWITCHES:
                keep &= np.abs(t - e["t"]) > GUARD * dt * (1 + 1e-9)
    return keep


def _max(values: np.ndarray, mask: np.ndarray | None = None) -> float:
    v = values if mask is None else values[mask]
    return float(np.max(v)) if v.size else 0.0


def errors(run, ref) -> dict[str, float]:
    """Force [N], tip [m] and stage [m] errors of ``run`` against ``ref`` (same output grid)."""
    if len(run.t) != len(ref.t) or np.max(np.abs(run.t - ref.t)) > 1e-12:
        raise ValueError("the runs have different output grids")
    keep = _event_mask(run.t, run, ref)
    out = {}
    force = np.zeros(len(run.t))
    for name in run.channels:
        if name.startswith("contact.") and name.endswith(".F_n"):
            force = np.maximum(force, np.abs(run[name] - ref[name]))
    tip = np.linalg.norm(run["tip"] - ref["tip"], axis=1)
    stage = np.zeros(len(run.t))
    for name in run.channels:
        if name.startswith("stage.") and name.endswith(".x"):
            stage = np.maximum(stage, np.abs(run[name] - ref[name]))
    for label, values in (("force", force), ("tip", tip), ("stage", stage)):
        out[f"{label}_all"] = _max(values)
        out[f"{label}_away"] = _max(values, keep)
    out["samples_away"] = int(keep.sum())
    out["samples"] = len(keep)
    return out


def bench(name: str, repeats: int) -> dict:
    scene = load_scene(name)
    row: dict = {"scene": name, "duration_s": scene.duration, "method": scene.solver.method,
                 "rtol": scene.solver.rtol, "atol": scene.solver.atol, "output_rate_hz": scene.solver.output_rate}
    walls = []
    run = None
    for _ in range(repeats):
        t0 = time.perf_counter()
        run = simulate(name)
        walls.append(time.perf_counter() - t0)
    wall = statistics.median(walls)
    row.update(wall_s=wall, wall_runs_s=walls, real_time_factor=scene.duration / wall, steps=run.stats["steps"],
               rhs_evals=run.stats["rhs_evals"], events=len(run.events), impacts=len(run.impacts),
               max_force_n=max((float(np.max(np.abs(run[c]))) for c in run.channels
                                if c.startswith("contact.") and c.endswith(".F_n")), default=0.0))
    try:
        t0 = time.perf_counter()
        ref = simulate(name, REFERENCE)
        row["reference_wall_s"] = time.perf_counter() - t0
        row["reference_steps"] = ref.stats["steps"]
        check = simulate(name, CHECK)
    except ContactdynError as exc:  # a reference that cannot be had is a result too
        row["reference_error"] = str(exc)
        return row
    row.update({f"err_{k}": v for k, v in errors(run, ref).items()})
    row.update({f"refcheck_{k}": v for k, v in errors(ref, check).items()})
    row["events_reference"] = len(ref.events)
    return row


def _err(r: dict, what: str, where: str) -> str:
    """An error, or "< c" when it is below the reference's own check difference c (not resolved)."""
    e, c = r[f"err_{what}_{where}"], r[f"refcheck_{what}_{where}"]
    return f"< {c:.0e}" if e < c else f"{e:.1e}"


def table(rows: list[dict]) -> str:
    head = ("| scene | T [s] | wall [s] | RTF | steps | rhs evals | events | force err [N] away / all | "
            "tip err [m] away / all | stage err [m] away | reference self-check force [N] / tip [m] |")
    lines = [head, "|" + "---|" * (head.count("|") - 1)]
    for r in rows:
        if "reference_error" in r:
            errs = f"reference failed: {r['reference_error'][:60]}"
            lines.append(f"| {r['scene']} | {r['duration_s']:g} | {r['wall_s']:.2f} | {r['real_time_factor']:.2f} | "
                         f"{r['steps']} | {r['rhs_evals']} | {r['events']} | {errs} | | | |")
            continue
        lines.append(
            f"| {r['scene']} | {r['duration_s']:g} | {r['wall_s']:.2f} | {r['real_time_factor']:.2f} | {r['steps']} | "
            f"{r['rhs_evals']} | {r['events']} | {_err(r, 'force', 'away')} / {_err(r, 'force', 'all')} | "
            f"{_err(r, 'tip', 'away')} / {_err(r, 'tip', 'all')} | {_err(r, 'stage', 'away')} | "
            f"{r['refcheck_force_away']:.1e} / {r['refcheck_tip_away']:.1e} |")
    return "\n".join(lines)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("scenes", nargs="*", help="scene names (default: every sims/*.toml)")
    parser.add_argument("--repeats", type=int, default=3, help="default-settings runs per scene (median wall)")
    args = parser.parse_args()
    names = args.scenes or sorted(p.stem for p in sims_dir().glob("*.toml"))
    rows = []
    for name in names:
        rows.append(bench(name, args.repeats))
        r = rows[-1]
        nan = float("nan")
        print(f"{name}: wall {r['wall_s']:.2f} s (RTF {r['real_time_factor']:.2f}), "
              f"force err {r.get('err_force_away', nan):.2e} N, tip err {r.get('err_tip_away', nan):.2e} m", flush=True)
    print()
    print(table(rows))
    OUT.mkdir(parents=True, exist_ok=True)
    meta = {"machine": platform.platform(), "cpus": os.cpu_count(), "load_average": os.getloadavg(),
            "repeats": args.repeats, "reference": REFERENCE, "check": CHECK, "guard_samples": GUARD}
    (OUT / "scenes.json").write_text(json.dumps({"meta": meta, "scenes": rows}, indent=2))
    keys = [k for k in rows[0] if k != "wall_runs_s"]
    for r in rows[1:]:
        keys += [k for k in r if k not in keys and k != "wall_runs_s"]
    with open(OUT / "scenes.csv", "w", newline="") as fh:
        writer = csv.DictWriter(fh, fieldnames=keys, extrasaction="ignore")
        writer.writeheader()
        writer.writerows(rows)
    print(f"\nwrote {OUT / 'scenes.json'} and {OUT / 'scenes.csv'}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
