"""Where a scene's first run spends its compile time: numba's compiles of each function, with an empty cache.

Runs ``contactdyn run``'s work (load the scene, simulate) in this process with NUMBA_CACHE_DIR a new
empty folder, and records numba's compile events (``numba:compile``, one per specialization compiled):
per function, the number of specializations, the time inside its compiles [s] ("incl.") and that time
less the compiles of the functions it called first ("own"), and the function whose compile first
needed it ("(Python)": a call from Python); then each function with more than one
specialization and its signatures (a duplicate from differing argument types: int against int64,
read-only or non-contiguous arrays, ...). Also the run's time and the sum of own times. All times are
this process's CPU time [s] (compiling is single-threaded: on a shared machine, less noisy than wall time).

    python3 benchmarks/compile_profile.py SCENE [--top 25] [--set KEY=VALUE ...] [--interpreted]

``--interpreted``: the run on the same call interpreted (``simulate(..., compiled=False)``, its Python twins: what a
first ``contactdyn run`` takes, contactdyn.first_run): what that path still compiles (its leaves). It replaces
``--readable``, the readable model's run: a path that no longer exists.
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from collections import defaultdict
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent


class Recorder:
    """numba's compile events -> per function: [specializations, own s, incl. s, signatures, first caller]."""

    def __init__(self) -> None:
        self.stack: list[list] = []  # [name, start, children's time, argument types]
        self.table: dict[str, list] = defaultdict(lambda: [0, 0.0, 0.0, [], None])
        self.dispatchers: dict[str, object] = {}  #: name -> its dispatcher (for :func:`array_setitems`)

    def on_start(self, event) -> None:
        d = event.data["dispatcher"]
        name = f"{d.py_func.__module__.removeprefix('contactdyn.')}.{d.py_func.__qualname__}"
        self.dispatchers[name] = d
        self.stack.append([name, time.process_time(), 0.0, event.data["args"]])

    def on_end(self, event) -> None:
        name, start, children, args = self.stack.pop()
        incl = time.process_time() - start
        row = self.table[name]
        row[0] += 1
        row[1] += incl - children
        row[2] += incl
        row[3].append(", ".join(str(a) for a in args))
        if row[4] is None:
            row[4] = self.stack[-1][0] if self.stack else "(Python)"
        if self.stack:
            self.stack[-1][2] += incl


def array_setitems(dispatchers: dict[str, object]) -> list[str]:
    """Each array stored into an array (``a[i:j] = b``, ``A[k] = row``: numba checks the shapes and compiles the
    check's message once per process, ~1.5–2 s) in the package's compiled functions, as "file:line function"."""
    from numba.core import ir, types

    found = set()
    for name, d in dispatchers.items():
        if not d.py_func.__module__.startswith("contactdyn"):
            continue
        for cres in d.overloads.values():
            calltypes = getattr(cres.type_annotation, "calltypes", None) or {}  # (the fndesc's: cleared by the cache)
            for inst, sig in calltypes.items():
                if isinstance(inst, (ir.SetItem, ir.StaticSetItem)) and sig is not None \
                        and isinstance(sig.args[-1], types.Array):
                    found.add(f"{inst.loc.filename.split('contactdyn/')[-1]}:{inst.loc.line} {name}")
    return sorted(found)


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("scene")
    p.add_argument("--top", type=int, default=25)
    p.add_argument("--set", action="append", default=[], help="override KEY=VALUE (TOML value)")
    p.add_argument("--setitems", action="store_true", help="list the arrays stored into arrays (shape checks)")
    p.add_argument("--interpreted", action="store_true", help="the run interpreted (a first run's path)")
    args = p.parse_args()
    os.environ["NUMBA_CACHE_DIR"] = tempfile.mkdtemp(prefix="compile_profile_")
    sys.path.insert(0, str(ROOT))
    from numba.core import event

    from contactdyn.scene.scene_file import load_scene, parse_override
    from contactdyn.simulate import simulate

    rec = Recorder()
    listener = type("L", (event.Listener,), {"on_start": lambda s, e: rec.on_start(e),
                                             "on_end": lambda s, e: rec.on_end(e)})()
    event.register("numba:compile", listener)
    t0 = time.process_time()
    simulate(load_scene(args.scene, dict(parse_override(s) for s in args.set)), compiled=not args.interpreted)
    wall = time.process_time() - t0
    rows = sorted(rec.table.items(), key=lambda kv: -kv[1][1])
    print(f"{args.scene}: run {wall:.1f} s (CPU), compiling (own, summed) {sum(r[1] for _, r in rows):.1f} s, "
          f"{len(rows)} functions, {sum(r[0] for _, r in rows)} specializations")
    print(f"{'function':52s} {'n':>3s} {'own [s]':>8s} {'incl. [s]':>9s}  first compiled for")
    for name, (n, own, incl, _, caller) in rows[:args.top]:
        print(f"{name:52s} {n:3d} {own:8.2f} {incl:9.2f}  {caller}")
    for name, (n, own, _, sigs, _) in rows:
        if n > 1:
            print(f"\n{name}: {n} specializations ({own:.2f} s own)")
            for s in sigs:
                print(f"  ({s})")
    if args.setitems:
        print("\narrays stored into arrays (each compiles numba's shape-check message, once per process):")
        for line in array_setitems(rec.dispatchers):
            print(f"  {line}")


if __name__ == "__main__":
    main()
