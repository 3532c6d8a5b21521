"""Whole runs on the one pipeline (``LivePipelines.prefer``) against the same runs on the twin's plans, in one process.

    PYTHONPATH=. python3 benchmarks/pipeline_loop.py [SCENE ...] [--repeats 3] [--set KEY=VALUE ...] [--out FILE.json]

Per scene (:data:`SCENES`: every scene of ``sims/``, ``benchmarks/hard/``, ``examples/`` and ``benchmarks/b2.toml``,
at its own duration and settings; ``--set`` overrides a key in every one, e.g. ``solver.rtol=1e-11``): the CPU median
of a whole run (System built, run, output sampled; the scene file read once before) with the switch off (every mode
on the twin's plan where it has one: the default) and on (every mode ``pack.unsupported`` accepts on the pipeline: its
compiled steps, event values and output samples; a mode it declines keeps its plan or the readable model), and of the
hand-written closed-form B1 (:mod:`b1_reference`, 2 s simulated: issue 29's floor, as ``scene_cost.py`` times it),
timed interleaved after an untimed run of each; the cost per simulated second, the ratios on/off and on/floor, the
integration steps of each, the paths the modes of each run took (per mode in the JSON; the table counts the "on"
run's modes per path), and the run's agreement: the largest relative difference over all channels (max |on − off| /
max |off| per channel) and its channel, the events' kinds the same and the largest difference of their times [s].
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


def run(scene, prefer: bool):
    """One whole run of ``scene`` with the switch set (restored after)."""
    LivePipelines.prefer = prefer
    try:
        return run_system(System(scene))
    finally:
        LivePipelines.prefer = False


def agreement(on, off) -> dict:
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


def measure(path: str, repeats: int, overrides: dict | None = None) -> dict:
    scene = load_scene(ROOT / path, overrides)
    variants = {"off": lambda: run(scene, False), "on": lambda: run(scene, True), "floor": b1_reference.run}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        for call in variants.values():
            call()  # untimed: compiles, caches
        times = interleaved(variants, repeats)
    off, on = times["off"], times["on"]
    T = scene.duration
    floor = times["floor"].cpu / b1_reference.T_END  # [s CPU per simulated s] the hand-written B1
    return {"scene": path, "duration_s": T, "off_cpu_s": off.cpu, "on_cpu_s": on.cpu,
            "off_per_sim_s": off.cpu / T, "on_per_sim_s": on.cpu / T, "ratio_on_off": on.cpu / off.cpu,
            "floor_per_sim_s": floor, "on_x_floor": on.cpu / T / floor, "off_x_floor": off.cpu / T / floor,
            "off_steps": off.last.stats["steps"], "on_steps": on.last.stats["steps"],
            "on_paths": paths(on.last), "off_paths": paths(off.last),
            **agreement(on.last, off.last)}


def path_counts(by_mode: dict) -> str:
    """'one pipeline 3, compiled call 1': how many modes took each path."""
    return ", ".join(f"{path} {n}" for path, n in Counter(by_mode.values()).most_common())


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("scenes", nargs="*", default=SCENES)
    p.add_argument("--repeats", type=int, default=3)
    p.add_argument("--set", action="append", default=[], metavar="KEY=VALUE", help="override a key in every scene")
    p.add_argument("--out", default=str(ROOT / "benchmarks" / "out" / "pipeline_loop.json"))
    args = p.parse_args(argv)
    overrides = dict(parse_override(text) for text in args.set)
    rows = []
    print("| scene | off CPU/sim s | on CPU/sim s | on/off | on/floor | steps off/on | max rel diff (channel) | events "
          "| max Δt [s] | on paths (modes) |\n|---|---|---|---|---|---|---|---|---|---|")
    for path in args.scenes:
        try:
            r = measure(path, args.repeats, overrides)
        except SimulationError as err:  # (e.g. a step budget under --set): the row says so, the others run
            rows.append({"scene": path, "error": str(err)})
            print(f"| {Path(path).stem} | failed: {err} |", flush=True)
            continue
        rows.append(r)
        print(f"| {Path(path).stem} | {r['off_per_sim_s']:.4f} | {r['on_per_sim_s']:.4f} | {r['ratio_on_off']:.2f} | "
              f"{r['on_x_floor']:.2f} | {r['off_steps']}/{r['on_steps']} | {r['max_rel_diff']:.1e} ({r['channel']}) | "
              f"{r['events']}{'' if r['events_same'] else ' DIFFER'} | {r['max_event_dt_s']:.1e} | "
              f"{path_counts(r['on_paths'])} |", flush=True)
    write_report(Path(args.out), {"repeats": args.repeats, "overrides": overrides, "cpu": "process_time, median",
                                  "floor": "b1_reference.run (hand-written B1), CPU per simulated s"}, rows)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
