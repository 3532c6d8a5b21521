"""Every scene with dry friction on every joint: does it run to its end, with clean physics checks?

    PYTHONPATH=. python3 benchmarks/joint_friction_variants.py [--jobs 1] [--variants NAME ...] [scene ...]

Each scene of ``sims/`` and ``benchmarks/hard/`` (or those named) runs, at its own settings otherwise, under
:data:`VARIANTS`: ``f0.5``, 0.5 N·m (or N) of dry friction on every joint (static = kinetic); ``f2/1@500``, 2 static
and 1 kinetic on every joint with the controller sampled at 500 Hz; ``f1.5/0.5``, 1.5 static and 0.5 kinetic,
continuous (light wrist joints that stick and slip as a touch's impact moves them: contactdyn.model.joint_friction's
"Impacts"); ``f0.05`` and ``f4``, the extremes (0.05 and 4 N·m or N, static = kinetic): where holds sit near their
limits for long and redundant holds are near-singular, the false alarms and storms this table keeps visible;
``f0.2``, ``f1`` and ``f2.5`` between them (static = kinetic: a sweep of these found the UR5 writer's storm at its
run's last instant, hybrid.loop's ``min_span`` end). These
are conditions the scenes were not written for: a contact and joints at rest together, redundant holds (every joint of
an arm stuck while its tool sticks: split by the holds' limits, contactdyn.model.pipeline.kkt.coulomb_split),
stick-slip of light wrist joints. Per run: ``ok`` (it reached its end), or the first line of its error; the steps,
events, ``decided_together`` (contacts and joints decided together at rest: contactdyn.hybrid.at_rest),
``singular_solves`` (calls whose holds were redundant), the number of physics-check warnings, and the wall time [s].
A scene whose own joint table already sets ``friction`` cannot take ``friction_static``: "not applicable".

Writes benchmarks/out/joint_friction_variants.json and .csv; with scenes or variants named,
joint_friction_variants_some.json and .csv (the committed table stays the whole set's).
"""

from __future__ import annotations

import argparse
import csv
import json
import sys
import time
import warnings
from multiprocessing import Pool
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from contactdyn import simulate  # noqa: E402
from contactdyn.errors import SceneError  # noqa: E402

OUT = Path(__file__).parent / "out"
VARIANTS = {
    "f0.5": lambda joints: {f"robot.joint.{j}.friction": 0.5 for j in joints},
    "f2/1@500": lambda joints: {**{f"robot.joint.{j}.friction_static": 2.0 for j in joints},
                                **{f"robot.joint.{j}.friction_kinetic": 1.0 for j in joints},
                                "controller.sample_rate": 500.0},
    "f1.5/0.5": lambda joints: {**{f"robot.joint.{j}.friction_static": 1.5 for j in joints},
                                **{f"robot.joint.{j}.friction_kinetic": 0.5 for j in joints}},
    "f0.05": lambda joints: {f"robot.joint.{j}.friction": 0.05 for j in joints},
    "f4": lambda joints: {f"robot.joint.{j}.friction": 4.0 for j in joints},
    **{f"f{tau:g}": (lambda joints, tau=tau: {f"robot.joint.{j}.friction": tau for j in joints})
       for tau in (0.2, 1.0, 2.5)},
}


def scenes() -> list[str]:
    """The scene files of sims/ and benchmarks/hard/, relative to the checkout."""
    files = sorted((ROOT / "sims").glob("*.toml")) + sorted((ROOT / "benchmarks" / "hard").glob("*.toml"))
    return [str(f.relative_to(ROOT)) for f in files]


def one(job: tuple[str, str]) -> dict:
    """One scene under one variant: its row."""
    scene, variant = job
    warnings.simplefilter("ignore")
    row = {"scene": Path(scene).stem, "variant": variant, "outcome": "", "steps": None, "events": None,
           "decided_together": None, "singular_solves": None, "check_warnings": None, "wall_s": None}
    path = str(ROOT / scene)
    start = time.perf_counter()
    try:
        joints = simulate(path, {"duration": 1e-3}).meta["joints"]
        r = simulate(path, VARIANTS[variant](joints))
    except SceneError as exc:
        row["outcome"] = "not applicable: " + str(exc).splitlines()[0][:200]
        return row
    except Exception as exc:  # noqa: BLE001 (a run's failure is its row)
        row["outcome"] = f"{type(exc).__name__}: " + str(exc).splitlines()[0][:200]
        row["wall_s"] = round(time.perf_counter() - start, 2)
        return row
    row.update(outcome="ok", steps=r.stats["steps"], events=len(r.events),
               decided_together=r.stats.get("decided_together"), singular_solves=r.stats["singular_solves"],
               check_warnings=len(r.meta["check_warnings"]), wall_s=round(time.perf_counter() - start, 2))
    return row


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("scenes", nargs="*", help="scene files (default: sims/ and benchmarks/hard/)")
    ap.add_argument("--jobs", type=int, default=1)
    ap.add_argument("--variants", nargs="+", choices=list(VARIANTS), default=list(VARIANTS))
    args = ap.parse_args()
    jobs = [(s, v) for s in (args.scenes or scenes()) for v in args.variants]
    rows = []
    with Pool(args.jobs, maxtasksperchild=1) as pool:
        for row in pool.imap(one, jobs):
            rows.append(row)
            print(f"{row['scene']:26s} {row['variant']:9s} {row['outcome'][:70]:70s} steps {row['steps']} events "
                  f"{row['events']} together {row['decided_together']} singular {row['singular_solves']} "
                  f"checks {row['check_warnings']} {row['wall_s']} s", flush=True)
    ran = [r for r in rows if not r["outcome"].startswith("not applicable")]
    clean = sum(r["outcome"] == "ok" and r["check_warnings"] == 0 for r in ran)
    print(f"{clean} of {len(ran)} runs reached their end with clean checks")
    OUT.mkdir(exist_ok=True)
    whole = not args.scenes and args.variants == list(VARIANTS)
    stem = "joint_friction_variants" if whole else "joint_friction_variants_some"
    (OUT / f"{stem}.json").write_text(json.dumps(rows, indent=1))
    with open(OUT / f"{stem}.csv", "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)


if __name__ == "__main__":
    main()
