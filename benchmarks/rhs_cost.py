"""Cost of one right-hand-side evaluation (what the integrator calls): the compiled call, and with its diagnostics.

    python benchmarks/rhs_cost.py [SCENE[@T] ...] [--calls 20000] [--out FILE.csv]
    python benchmarks/rhs_cost.py SCENE[@T] ... --baseline TREE [--repeats 5] [--out FILE.csv]

Default scene: b1 (2 DOF + one deformable frictional contact: a bonded model-(b) surface
mass and sliding Coulomb friction), the budget case (≤ 10 µs median). Each scene is
built, its initial modes made consistent, and the integrator's function called on the
states of a short run (so the timing covers real states, not one cached point): the one
pipeline's compiled call as the loop wraps it (:class:`~contactdyn.hybrid.pipeline_mode.PipelineMode`'s
``rhs``, from :func:`~contactdyn.hybrid.pipeline_mode.mode_runner`; a mode the pipeline does not pack stops it).
Reports the median and the 10th/90th percentiles over batches of calls, wall and CPU time, and
the cost of the model at an instant with all its diagnostics (``PipelineMode.evaluation``: one call with the
diagnostics on, an Evaluation; it took the readable ``System.evaluate`` once) for comparison.

``SCENE@T``: the mode the run is in at time T [s] (e.g. ``case3_a_position@2`` for the
press after the approach) instead of the first. ``--baseline TREE``: before/after, the
measurement run alternately in child processes importing ``contactdyn`` from TREE (e.g. an
export of ``main``; :mod:`before_after`) and from this tree, ``--repeats`` times each; medians and their ratio.
"""

from __future__ import annotations

import argparse
import importlib
import json
import statistics
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from before_after import HERE, alternate, use_tree  # noqa: E402

use_tree()

import numpy as np  # noqa: E402

from contactdyn.hybrid.pipeline_mode import mode_runner  # noqa: E402
from contactdyn.scene.scene_file import Scene, load_scene  # noqa: E402

BATCHES = 41  #: batches per measurement (median over batches)


def _batches(fn, states, calls: int, clock) -> list[float]:
    per_batch = max(calls // BATCHES, 1)
    out = []
    n = len(states)
    for b in range(BATCHES):
        t, x = states[b % n]
        t0 = clock()
        for _ in range(per_batch):
            fn(t, x)
        out.append((clock() - t0) / per_batch)
    return out


def _mode_at(scene: Scene, at: float | None, package: str = "contactdyn"):
    """(system, modes, phase, t, x) of the mode the run is in at time ``at`` (None: the first, at its start), by
    ``package`` (another tree's imported under another name: benchmarks/call_cycles.py's baseline)."""
    def of(module: str):
        return importlib.import_module(f"{package}.{module}")

    if at is None:
        system, modes, phase, x0 = of("simulate").prepare(scene)
        return system, modes, phase, phase.t_start, x0
    system = of("model.system").System(of("scene.scene_file").load_scene(scene.file, {"duration": at})
                                       if scene.file else scene)
    run = of("hybrid.loop").HybridRun(system)
    run.run(time.perf_counter())
    seg = max((s for s in run.segments if s.t1 > s.t0), key=lambda s: s.t1)  # the last segment of nonzero length
    return system, list(seg.modes), seg.phase, seg.t1, np.array(seg.sol(seg.t1), dtype=float)


def measure(scene: str | Scene, calls: int = 20000, at: float | None = None) -> dict:
    """Median cost [µs] of one rhs call and of one full evaluation on a scene's mode at time ``at``
    (None: its first mode; ``scene``: a name or a Scene)."""
    scene = load_scene(scene) if isinstance(scene, str) else scene
    scene_name = scene.name if at is None else f"{scene.name}@{at:g}"
    system, modes, phase, t0, x0 = _mode_at(scene, at)
    mode = mode_runner(system)(modes, phase)
    f, evaluation = mode.rhs, mode.evaluation
    # states along a short stretch of the real trajectory (this mode's physics only)
    from scipy.integrate import solve_ivp

    sol = solve_ivp(f, (t0, t0 + 0.01), x0, method="DOP853", rtol=1e-8, atol=1e-10)
    states = [(float(t), sol.y[:, i].copy()) for i, t in enumerate(sol.t)]
    for t, x in states[:50]:  # the lean path must agree with the full evaluation
        ref = evaluation(t, x).xdot
        if not np.allclose(f(t, x), ref, rtol=1e-10, atol=1e-10 * (1 + np.abs(ref).max())):
            raise SystemExit(f"{scene_name}: rhs disagrees with the full evaluation at t = {t}")
    wall = _batches(f, states, calls, time.perf_counter)
    cpu = _batches(f, states, calls, time.process_time)
    full = _batches(evaluation, states, max(calls // 10, BATCHES), time.perf_counter)
    full_cpu = _batches(evaluation, states, max(calls // 10, BATCHES), time.process_time)
    q = statistics.quantiles(wall, n=10)
    path = f"compiled ({mode.reason})" if mode.reason else "compiled"  # (its Python stages, if any)
    return {"scene": scene_name, "n_states": system.n, "path": path,
            "rhs_median_us": statistics.median(wall) * 1e6,
            "rhs_p10_us": q[0] * 1e6, "rhs_p90_us": q[-1] * 1e6, "rhs_cpu_median_us": statistics.median(cpu) * 1e6,
            "evaluation_median_us": statistics.median(full) * 1e6,
            "evaluation_cpu_median_us": statistics.median(full_cpu) * 1e6,
            "rhs_cpu_min_us": min(cpu) * 1e6, "evaluation_cpu_min_us": min(full_cpu) * 1e6}


def _scene_at(arg: str) -> tuple[str, float | None]:
    name, _, at = arg.partition("@")
    return name, float(at) if at else None


def compare(scenes: list[str], calls: int, baseline: str, repeats: int) -> list[dict]:
    """Before/after: each repeat measures every scene in a child importing TREE, then one importing this tree."""
    got = alternate(__file__, [*scenes, "--calls", str(calls)], {"baseline": baseline, "this": str(HERE)}, repeats)
    rows = []
    for i, first in enumerate(got["this"][0]):
        before = statistics.median(run[i]["rhs_cpu_median_us"] for run in got["baseline"])
        after = statistics.median(run[i]["rhs_cpu_median_us"] for run in got["this"])
        rows.append({"scene": first["scene"], "baseline_cpu_us": before, "this_cpu_us": after, "ratio": before / after,
                     "repeats": repeats})
    return rows


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("scenes", nargs="*", default=["b1"])
    p.add_argument("--calls", type=int, default=20000)
    p.add_argument("--out", help="CSV file to write")
    p.add_argument("--baseline", help="source tree to compare against (before/after)")
    p.add_argument("--repeats", type=int, default=5)
    p.add_argument("--json", action="store_true", help=argparse.SUPPRESS)  # a child's output
    args = p.parse_args(argv)
    if args.baseline:
        rows = compare(args.scenes, args.calls, args.baseline, args.repeats)
    else:
        rows = [measure(name, args.calls, at) for name, at in map(_scene_at, args.scenes)]
    if args.json:
        print(json.dumps(rows))
        return 0
    cols = list(rows[0])
    print(" | ".join(cols))
    for r in rows:
        print(" | ".join(f"{r[c]:.2f}" if isinstance(r[c], float) else str(r[c]) for c in cols))
    if args.out:
        Path(args.out).parent.mkdir(parents=True, exist_ok=True)
        with open(args.out, "w") as fh:
            fh.write(",".join(cols) + "\n")
            for r in rows:
                fh.write(",".join(str(r[c]) for c in cols) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
