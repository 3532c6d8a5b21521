"""When a first run's leaves are ready: numba's compiles of the run and of its leaves' helper, on one time line.

For each scene, a fresh process runs ``contactdyn run SCENE --json`` with an empty compile cache (what a fresh
install meets: contactdyn.first_run). A ``sitecustomize`` in a temporary folder on PYTHONPATH registers a listener
for numba's ``numba:compile`` events in every process that imports numba (the run, its helper, the background build:
``python -m contactdyn.first_run`` has its module's path as ``sys.argv[0]``) and appends each outermost compile
(start, end [s], process role, function) to a log. Printed per scene: the run's wall time [s], when the run's last
leaf compile ended ("ready" [s] after the start), the compile seconds of the run and of the helper, and the
functions both compiled (duplicates). The background build is killed when the run ends (it would run on). Steadier
than the whole first run's wall time: what the leaves' split changes is when the run is ready, not how long its
interpreted part takes.

    python3 benchmarks/first_run_compiles.py [SCENE ...] [--repeats 1]

Prints a table and writes benchmarks/out/first_run_compiles.json.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
OUT = Path(__file__).parent / "out"
HOOK = '''
import os, sys, time
def _listen():
    from numba.core import event
    log, depth = open(os.environ["FIRST_RUN_COMPILES_LOG"], "a", buffering=1), [0]
    role = "helper" if "--leaves" in sys.argv else ("build" if sys.argv[0].endswith("first_run.py") else "run")
    class Listener(event.Listener):
        def on_start(self, e):
            depth[0] += 1
            if depth[0] == 1:
                self.t0 = time.time()
        def on_end(self, e):
            depth[0] -= 1
            if depth[0] == 0:
                f = getattr((e.data or {}).get("dispatcher"), "py_func", None)
                log.write(f"{self.t0:.3f} {time.time():.3f} {role} {getattr(f, '__qualname__', f)}\\n")
    event.register("numba:compile", Listener())
import builtins
_import, _done = builtins.__import__, []
def _hooked(name, *args, **kwargs):
    module = _import(name, *args, **kwargs)
    ev = sys.modules.get("numba.core.event")
    if not _done and ev is not None and hasattr(ev, "Listener") and hasattr(sys.modules.get("numba"), "njit"):
        _done.append(1)
        _listen()
    return module
builtins.__import__ = _hooked
'''


def _stop_background() -> None:
    """End the background build and helper a first run leaves behind (they would load the next measurement)."""
    subprocess.run(["pkill", "-f", "contactdyn.first_run"], check=False)
    time.sleep(0.5)


def one_run(scene: str, hook: str) -> dict:
    """A first run of ``scene`` with an empty cache, its compiles logged."""
    with tempfile.TemporaryDirectory() as cache, tempfile.TemporaryDirectory() as work:
        log = Path(work) / "compiles.log"
        env = dict(os.environ, NUMBA_CACHE_DIR=cache, FIRST_RUN_COMPILES_LOG=str(log),
                   PYTHONPATH=os.pathsep.join([hook, str(ROOT)]))
        _stop_background()
        start = time.time()
        subprocess.run([sys.executable, "-c", "import sys; from contactdyn.cli import main; sys.exit(main())", "run",
                        scene, "--json"], env=env, cwd=work, capture_output=True, check=True)
        wall = time.time() - start
        _stop_background()
        rows = [line.split(None, 3) for line in log.read_text().splitlines()] if log.exists() else []
    rows = [(float(a) - start, float(b) - start, role, name) for a, b, role, name in rows if role != "build"]
    run = [r for r in rows if r[2] == "run"]
    helper = [r for r in rows if r[2] == "helper"]
    both = sorted({r[3] for r in run} & {r[3] for r in helper})
    return {"scene": scene, "wall": wall, "ready": max((r[1] for r in run), default=0.0),
            "run_compiles": sum(r[1] - r[0] for r in run), "helper_compiles": sum(r[1] - r[0] for r in helper),
            "duplicates": both, "timeline": rows}


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("scenes", nargs="*", default=["b1", "case1_cart", "case2_writer5dof", "force_loop_real_cell"])
    p.add_argument("--repeats", type=int, default=1)
    args = p.parse_args()
    with tempfile.TemporaryDirectory() as hook:
        (Path(hook) / "sitecustomize.py").write_text(HOOK)
        runs = [one_run(scene, hook) for _ in range(args.repeats) for scene in args.scenes]
    print(f"{'scene':24s} {'wall [s]':>9s} {'ready [s]':>10s} {'run [s]':>8s} {'helper [s]':>11s}  duplicates")
    for scene in args.scenes:
        mine = [r for r in runs if r["scene"] == scene]
        med = {k: statistics.median(r[k] for r in mine) for k in ("wall", "ready", "run_compiles", "helper_compiles")}
        dups = sorted({d for r in mine for d in r["duplicates"]})
        print(f"{scene:24s} {med['wall']:9.2f} {med['ready']:10.2f} {med['run_compiles']:8.2f} "
              f"{med['helper_compiles']:11.2f}  {', '.join(dups) or '-'}")
    OUT.mkdir(exist_ok=True)
    (OUT / "first_run_compiles.json").write_text(json.dumps({"load": os.getloadavg()[0], "runs": runs}, indent=1))
    print(f"-> {OUT / 'first_run_compiles.json'}")


if __name__ == "__main__":
    main()
