"""Where a scene's run goes: the right-hand side, the step ends' event tests, the core and its restarts,
the output, building the modes' pipelines.

    PYTHONPATH=. python3 benchmarks/scene_split.py [SCENE ...] [--repeats 5] [--out FILE.json]

Per scene, CPU medians over ``--repeats`` runs of ``simulate(load_scene(name))``:

- run [ms]: the whole run, uninstrumented;
- then one instrumented run (each piece wrapped by a CPU timer, ~0.5 µs a reading; the sum of the
  pieces therefore exceeds the uninstrumented run by that times the calls, reported as ``timer``):
  rhs = inside the segment's right-hand side (the one pipeline's compiled call, and a stuck contact's cone margin
  sampled at each stage) and its compiled steps (:mod:`contactdyn.hybrid.steps`, 12 calls each); events =
  the events' values at the step ends and their location (``dop853._EventWatch.stop``); stepping = the
  rest of the integration (the core's arithmetic, its callbacks, the restarts after a rejected step; the
  compiled steps' control); output = sampling the channels (``HybridRun._result``);
  pipelines = a mode's pipeline where the run starts it (``LivePipelines.mode``: packed the first time,
  looked up after); other = the rest (loading, transitions, segment set-up);
- steps, rejected steps, runs of the compiled core (one per segment, one more per rejection, one
  more where the step after a retry would grow; 0 where a compiled mode takes every step in one compiled call,
  :mod:`contactdyn.hybrid.steps`, which does not run the core).

Only DOP853C's segments are split (a segment on LSODA, the 2-D launch or a slide's finish, counts under other).
Writes benchmarks/out/scene_split.json.
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from contactdyn.hybrid import loop as hybrid  # noqa: E402
from contactdyn.model.paths import LivePipelines  # noqa: E402
from contactdyn.numerics import dop853  # noqa: E402
from contactdyn.scene.scene_file import load_scene  # noqa: E402
from contactdyn.simulate import simulate  # noqa: E402

SCENES = ["b1", "case2_writer_b", "case2_writer_rigid", "case3_a_force", "case1_cart", "case2_writer5dof"]
CLOCK = time.process_time


class Split:
    """CPU time [s] spent inside the wrapped functions, by piece; calls counted."""

    def __init__(self):
        self.s: dict[str, float] = {}
        self.calls: dict[str, int] = {}
        self.undo: list = []

    def wrap(self, owner, attr: str, piece: str) -> None:
        orig = getattr(owner, attr)

        def timed(*args, **kw):
            t0 = CLOCK()
            try:
                return orig(*args, **kw)
            finally:
                self.s[piece] = self.s.get(piece, 0.0) + CLOCK() - t0
                self.calls[piece] = self.calls.get(piece, 0) + 1
        setattr(owner, attr, timed)
        self.undo.append((owner, attr, orig))

    def restore(self) -> None:
        for owner, attr, orig in reversed(self.undo):
            setattr(owner, attr, orig)


def timer_cost(n: int = 20000) -> float:
    """[s] one CLOCK reading."""
    t0 = CLOCK()
    for _ in range(n):
        CLOCK()
    return (CLOCK() - t0) / n


def instrumented(name: str) -> dict:
    """One run with its pieces timed (ms) and the core's runs counted."""
    split = Split()
    solve = dop853.solve
    calls = {"rhs": 0}
    inside = [False]  #: within a segment's integration (the interpolants the output builds later call f too)

    def timed(fun, per_call: int):
        def f(*args):
            if not inside[0]:
                return fun(*args)
            t0 = CLOCK()
            try:
                return fun(*args)
            finally:
                split.s["rhs"] = split.s.get("rhs", 0.0) + CLOCK() - t0
                calls["rhs"] += per_call
        return f

    def timed_solve(fun, *args, step=None, **kw):  # the rhs as the core sees it, and a compiled mode's steps
        t0, inside[0] = CLOCK(), True
        try:
            return solve(timed(fun, 1), *args, step=timed(step, 12) if step else None, **kw)
        finally:
            inside[0] = False
            split.s["integrate"] = split.s.get("integrate", 0.0) + CLOCK() - t0
    dop853.solve = timed_solve
    split.wrap(dop853._EventWatch, "stop", "events")
    split.wrap(dop853._Core, "run", "core_runs")
    split.wrap(hybrid.HybridRun, "_result", "output")
    split.wrap(LivePipelines, "mode", "pipelines")
    try:
        t0 = CLOCK()
        res = simulate(load_scene(name))
        total = CLOCK() - t0
    finally:
        split.restore()
        dop853.solve = solve
    s = split.s
    timer = 2 * timer_cost() * (calls["rhs"] + sum(split.calls.values()))
    stepping = s.get("integrate", 0.0) - s.get("rhs", 0.0) - s.get("events", 0.0)
    ms = {k: 1e3 * v for k, v in {"rhs": s.get("rhs", 0.0), "events": s.get("events", 0.0), "stepping": stepping,
                                  "output": s.get("output", 0.0), "pipelines": s.get("pipelines", 0.0),
                                  "other": total - s.get("integrate", 0.0) - s.get("output", 0.0)
                                  - s.get("pipelines", 0.0), "timer": timer}.items()}
    return {**ms, "steps": res.stats["steps"], "rhs_calls": calls["rhs"],
            "core_runs": split.calls.get("core_runs", 0), "step_ends": split.calls.get("events", 0)}


def measure(name: str, repeats: int) -> dict:
    simulate(load_scene(name))  # warm: robot model, caches
    runs = []
    for _ in range(repeats):
        t0 = CLOCK()
        simulate(load_scene(name))
        runs.append(CLOCK() - t0)
    return {"scene": name, "run": 1e3 * statistics.median(runs), **instrumented(name)}


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("scenes", nargs="*", default=SCENES)
    p.add_argument("--repeats", type=int, default=5)
    p.add_argument("--out", default=str(Path(__file__).resolve().parent / "out" / "scene_split.json"))
    args = p.parse_args(argv)
    rows = [measure(name, args.repeats) for name in args.scenes]
    cols = ["scene", "run", "rhs", "events", "stepping", "output", "pipelines", "other", "timer", "steps", "rhs_calls",
            "core_runs"]
    print("CPU ms (run: median, uninstrumented; the rest: one instrumented run)")
    print(" | ".join(cols) + " | events µs/step | stepping µs/step")
    for r in rows:
        per = f" | {1e3 * r['events'] / max(r['step_ends'], 1):.1f} | {1e3 * r['stepping'] / max(r['steps'], 1):.1f}"
        print(" | ".join(f"{r[c]:.1f}" if isinstance(r[c], float) else str(r[c]) for c in cols) + per)
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    Path(args.out).write_text(json.dumps(rows, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
