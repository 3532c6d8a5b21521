"""Whole runs' cost per simulated second against the hand-written B1 floor, in one process; optionally against the
same runs interpreted for agreement.

    PYTHONPATH=. python3 benchmarks/pipeline_loop.py [SCENE ...] [--repeats 3] [--interpreted] [--set KEY=VALUE ...]
        [--out FILE.json]

Per scene (:data:`SCENES`: every scene of ``sims/``, ``benchmarks/hard/``, ``examples/`` and ``benchmarks/b2.toml``,
at its own duration and settings; ``--set`` overrides a key in every one, e.g. ``solver.rtol=1e-11``): the CPU median
of a whole run as it is (System built, run, output sampled; the scene file read once before: every mode on the one
pipeline's compiled call, its compiled steps, event values and output samples) and of the hand-written closed-form
B1 (:mod:`b1_reference`, 2 s simulated: issue 29's floor, as ``scene_cost.py`` times it), timed interleaved after an
untimed run of each; the cost per simulated second, its ratio to the floor's, the integration steps and the paths
the modes took (per mode in the JSON; the table counts them per path). ``--interpreted``: the same run with
``LivePipelines.use = False`` (every mode on the same call interpreted, its Python twins,
:mod:`contactdyn.numerics.twins`; slow: for short scenes) joins the interleaved variants: its cost, the ratio
compiled/interpreted, and the runs' agreement: the largest relative difference over all channels
(max |compiled − interpreted| / max |interpreted| per channel) and its channel, the events' kinds the same and the
largest difference of their times [s]. (It replaces ``--readable``, the readable model's runs: a path that no
longer exists.)
"""

from __future__ import annotations

import argparse
import sys
import warnings
from collections import Counter
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import b1_reference  # noqa: E402
from timing import interleaved, write_report  # noqa: E402

from contactdyn.errors import SimulationError  # noqa: E402
from contactdyn.model.paths import LivePipelines  # noqa: E402
from contactdyn.model.system import System  # noqa: E402
from contactdyn.scene.scene_file import load_scene, parse_override  # noqa: E402
from contactdyn.simulate import run_system  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent
SCENES = [*(str(p.relative_to(ROOT)) for folder in ("sims", "benchmarks/hard", "examples")
            for p in sorted((ROOT / folder).glob("*.toml"))), "benchmarks/b2.toml"]


def run(scene, compiled: bool = True):
    """One whole run of ``scene`` (``compiled`` False: every mode interpreted; the switch restored after)."""
    LivePipelines.use = compiled
    try:
        return run_system(System(scene))
    finally:
        LivePipelines.use = True


def agreement(on, off) -> dict:  # (on: the compiled run; off: the interpreted one)
    """The largest relative channel difference (and where), the events' kinds alike, their times' largest gap [s]."""
    worst, where = 0.0, ""
    for key, ref in off.channels.items():
        ref, got = np.asarray(ref, float), np.asarray(on.channels[key], float)
        if not ref.size or np.all(np.isnan(ref)):
            continue
        d = float(np.nanmax(np.abs(got - ref))) / max(float(np.nanmax(np.abs(ref))), 1e-300)
        if d > worst:
            worst, where = d, key
    same = [(e["kind"], e["name"]) for e in on.events] == [(e["kind"], e["name"]) for e in off.events]
    dt = max((abs(a["t"] - b["t"]) for a, b in zip(on.events, off.events, strict=True)), default=0.0) if same \
        else float("nan")
    return {"max_rel_diff": worst, "channel": where, "events_same": same, "events": len(off.events),
            "max_event_dt_s": dt}


def paths(result) -> dict:
    """The path each mode of a run took, by mode."""
    return {mode: r["path"] for mode, r in result.stats["paths"].items()}


def measure(path: str, repeats: int, overrides: dict | None = None, interpreted: bool = False) -> dict:
    scene = load_scene(ROOT / path, overrides)
    variants = {"compiled": lambda: run(scene), "floor": b1_reference.run}
    if interpreted:
        variants["interpreted"] = lambda: run(scene, False)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        for call in variants.values():
            call()  # untimed: compiles, caches
        times = interleaved(variants, repeats)
    on, T = times["compiled"], scene.duration
    floor = times["floor"].cpu / b1_reference.T_END  # [s CPU per simulated s] the hand-written B1
    row = {"scene": path, "duration_s": T, "cpu_s": on.cpu, "per_sim_s": on.cpu / T, "floor_per_sim_s": floor,
           "x_floor": on.cpu / T / floor, "steps": on.last.stats["steps"], "paths": paths(on.last)}
    if interpreted:
        off = times["interpreted"]
        row.update({"interpreted_cpu_s": off.cpu, "interpreted_per_sim_s": off.cpu / T,
                    "ratio_compiled_interpreted": on.cpu / off.cpu, "interpreted_steps": off.last.stats["steps"],
                    **agreement(on.last, off.last)})
    return row


def path_counts(by_mode: dict) -> str:
    """'compiled call 3, interpreted call 1': how many modes took each path."""
    return ", ".join(f"{path} {n}" for path, n in Counter(by_mode.values()).most_common())


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("scenes", nargs="*", default=SCENES)
    p.add_argument("--repeats", type=int, default=3)
    p.add_argument("--interpreted", action="store_true", help="also every run interpreted (agreement)")
    p.add_argument("--set", action="append", default=[], metavar="KEY=VALUE", help="override a key in every scene")
    p.add_argument("--out", default=str(ROOT / "benchmarks" / "out" / "pipeline_loop.json"))
    args = p.parse_args(argv)
    overrides = dict(parse_override(text) for text in args.set)
    rows = []
    extra = " interpreted CPU/sim s | compiled/interpreted | max rel diff (channel) | events | max Δt [s] |"
    print("| scene | CPU/sim s | floor CPU/sim s | × floor | steps | paths (modes) |"
          + (extra if args.interpreted else "")
          + "\n|---|---|---|---|---|---|" + ("---|---|---|---|---|" if args.interpreted else ""))
    for path in args.scenes:
        try:
            r = measure(path, args.repeats, overrides, args.interpreted)
        except SimulationError as err:  # (e.g. a step budget under --set): the row says so, the others run
            rows.append({"scene": path, "error": str(err)})
            print(f"| {Path(path).stem} | failed: {err} |", flush=True)
            continue
        rows.append(r)
        line = (f"| {Path(path).stem} | {r['per_sim_s']:.4f} | {r['floor_per_sim_s']:.4f} | {r['x_floor']:.2f} | "
                f"{r['steps']} | {path_counts(r['paths'])} |")
        if args.interpreted:
            line += (f" {r['interpreted_per_sim_s']:.4f} | {r['ratio_compiled_interpreted']:.3f} | "
                     f"{r['max_rel_diff']:.1e} "
                     f"({r['channel']}) | {r['events']}{'' if r['events_same'] else ' DIFFER'} | "
                     f"{r['max_event_dt_s']:.1e} |")
        print(line, flush=True)
    write_report(Path(args.out), {"repeats": args.repeats, "overrides": overrides, "interpreted": args.interpreted,
                                  "cpu": "process_time, median",
                                  "floor": "b1_reference.run (hand-written B1), CPU per simulated s"}, rows)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
