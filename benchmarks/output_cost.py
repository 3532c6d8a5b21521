"""Cost of a run's output per sample: the compiled call's batched output against one compiled call per sample.

    PYTHONPATH=. python3 benchmarks/output_cost.py [SCENE ...] [--repeats 5] [--out FILE.json]

Per scene, one run records its segments; then, interleaved per repeat in one process, the
output pass (:func:`~contactdyn.output.channels.sample_segments`) over those segments twice: with
the one pipeline's batched output (:meth:`~contactdyn.hybrid.pipeline_mode.PipelineMode.samples`, as
the run does) and with every sample from its own call (the same ``PipelineMode.samples`` on one row at a
time: what the output costs without the batching; the states are interpolated alike in both). CPU µs per
sample, medians over the repeats, their ratio, the largest relative difference of the channels between the two,
and the share of the run's CPU time the output takes. The hand-written B1 (:mod:`b1_reference`) runs in the same
loop so the per-sample cost can be read against its cost per simulated second.
"""

from __future__ import annotations

import argparse
import sys
import time
from functools import partial
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from before_after import use_tree  # noqa: E402
from scene_cost import report  # noqa: E402
from timing import interleaved  # noqa: E402

use_tree()

import b1_reference  # noqa: E402
import numpy as np  # noqa: E402

import contactdyn.hybrid.loop as hybrid  # noqa: E402
from contactdyn import simulate  # noqa: E402
from contactdyn.hybrid.pipeline_mode import PipelineMode  # noqa: E402
from contactdyn.output.channels import sample_segments  # noqa: E402
from contactdyn.output.samples import Samples  # noqa: E402
from contactdyn.scene.scene_file import load_scene  # noqa: E402

SCENES = ["case1_cart", "case2_writer_motors", "case3_a_position", "case3_a_force", "case3_b_position",
          "case3_b_force", "b1"]


_BATCHED = PipelineMode.samples  #: the pipeline's batched output (the run's)


def _per_sample(mode, ts, X, modes=None, runs=None):
    """PipelineMode.samples' stand-in: every sample from its own compiled call (``runs``: one at a time here)."""
    if modes is not None:
        mode.use(modes)
    return Samples.concatenate([_BATCHED(mode, ts[k:k + 1], X[k:k + 1]) for k in range(len(ts))], mode.system)


def recorded_run(name: str):
    """(result, its CPU time [s], system, segments, output grid) of one run of the scene."""
    seen = {}
    original = hybrid.sample_states

    def record(system, segments, grid, stats):
        seen.update(system=system, segments=segments, grid=grid)
        return original(system, segments, grid, stats)

    hybrid.sample_states = record
    try:
        t0 = time.process_time()
        result = simulate(load_scene(name))
        run_s = time.process_time() - t0
    finally:
        hybrid.sample_states = original
    return result, run_s, seen["system"], seen["segments"], seen["grid"]


def _output(system, segments, grid, per_sample: bool) -> dict:
    """The channels of the output pass, batched or one call per sample."""
    if per_sample:
        PipelineMode.samples = _per_sample
    try:
        return sample_segments(system, segments, grid, {"singular_solves": 0})
    finally:
        PipelineMode.samples = _BATCHED


def _difference(a: dict, b: dict) -> float:
    """Largest relative difference over the channels (NaN equal to NaN)."""
    worst = 0.0
    for key, ref in b.items():
        ref, got = np.asarray(ref, float), np.asarray(a[key], float)
        scale = max(float(np.nanmax(np.abs(ref))) if np.any(np.isfinite(ref)) else 0.0, 1e-300)
        worst = max(worst, float(np.nanmax(np.abs(got - ref), initial=0.0)) / scale)
    return worst


def measure(scenes: list[str], repeats: int) -> list[dict]:
    rows = []
    for name in scenes:
        result, run_s, system, segments, grid = recorded_run(name)
        n = len(grid)
        times = interleaved({"hand": b1_reference.run,
                             "batched": partial(_output, system, segments, grid, per_sample=False),
                             "per_sample": partial(_output, system, segments, grid, per_sample=True)}, repeats)
        f, s = times["batched"].cpu / n * 1e6, times["per_sample"].cpu / n * 1e6
        rows.append({"scene": name, "samples": n, "batched_us": f, "per_sample_us": s, "speedup": s / f,
                     "max_rel_diff": _difference(times["batched"].last, times["per_sample"].last),
                     "output_share_of_run": f * n * 1e-6 / run_s,
                     "batched_ms_per_s": f * n * 1e-3 / float(result.t[-1]),
                     "hand_written_ms_per_s": times["hand"].cpu / b1_reference.T_END * 1e3})
    return rows


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("scenes", nargs="*", default=SCENES)
    p.add_argument("--repeats", type=int, default=5)
    p.add_argument("--out", help="JSON file to write")
    args = p.parse_args(argv)
    report(measure(args.scenes, args.repeats), args.out)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
