"""Benchmark B1 ("press and slide", /work/shared/bench/B1.md) at contactdyn's default settings.

    python benchmarks/b1.py --out benchmarks/out/b1.json [--repeats 5] [--set solver.rtol=1e-6]

Writes one JSON object: ``wall_s`` (wall time of the whole simulation,
``contactdyn.simulate(scene)``: building the system — loading the robot — integrating 2 s
with its events and sampling the 1 kHz output; median of ``--repeats``), ``rhs_evals``,
and the 1 kHz arrays ``t``, ``x_tip``, ``F_n`` (2001 samples each); besides those, the
settings, ``steps``, ``wall_runs_s`` (every repeat), ``cpu_s`` (median process CPU time),
``run_s`` (median of ``run_system`` on a built system: without loading the robot, as
``contactdyn bench`` times), and the errors against the hand-written closed-form model of
``b1_reference.py`` at rtol 1e-13 (``F_n_error`` [N] over t ∈ [0.05, 2] s,
``x_tip_error`` [m] over all samples).
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

import b1_reference  # noqa: E402

from contactdyn.model.system import System  # noqa: E402
from contactdyn.scene.scene_file import load_scene, parse_override  # noqa: E402
from contactdyn.simulate import run_system, simulate  # noqa: E402


def run_b1(overrides: dict | None = None, repeats: int = 5) -> dict:
    """Run B1 ``repeats`` times; channels from the last run, wall time the median."""
    scene = load_scene("b1", overrides)
    walls, cpus, runs = [], [], []
    result = None
    for _ in range(repeats):
        t0, c0 = time.perf_counter(), time.process_time()
        result = simulate(scene)
        walls.append(time.perf_counter() - t0)
        cpus.append(time.process_time() - c0)
    system = System(scene)
    for _ in range(repeats):
        t0 = time.perf_counter()
        run_system(system)
        runs.append(time.perf_counter() - t0)
    assert result is not None
    s = result.stats
    return {
        "wall_s": statistics.median(walls),
        "wall_runs_s": walls,
        "cpu_s": statistics.median(cpus),
        "run_s": statistics.median(runs),
        "rhs_evals": int(s["rhs_evals"]),
        "steps": int(s["steps"]),
        "method": s["method"],
        "rtol": s["rtol"],
        "atol": s["atol"],
        "t": result.t.tolist(),
        "x_tip": result["tip"][:, 0].tolist(),
        "F_n": result["contact.tip.F_n"].tolist(),
    }


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--out", required=True, help="JSON file to write")
    p.add_argument("--repeats", type=int, default=5)
    p.add_argument("--set", action="append", default=[], metavar="KEY=VALUE", help="override a scene key")
    args = p.parse_args(argv)
    out = run_b1(dict(parse_override(s) for s in args.set), args.repeats)
    import numpy as np

    ref = b1_reference.reference()
    e_f, e_x = b1_reference.errors({k: np.asarray(out[k]) for k in ("F_n", "x_tip")}, ref)
    out["F_n_error"], out["x_tip_error"] = e_f, e_x
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    Path(args.out).write_text(json.dumps(out))
    print(f"B1 {out['method']} rtol={out['rtol']:g} atol={out['atol']:g}: wall {out['wall_s'] * 1e3:.1f} ms "
          f"(median of {args.repeats}; {out['run_s'] * 1e3:.1f} ms without loading the robot), "
          f"{out['rhs_evals']} rhs evals, {out['steps']} steps, "
          f"F_n error {e_f:.2e} N, x_tip error {e_x:.2e} m -> {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
