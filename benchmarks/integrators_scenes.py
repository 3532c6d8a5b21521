"""Every scene in sims/ on solve_ivp's DOP853 and on the compiled DOP853C: wall time at equal settings, errors.

    PYTHONPATH=. python3 benchmarks/integrators_scenes.py [--repeats 3] [--methods DOP853,DOP853C] [scene ...]

Each scene runs at its own settings with only ``solver.method`` changed; the methods are
interleaved repeat by repeat; cost = the median process CPU time around ``simulate`` (loading
and output included; CPU rather than wall time because the shared machine's load reached 7 on
2 cores; wall times are in the JSON). Errors against the reference of ``benchmarks/scenes.py`` (the scene
by solve_ivp's DOP853 at rtol 1e-11), measured as there (force [N] and tip [m], away from
±2 samples of every event). Writes benchmarks/out/integrators_scenes.json and .csv.
"""

from __future__ import annotations

import argparse
import csv
import json
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

import scenes  # noqa: E402
from timing import interleaved  # noqa: E402

from contactdyn import simulate  # noqa: E402
from contactdyn.scene.scene_file import load_scene, sims_dir  # noqa: E402

OUT = Path(__file__).parent / "out"


def compare(name: str, methods: list[str], repeats: int) -> dict:
    scene = load_scene(name)
    times = interleaved({m: lambda m=m: simulate(name, {"solver.method": m}) for m in methods}, repeats)
    ref = simulate(name, scenes.REFERENCE)
    row: dict = {"scene": name, "duration_s": scene.duration, "rtol": scene.solver.rtol}
    for m in methods:
        r, cpu = times[m].last, times[m].cpu
        err = scenes.errors(r, ref)
        row[m] = {"wall_s": times[m].wall, "cpu_s": cpu, "ms_per_simulated_s": cpu / scene.duration * 1e3,
                  "steps": r.stats["steps"], "rhs_evals": r.stats["rhs_evals"],
                  "events": len(r.events), "force_err": err["force_away"], "tip_err": err["tip_away"]}
    return row


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("scenes", nargs="*")
    p.add_argument("--repeats", type=int, default=3)
    p.add_argument("--methods", default="DOP853,DOP853C")
    args = p.parse_args(argv)
    methods = args.methods.split(",")
    names = args.scenes or sorted(q.stem for q in sims_dir().glob("*.toml"))
    head = "| scene | " + " | ".join(f"{m} CPU ms/sim-s | {m} steps | {m} force err [N] | {m} tip err [m]"
                                      for m in methods) + f" | {methods[0]} / {methods[-1]} |"
    lines = [head, "|" + "---|" * (head.count("|") - 1)]
    rows = []
    for name in names:
        r = compare(name, methods, args.repeats)
        rows.append(r)
        cells = " | ".join(f"{r[m]['ms_per_simulated_s']:.0f} | {r[m]['steps']} | {r[m]['force_err']:.1e} | "
                           f"{r[m]['tip_err']:.1e}" for m in methods)
        lines.append(f"| {name} | {cells} | {r[methods[0]]['cpu_s'] / r[methods[-1]]['cpu_s']:.2f} |")
        print(lines[-1], flush=True)
    print("\n".join(lines))
    OUT.mkdir(parents=True, exist_ok=True)
    (OUT / "integrators_scenes.json").write_text(json.dumps({"repeats": args.repeats, "rows": rows}, indent=1))
    with open(OUT / "integrators_scenes.csv", "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["scene", "method", "ms_per_simulated_s", "steps", "rhs_evals", "force_err", "tip_err"])
        for r in rows:
            for m in methods:
                d = r[m]
                w.writerow([r["scene"], m, d["ms_per_simulated_s"], d["steps"], d["rhs_evals"], d["force_err"],
                            d["tip_err"]])
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
