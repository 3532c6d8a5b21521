"""Motor scenes on the compiled path against the same call interpreted, timed in the same process.

    PYTHONPATH=. python3 benchmarks/motor_fastpath.py [--repeats 3] [--error] [scene ...]

For each scene with DC motors or elastic transmissions: the run as it is (every mode the one
pipeline packs on its compiled call) and the same run with ``LivePipelines.use = False`` (every mode on
the same call interpreted, its Python twins: :mod:`contactdyn.numerics.twins`), interleaved after an untimed run
of each, ``--repeats`` times each; the median walls [s] and their ratio.
With ``--error``: both default runs' force error max |F_n − F_n,ref| [N] against a compiled
reference at rtol 1e-11, atol 1e-13, away from ±2 samples of every event (the two paths
run the same functions, so the errors should agree). Writes benchmarks/out/motor_fastpath.json.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

import numpy as np  # noqa: E402
from timing import interleaved, write_report  # noqa: E402

from contactdyn.model.contact import structure  # noqa: E402
from contactdyn.model.paths import LivePipelines  # noqa: E402
from contactdyn.model.pipeline.pipeline import Pipeline  # noqa: E402
from contactdyn.model.system import System  # noqa: E402
from contactdyn.numerics.twins import Twins  # noqa: E402
from contactdyn.scene.scene_file import load_scene  # noqa: E402
from contactdyn.simulate import run_system  # noqa: E402

SCENES = ["case1_cart", "case2_writer_motors", "case3_a_position", "case3_a_force", "case3_b_position",
          "case3_b_force", "case3_b_force_varied"]
OUT = Path(__file__).resolve().parent / "out" / "motor_fastpath.json"


def run(scene: str, interpreted: bool, overrides: dict | None = None, interpret=None):
    """Build the scene's system and run it; the Result. ``interpreted``: every mode on the same call interpreted
    (``LivePipelines.use`` off), or with ``interpret`` (a predicate of (modes, phase)) only the modes it matches
    (their pipelines given twins, the path "interpreted call" in ``stats["paths"]``); both restored after."""
    system = System(load_scene(scene, overrides or {}))
    if not interpreted:
        return run_system(system)
    compiled_mode = LivePipelines.mode
    if interpret is None:
        LivePipelines.use = False
    else:
        twins = Twins()

        def mode(pipes, modes, phase):
            if not interpret(modes, phase):
                return compiled_mode(pipes, modes, phase)
            key = ("interpreted", structure(modes), phase.key())
            pipe = pipes.pipes.get(key)
            if pipe is None:
                pipe = pipes.pipes[key] = pipes.wrap(Pipeline(pipes.system, modes, phase, twins))
            pipe.use(modes)
            return pipe

        LivePipelines.mode = mode
    try:
        return run_system(system)
    finally:
        LivePipelines.use, LivePipelines.mode = True, compiled_mode


def force_error(result, ref) -> float:
    """max |F_n − F_n,ref| over the contacts [N] on the common output grid, away from ±2 samples of
    every event of either run (a mode switch at a slightly different time is a jump, not an error)."""
    t = ref.t
    keep = np.ones(len(t), bool)
    dt = t[1] - t[0]
    for ev in list(result.events) + list(ref.events):
        keep &= np.abs(t - ev["t"]) > 2.5 * dt
    keys = [k for k in ref.channels if k.endswith(".F_n")]
    return max(float(np.max(np.abs(result[k] - ref[k])[keep])) for k in keys)


def measure(scene: str, repeats: int, error: bool) -> dict:
    variants = {interpreted: lambda interpreted=interpreted: run(scene, interpreted) for interpreted in (False, True)}
    for call in variants.values():
        call()  # untimed: numba's compile (or cache load) of the pipeline for this scene's laws
    times = interleaved(variants, repeats)
    results = {interpreted: t.last for interpreted, t in times.items()}
    row = {"scene": scene, "compiled_s": times[False].wall, "interpreted_s": times[True].wall,
           "compiled_modes": results[False].stats["compiled_modes"]}
    row["speedup"] = row["interpreted_s"] / row["compiled_s"]
    if error:
        ref = run(scene, False, {"solver.rtol": 1e-11, "solver.atol": 1e-13})
        row["F_err_compiled"] = force_error(results[False], ref)
        row["F_err_interpreted"] = force_error(results[True], ref)
    return row


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("scenes", nargs="*", default=SCENES)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--error", action="store_true")
    args = ap.parse_args(argv)
    rows = []
    print(f"{'scene':24s} {'compiled [s]':>12s} {'interpreted [s]':>15s} {'speed-up':>9s}  "
          "F err compiled / interpreted [N]")
    for scene in args.scenes:
        row = measure(scene, args.repeats, args.error)
        rows.append(row)
        err = f"  {row['F_err_compiled']:.3g} / {row['F_err_interpreted']:.3g}" if args.error else ""
        print(f"{scene:24s} {row['compiled_s']:12.3f} {row['interpreted_s']:15.3f} {row['speedup']:8.2f}x{err}"
              f"   (compiled modes {row['compiled_modes']})")
    write_report(OUT, {"repeats": args.repeats, "error": args.error}, rows)
    return 0


if __name__ == "__main__":
    sys.exit(main())
