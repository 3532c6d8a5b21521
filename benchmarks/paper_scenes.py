"""Each scene in sims/ at its default settings: real-time factor and force error.

    python benchmarks/paper_scenes.py [--repeats 3] [--out benchmarks/out/paper_scenes] [SCENE ...]

Wall time: median of ``--repeats`` runs of :func:`contactdyn.simulate.run_system` on a
built system (integration, events, impacts and the sampled output; reading the scene and
loading the robot excluded, reported as ``build_ms``). Real-time factor = simulated
duration / wall time. Force error: max |F_n − F_n,ref| over the output samples with
t ≥ 0.05 s and every contact, against the same scene at rtol 1e-11 (atol scaled like the
scene's), whose own error is estimated against rtol 5e-12. Writes ``paper_scenes.md``
(the README table) and ``paper_scenes.json``.
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from contactdyn.errors import ContactdynError  # noqa: E402
from contactdyn.scene import load_scene, sims_dir  # noqa: E402
from contactdyn.simulate import run_system  # noqa: E402
from contactdyn.system import System  # noqa: E402
from contactdyn.workprecision import errors  # noqa: E402

REFERENCE_RTOL = 1e-11


def measure(name: str, repeats: int) -> dict:
    t0 = time.perf_counter()
    scene = load_scene(name)
    system = System(scene)
    build_ms = (time.perf_counter() - t0) * 1e3
    walls, cpus = [], []
    for _ in range(repeats):
        w0, c0 = time.perf_counter(), time.process_time()
        res = run_system(system)
        walls.append(time.perf_counter() - w0)
        cpus.append(time.process_time() - c0)
    wall = statistics.median(walls)
    s = res.stats
    row = {"scene": scene.name, "duration_s": scene.duration, "method": s["method"], "rtol": s["rtol"],
           "integrators": s.get("segments_by_method", {}), "wall_s": wall, "cpu_s": statistics.median(cpus),
           "real_time_factor": scene.duration / wall, "build_ms": build_ms, "rhs_evals": s["rhs_evals"],
           "events": s["events"], "compiled_modes": s.get("compiled_modes", 0),
           "fallback": s.get("fallback_modes", {})}
    ratio = scene.solver.atol / scene.solver.rtol
    refs = []
    for r in (REFERENCE_RTOL, REFERENCE_RTOL / 2):
        try:
            refs.append(run_system(System(load_scene(name, {"solver.rtol": r, "solver.atol": r * ratio}))))
        except ContactdynError as exc:
            row["reference_status"] = str(exc)
            return row
    try:
        row["force_error_N"], row["position_error_m"] = errors(res, refs[0])
        row["reference_error_N"], _ = errors(refs[0], refs[1])
    except ContactdynError as exc:
        row["reference_status"] = str(exc)
    return row


def markdown(rows: list[dict]) -> str:
    lines = ["| scene | duration [s] | integrator, rtol | wall [s] | real-time factor | rhs evals | events | "
             "F_n error [N] | reference's own [N] | right-hand side |",
             "|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        integ = ", ".join(f"{k}×{v}" if v > 1 else k for k, v in r["integrators"].items())
        path = "compiled" if not r["fallback"] else "System.evaluate (" + "; ".join(r["fallback"]) + ")"
        lines.append(f"| {r['scene']} | {r['duration_s']:g} | {integ}, {r['rtol']:g} | {r['wall_s']:.3f} | "
                     f"{r['real_time_factor']:.1f} | {r['rhs_evals']} | {r['events']} | "
                     f"{r.get('force_error_N', float('nan')):.1e} | {r.get('reference_error_N', float('nan')):.0e} | "
                     f"{path} |")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("scenes", nargs="*", default=sorted(f.stem for f in sims_dir().glob("*.toml")))
    p.add_argument("--repeats", type=int, default=3)
    p.add_argument("--out", default=str(Path(__file__).resolve().parent / "out" / "paper_scenes"))
    args = p.parse_args(argv)
    rows = []
    for name in args.scenes:
        rows.append(measure(name, args.repeats))
        print(json.dumps(rows[-1], default=str), flush=True)
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.with_suffix(".json").write_text(json.dumps(rows, indent=1, default=str))
    out.with_suffix(".md").write_text(markdown(rows) + "\n")
    print(markdown(rows))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
