"""The first run of a fresh install against a later one: `contactdyn run SCENE` with an empty cache, then warm.

For each scene (default: b1, then every other ``sims/*.toml``) two fresh processes run
``contactdyn run SCENE --quiet`` (no plots, no viewer, nothing saved; the working directory a
temporary folder): the first with ``NUMBA_CACHE_DIR`` pointing at a new empty folder (what a fresh
``pip install .`` meets: nothing compiled), the second with the same folder, now filled (a later
process). Each wall time [s] is measured around the whole process (interpreter start, imports,
compilation or cache loading, the run), and so is its CPU time [s] (user + system: what the process
itself spent, less inflated by other load on a shared machine). Also: ``contactdyn --help`` (the console script's call,
``contactdyn.cli.main``), median of ``--help-repeats`` processes [s], and whether the first run
printed the compile notice (a stderr line containing "compiling").

The processes run this checkout's package (``PYTHONPATH`` = the checkout). The 1-minute load
average before each run is recorded: on a shared machine a load above the core count means the
times are inflated.

    python3 benchmarks/first_run.py [SCENE ...] [--help-repeats 5]

Prints a table and writes benchmarks/out/first_run.json and benchmarks/out/first_run.csv.
"""

from __future__ import annotations

import argparse
import csv
import json
import os
import platform
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
OUT = Path(__file__).parent / "out"
HELP = ["-c", "import sys; from contactdyn.cli import main; sys.exit(main())", "--help"]  # = the console script
TIMEOUT = 1800.0  #: [s] one process at most


def default_scenes() -> list[str]:
    """b1 first, then every other scene of sims/."""
    names = sorted(p.stem for p in (ROOT / "sims").glob("*.toml"))
    return ["b1"] + [n for n in names if n != "b1"]


def _environment(cache: str | None) -> dict[str, str]:
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join([str(ROOT)] + ([env["PYTHONPATH"]] if env.get("PYTHONPATH") else []))
    env.pop("NUMBA_CACHE_DIR", None)
    if cache is not None:
        env["NUMBA_CACHE_DIR"] = cache
    return env


def _children_cpu() -> float:
    """[s] CPU time (user + system) of the finished child processes so far."""
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    return usage.ru_utime + usage.ru_stime


def timed(args: list[str], cache: str | None, cwd: str) -> tuple[float, float, int, str]:
    """(wall [s], CPU [s], exit code, stderr) of one ``python3 ARGS`` process."""
    t0, c0 = time.perf_counter(), _children_cpu()
    done = subprocess.run([sys.executable, *args], cwd=cwd, env=_environment(cache), capture_output=True, text=True,
                          timeout=TIMEOUT)
    return time.perf_counter() - t0, _children_cpu() - c0, done.returncode, done.stderr


def scene_row(scene: str, work: str) -> dict:
    """The first (empty cache) and later (warm cache) run of one scene."""
    path = ROOT / "sims" / f"{scene}.toml"
    path = path if path.is_file() else ROOT / scene  # a scene name of sims/, or a path in the checkout
    target = str(path) if path.is_file() else scene
    args = ["-m", "contactdyn.cli", "run", target, "--quiet"]
    with tempfile.TemporaryDirectory(prefix="first_run_cache_") as cache:
        load = os.getloadavg()[0]
        first, first_cpu, rc1, err1 = timed(args, cache, work)
        later, later_cpu, rc2, err2 = timed(args, cache, work)
    return {"scene": scene, "first_s": round(first, 2), "later_s": round(later, 2),
            "first_cpu_s": round(first_cpu, 2), "later_cpu_s": round(later_cpu, 2),
            "notice": "compiling" in err1, "exit_codes": [rc1, rc2], "load_before": round(load, 2),
            "stderr_first": err1.strip()[-400:], "stderr_later": err2.strip()[-400:]}


def help_time(repeats: int, work: str) -> dict:
    """``contactdyn --help``: median wall [s] of ``repeats`` processes."""
    walls = [timed(HELP, None, work)[0] for _ in range(repeats)]
    return {"median_s": round(statistics.median(walls), 3), "walls_s": [round(w, 3) for w in walls]}


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("scenes", nargs="*", help="scene names in sims/ or paths in the checkout (default: b1 and every "
                   "sims/*.toml)")
    p.add_argument("--help-repeats", type=int, default=5, help="processes timed for contactdyn --help")
    args = p.parse_args()
    scenes = args.scenes or default_scenes()
    rows = []
    with tempfile.TemporaryDirectory(prefix="first_run_work_") as work:
        helps = help_time(args.help_repeats, work)
        print(f"contactdyn --help: {helps['median_s']:.3f} s (median of {args.help_repeats})", flush=True)
        heads = ("first [s]", "later [s]", "first CPU", "later CPU")
        print(f"{'scene':24s} " + " ".join(f"{h:>10s}" for h in heads) + "  notice  load", flush=True)
        for scene in scenes:
            row = scene_row(scene, work)
            rows.append(row)
            flag = "" if row["exit_codes"] == [0, 0] else f"  exit codes {row['exit_codes']}: {row['stderr_first']}"
            print(f"{scene:24s} {row['first_s']:10.2f} {row['later_s']:10.2f} {row['first_cpu_s']:10.2f} "
                  f"{row['later_cpu_s']:10.2f}  {str(row['notice']):6s}  "
                  f"{row['load_before']:.2f}{flag}", flush=True)
    OUT.mkdir(parents=True, exist_ok=True)
    doc = {"help": helps, "scenes": rows, "cpus": os.cpu_count(), "python": platform.python_version(),
           "git": subprocess.run(["git", "-C", str(ROOT), "rev-parse", "--short", "HEAD"], capture_output=True,
                                 text=True).stdout.strip()}
    (OUT / "first_run.json").write_text(json.dumps(doc, indent=1))
    with open(OUT / "first_run.csv", "w", newline="") as f:
        w = csv.DictWriter(f, ["scene", "first_s", "later_s", "first_cpu_s", "later_cpu_s", "notice", "load_before"],
                           extrasaction="ignore")
        w.writeheader()
        w.writerows(rows)
    print(f"-> {OUT / 'first_run.json'}, {OUT / 'first_run.csv'}")


if __name__ == "__main__":
    main()
