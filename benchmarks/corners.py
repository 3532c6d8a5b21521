"""Segments ending at the set-points' corners, against segments that step over them: cost and error per scene.

    PYTHONPATH=. python3 benchmarks/corners.py [--repeats 3] [--methods DOP853C] [--restart 25] [scene ...]

1. Every scene of sims/ at its own settings, once with ``HybridRun.at_corners`` off (the
   corners fall inside steps, as before) and once on, interleaved repeat by repeat; cost = the
   median process CPU time around ``simulate`` (``timing.interleaved``) (loading and output included; CPU because the
   machine is shared). Steps, right-hand-side calls, corners passed; force [N] and tip [m]
   errors against the reference of ``benchmarks/scenes.py`` (solve_ivp's DOP853 at rtol 1e-11,
   with the corners), away from ±2 samples of every event, as there.
2. What one corner costs: B1 with ``--restart`` extra trapezoid moves of zero displacement
   (4 corners each, no change to the motion), corners on against off: the CPU difference per
   corner (the segment's restart: its events, the first step, a Segment, two calls for the
   events' check across the corner) and the steps it adds.

Writes benchmarks/out/corners.json.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

import scenes  # noqa: E402
from timing import interleaved  # noqa: E402

from contactdyn import simulate  # noqa: E402
from contactdyn.hybrid.loop import HybridRun  # noqa: E402
from contactdyn.scene.scene_file import load_scene, sims_dir  # noqa: E402

OUT = Path(__file__).parent / "out"


def _run(name: str, overrides: dict, corners: bool):
    """A call running the scene with the corners on or off."""
    def call():
        HybridRun.at_corners = corners
        try:
            return simulate(name, overrides)
        finally:
            HybridRun.at_corners = True
    return call


def _variants(name: str, overrides: dict, repeats: int) -> dict:
    return interleaved({"off": _run(name, overrides, False), "on": _run(name, overrides, True)}, repeats)


def compare(name: str, method: str | None, repeats: int) -> dict:
    """Corners off and on for one scene (its own method, or ``method``)."""
    times = _variants(name, {"solver.method": method} if method else {}, repeats)
    ref = simulate(name, scenes.REFERENCE)
    row: dict = {"scene": name, "method": method or load_scene(name).solver.method}
    for label, timing in times.items():
        r, err = timing.last, scenes.errors(timing.last, ref)
        row[label] = {"cpu_s": timing.cpu, "steps": r.stats["steps"], "rhs_evals": r.stats["rhs_evals"],
                      "corners": r.stats["corners"], "events": len(r.events),
                      "force_err": err["force_away"], "tip_err": err["tip_away"]}
    return row


def restart_cost(n_moves: int, repeats: int) -> dict:
    """B1 with n_moves zero-displacement trapezoids (4 corners each): CPU and steps, corners off and on."""
    doc = load_scene("b1").document
    moves = [*doc["phase"][0]["reference"]["moves"],
             *({"kind": "trapezoid", "delta": [0.0, 0.0, 0.0], "start": 0.05 + 0.07 * k, "duration": 0.05}
               for k in range(n_moves))]
    over = {"phase": [{**doc["phase"][0], "reference": {**doc["phase"][0]["reference"], "moves": moves}}]}
    times = _variants("b1", over, repeats)
    off, on = times["off"], times["on"]
    n = on.last.stats["corners"]
    return {"moves": n_moves, "corners": n, "cpu_off_s": off.cpu, "cpu_on_s": on.cpu,
            "us_per_corner": (on.cpu - off.cpu) / n * 1e6 if n else float("nan"),
            "steps_off": off.last.stats["steps"], "steps_on": on.last.stats["steps"]}


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("scenes", nargs="*")
    p.add_argument("--repeats", type=int, default=3)
    p.add_argument("--methods", default="", help="comma-separated; default: each scene's own")
    p.add_argument("--restart", type=int, default=25, help="zero moves in the per-corner cost run (0: skip)")
    args = p.parse_args(argv)
    methods = [m for m in args.methods.split(",") if m] or [None]
    names = args.scenes or sorted(q.stem for q in sims_dir().glob("*.toml"))
    head = ("| scene | method | corners | steps off / on | rhs calls off / on | CPU ms off / on | on / off | "
            "force err [N] off / on | tip err [m] off / on |")
    lines = [head, "|" + "---|" * (head.count("|") - 1)]
    rows = []
    for name in names:
        for method in methods:
            r = compare(name, method, args.repeats)
            rows.append(r)
            a, b = r["off"], r["on"]
            lines.append(f"| {name} | {r['method']} | {b['corners']} | {a['steps']} / {b['steps']} | "
                         f"{a['rhs_evals']} / {b['rhs_evals']} | {a['cpu_s'] * 1e3:.0f} / {b['cpu_s'] * 1e3:.0f} | "
                         f"{b['cpu_s'] / a['cpu_s']:.2f} | {a['force_err']:.1e} / {b['force_err']:.1e} | "
                         f"{a['tip_err']:.1e} / {b['tip_err']:.1e} |")
            print(lines[-1], flush=True)
    print("\n".join(lines))
    restart = restart_cost(args.restart, args.repeats) if args.restart else None
    if restart:
        print(f"\nB1 + {restart['moves']} zero trapezoids: {restart['corners']} corners, CPU "
              f"{restart['cpu_off_s'] * 1e3:.1f} ms off / {restart['cpu_on_s'] * 1e3:.1f} ms on = "
              f"{restart['us_per_corner']:.0f} µs per corner; steps {restart['steps_off']} / {restart['steps_on']}")
    OUT.mkdir(parents=True, exist_ok=True)
    (OUT / "corners.json").write_text(json.dumps({"repeats": args.repeats, "rows": rows, "restart": restart},
                                                 indent=1))
    print(f"wrote {OUT / 'corners.json'}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
