"""Every robot of `contactdyn list robots` through `contactdyn new`: how many starter scenes run and press.

    PYTHONPATH=. python3 benchmarks/starter_matrix.py [ROBOT ...] [--timeout 120] [--out FILE.json]

Per robot, as `contactdyn new NAME --robot ROBOT --friction` makes it (no --tip: the starter's own
choice, a known tool frame or the leaf with the longest chain), in a child process with a time limit:
the starter scene (`contactdyn.starter.starter_scene`), or the refusal's sentence; then the run:
whether the tip touched, the normal force at the end of the press phase against the 20 N set-point,
the warnings, the wall time. A run that applies no force without a
warning is counted as "silent" (the goal: none).
"""

from __future__ import annotations

import argparse
import json
import multiprocessing as mp
import sys
import time
import warnings
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))


def _one(robot: str, tip: str | None, queue) -> None:
    warnings.simplefilter("ignore")
    import tomllib

    from contactdyn import parse_scene, simulate
    from contactdyn.errors import ContactdynError
    from contactdyn.starter import PRESS, starter_scene

    row = {"robot": robot, "tip": tip}
    try:
        text = starter_scene("starter", robot, "b", True, tip)
    except ContactdynError as exc:
        queue.put({**row, "status": "refused", "why": str(exc)})
        return
    wall = time.perf_counter()
    try:
        r = simulate(parse_scene(tomllib.loads(text)))
    except ContactdynError as exc:
        queue.put({**row, "status": "failed", "why": str(exc)})
        return
    t = r.t
    press = (t > 1.2) & (t <= 1.5)
    F = r["contact.table.F_n"]
    pressed = bool(press.any()) and abs(float(F[press][-1]) - PRESS) < 0.05 * PRESS
    notes = r.meta["warnings"] + r.meta["check_warnings"]
    queue.put({**row, "status": "ran", "touched": bool(r["contact.table.touching"].any()),
               "F_end_of_press": float(F[press][-1]) if press.any() else 0.0, "pressed": pressed,
               "warnings": len(notes), "silent": (not r["contact.table.touching"].any()) and not notes,
               "wall_s": time.perf_counter() - wall})


def run(robot: str, tip: str | None, timeout: float) -> dict:
    queue = mp.Queue()
    p = mp.Process(target=_one, args=(robot, tip, queue))
    p.start()
    p.join(timeout)
    if p.is_alive():
        p.kill()
        return {"robot": robot, "tip": tip, "status": "timeout"}
    return queue.get() if not queue.empty() else {"robot": robot, "tip": tip, "status": "crashed"}


def main(argv: list[str] | None = None) -> int:
    from contactdyn.robot.listing import robot_entries

    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("robots", nargs="*")
    p.add_argument("--timeout", type=float, default=120.0)
    p.add_argument("--out")
    args = p.parse_args(argv)
    entries = [e for e in robot_entries() if not e.get("error")]
    if args.robots:
        entries = [e for e in entries if e["name"] in args.robots]
    rows = []
    for e in entries:
        row = run(e["name"], None, args.timeout)
        rows.append(row)
        print(json.dumps(row), flush=True)
    counts = {k: sum(1 for r in rows if r["status"] == k) for k in ("ran", "refused", "failed", "timeout", "crashed")}
    counts["pressed"] = sum(1 for r in rows if r.get("pressed"))
    counts["silent"] = sum(1 for r in rows if r.get("silent"))
    print(f"{len(rows)} robots: {counts}")
    if args.out:
        Path(args.out).write_text(json.dumps({"counts": counts, "rows": rows}, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
