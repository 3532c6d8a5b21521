"""How much of a run its compiled calls take: what a run would cost with no Python around them at all.

    PYTHONPATH=. python3 benchmarks/compiled_share.py [--repeats 5] [--rate 1000]

Issues 29 (item 3: the real cell within 2.4x the hand-written B1 floor per simulated second) and 31 (item 5: a
controller sampled at 1 kHz within 2x its continuous run) ask for bounds that the Python around the compiled calls
(the hybrid loop's samples, events, segments and output) keeps out of reach. This script measures how far a run
would get without that Python: the CPU spent inside the package's compiled entry points (a DOP853 step attempt,
the one call, the output samples' and interpolants' batches, a sampled law's stage: each timed around its call,
its dispatch included) against the whole run's CPU.

Runs, interleaved (``timing.interleaved``), CPU medians over ``--repeats``:

- ``b1`` continuous, and ``b1`` with ``controller.sample_rate`` = ``--rate``;
- ``force_loop_real_cell`` as it is (500 Hz, 2 samples of delay), and the hand-written closed-form B1
  (``b1_reference.run``, 2 s: issue 29's floor, as ``scene_cost.py`` times it).

Per run: CPU [s], the compiled calls' CPU [s] and share, and per simulated second [ms/s]. Then the two bounds,
each as it is and with the compiled calls alone (the run's Python taken as zero): the sampled b1 over the
continuous b1's whole run, and the real cell per simulated second over the floor's. Writes
benchmarks/out/compiled_share.json.
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

import b1_reference  # noqa: E402
from timing import interleaved, write_report  # noqa: E402

import contactdyn.hybrid.pipeline_mode as pipeline_mode  # noqa: E402
import contactdyn.hybrid.sampled_law as sampled_law  # noqa: E402
import contactdyn.hybrid.steps as steps  # noqa: E402
import contactdyn.model.pipeline.pipeline as pipeline  # noqa: E402
from contactdyn import load_scene, simulate  # noqa: E402

OUT = Path(__file__).parent / "out" / "compiled_share.json"
#: (module, name) of each compiled entry point the hybrid loop calls from Python
ENTRY_POINTS = ((steps, "attempt"), (steps, "interpolant"), (steps, "rates_at"), (pipeline_mode, "call"),
                (pipeline_mode, "samples_at"), (pipeline, "call"), (sampled_law, "law_at"))
_INSIDE = [0.0]  #: [s] CPU inside the entry points since the last reset


class _Timed:
    """A compiled function timed around each call (its other attributes its own: ``compile``, ``signatures``)."""

    def __init__(self, function):
        self.function = function

    def __call__(self, *args):
        c0 = time.process_time()
        try:
            return self.function(*args)
        finally:
            _INSIDE[0] += time.process_time() - c0

    def __getattr__(self, name):
        return getattr(self.function, name)


def _timed_entry_points() -> None:
    for module, name in ENTRY_POINTS:
        setattr(module, name, _Timed(getattr(module, name)))


def _run(scene: str, overrides: dict):
    def run():
        _INSIDE[0] = 0.0
        result = simulate(scene, overrides)
        return result, _INSIDE[0]
    return run


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--rate", type=float, default=1000.0, help="[Hz] b1's sample rate")
    args = ap.parse_args()
    _timed_entry_points()
    variants = {"b1": _run("b1", {}), "b1 sampled": _run("b1", {"controller.sample_rate": args.rate}),
                "real cell": _run("force_loop_real_cell", {}), "hand-written B1": lambda: (b1_reference.run(), 0.0)}
    for run in variants.values():
        run()  # (compiled and cached first)
    inside = {key: [] for key in variants}
    wrapped = {key: (lambda run=run, key=key: inside[key].append(run()[1])) for key, run in variants.items()}
    times = interleaved(wrapped, args.repeats)
    duration = {"b1": load_scene("b1").duration, "real cell": load_scene("force_loop_real_cell").duration,
                "hand-written B1": b1_reference.T_END}  # [s] simulated
    duration["b1 sampled"] = duration["b1"]
    rows = []
    print(f"{'run':16s} {'CPU [s]':>8s} {'compiled [s]':>12s} {'share':>6s} {'ms/s':>7s} {'compiled ms/s':>13s}")
    for key in variants:
        cpu, compiled = times[key].cpu, statistics.median(inside[key])
        rows.append({"run": key, "cpu_s": cpu, "compiled_s": compiled, "share": compiled / cpu,
                     "ms_per_s": 1e3 * cpu / duration[key], "compiled_ms_per_s": 1e3 * compiled / duration[key]})
        r = rows[-1]
        print(f"{key:16s} {cpu:8.3f} {compiled:12.3f} {r['share']:6.2f} {r['ms_per_s']:7.1f} "
              f"{r['compiled_ms_per_s']:13.1f}")
    by = {r["run"]: r for r in rows}
    bounds = {"sampled_over_continuous": by["b1 sampled"]["cpu_s"] / by["b1"]["cpu_s"],
              "sampled_compiled_only_over_continuous": by["b1 sampled"]["compiled_s"] / by["b1"]["cpu_s"],
              "real_cell_over_floor": by["real cell"]["ms_per_s"] / by["hand-written B1"]["ms_per_s"],
              "real_cell_compiled_only_over_floor": by["real cell"]["compiled_ms_per_s"]
              / by["hand-written B1"]["ms_per_s"]}
    print(f"b1 sampled at {args.rate:g} Hz over b1 continuous: {bounds['sampled_over_continuous']:.2f}x as it is, "
          f"{bounds['sampled_compiled_only_over_continuous']:.2f}x with its compiled calls alone (issue 31.5: <= 2)")
    print(f"real cell over the hand-written B1 floor per simulated second: {bounds['real_cell_over_floor']:.2f}x as "
          f"it is, {bounds['real_cell_compiled_only_over_floor']:.2f}x with its compiled calls alone (issue 29.3: "
          "<= 2.4)")
    write_report(OUT, {"repeats": args.repeats, "rate_hz": args.rate, "bounds": bounds}, rows)


if __name__ == "__main__":
    main()
