"""The first run of a fresh install against a later one: `contactdyn run SCENE` with an empty cache, then warm.

For each scene (default: b1, then every other ``sims/*.toml``) fresh processes run
``contactdyn run SCENE --json`` (no plots, no viewer, nothing saved; the working directory a
temporary folder; the default path ``auto``, contactdyn.first_run), all with ``NUMBA_CACHE_DIR`` pointing at
one new empty folder (what a fresh ``pip install .`` meets: nothing compiled): the first (the compiled call's
functions interpreted, :mod:`contactdyn.numerics.twins`, compiling only its leaves, the rigid-body algorithms and
the dense linear algebra; it starts the background build), one right after it (``during``: the build still runs,
so interpreted again, its leaves cached), then, once the build ended (``build``: seconds waited for it after the
second run), a later one (the compiled call, its code loaded from the cache). ``--compiled-first``: also a first
run with ``--path compiled`` in another empty folder (compiling in the foreground: what every first run cost
before). ``--alone``: also, before it, a first run without the leaves' helper (``CONTACTDYN_LEAVES_AHEAD=0``: on a
second core it compiles the first run's leaves from the other end, contactdyn.first_run) in another empty folder,
its background build waited for: the helper's gain, timed beside the run with it.
Each wall time [s] is measured around the whole process (interpreter start, imports,
compilation or cache loading, the run), and so is its CPU time [s] (user + system: what the process
itself spent, less inflated by other load on a shared machine). Also: ``contactdyn --help`` (the console script's call,
``contactdyn.cli.main``), median of ``--help-repeats`` processes [s], and whether the first run
printed the compile notice (a stderr line containing "compiling"), and which path each run took (``paths``:
the first and the later run's ``Result.stats["paths"]``, from ``--json``).

The machine's speed at the time: ``ref [s]``, before each scene, the median wall time of REFERENCE_REPEATS
processes running one fixed pure-Python workload (:data:`REFERENCE`; a first run is Python-bound: numba's compiler
front end and the interpreted call). On a shared machine it moves with the load, and the first runs with it: read
an absolute bound against it (``first_per_ref`` in the JSON and CSV: the first run in units of the reference).

The processes run this checkout's package (``PYTHONPATH`` = the checkout). The 1-minute load
average before each run is recorded: on a shared machine a load above the core count means the
times are inflated.

    python3 benchmarks/first_run.py [SCENE ...] [--help-repeats 5] [--compiled-first] [--alone]

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
sys.path.insert(0, str(ROOT))
from contactdyn.first_run import HELPER_ENV  # noqa: E402  (the leaves' helper's switch)

OUT = Path(__file__).parent / "out"
HELP = ["-c", "import sys; from contactdyn.cli import main; sys.exit(main())", "--help"]  # = the console script
TIMEOUT = 1800.0  #: [s] one process at most
#: the reference workload: pure Python, no imports (its process's start is in its wall time, as a first run's is)
REFERENCE = ["-c", "s = 0\nfor i in range(3_000_000):\n    s += i * i % 7\nprint(s)"]
REFERENCE_REPEATS = 3  #: processes timed for ref [s] before each scene


def default_scenes() -> list[str]:
    """b1 first, then every other scene of sims/."""
    names = sorted(p.stem for p in (ROOT / "sims").glob("*.toml"))
    return ["b1"] + [n for n in names if n != "b1"]


def _environment(cache: str | None, helper: bool = True) -> dict[str, str]:
    env = dict(os.environ)
    env.pop(HELPER_ENV, None)
    if not helper:
        env[HELPER_ENV] = "0"  # (no leaves' helper)
    env["PYTHONPATH"] = os.pathsep.join([str(ROOT)] + ([env["PYTHONPATH"]] if env.get("PYTHONPATH") else []))
    env.pop("NUMBA_CACHE_DIR", None)
    env.pop("CONTACTDYN_PATH", None)  # the command's default path: auto
    if cache is not None:
        env["NUMBA_CACHE_DIR"] = cache
    return env


def _children_cpu() -> float:
    """[s] CPU time (user + system) of the finished child processes so far."""
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    return usage.ru_utime + usage.ru_stime


def timed(args: list[str], cache: str | None, cwd: str, helper: bool = True) -> tuple[float, float, int, str]:
    """(wall [s], CPU [s], exit code, stderr) of one ``python3 ARGS`` process (its stdout in ``timed.out``);
    ``helper`` False: with the first run's leaves' helper turned off."""
    t0, c0 = time.perf_counter(), _children_cpu()
    done = subprocess.run([sys.executable, *args], cwd=cwd, env=_environment(cache, helper), capture_output=True,
                          text=True, timeout=TIMEOUT)
    timed.out = done.stdout
    return time.perf_counter() - t0, _children_cpu() - c0, done.returncode, done.stderr


def _paths() -> list[str]:
    """The paths the last timed ``run --json`` took (``Result.stats["paths"]``), sorted."""
    try:
        return sorted({row["path"] for row in json.loads(timed.out)["stats"]["paths"].values()})
    except (ValueError, KeyError, TypeError):
        return []


def _wait_for_build(cache: str) -> tuple[float, bool]:
    """([s] until the background build of ``contactdyn.first_run`` ended, and any leaves' helper, whether the build
    marked its kind built)."""
    t0 = time.perf_counter()
    while time.perf_counter() - t0 < TIMEOUT:
        if not list(Path(cache).glob("*/kinds/*.building")):
            break
        time.sleep(0.5)
    return time.perf_counter() - t0, bool(list(Path(cache).glob("*/kinds/*.built")))


def reference_time(work: str, repeats: int = REFERENCE_REPEATS) -> float:
    """[s] The median wall time of ``repeats`` processes running :data:`REFERENCE` (the machine's speed now)."""
    return statistics.median(timed(REFERENCE, None, work)[0] for _ in range(repeats))


def scene_row(scene: str, work: str, compiled_first: bool, alone: bool = False) -> dict:
    """The first run of one scene (empty cache, path ``auto``: the call interpreted, then the background build),
    a run while the build runs, the later run once it ended (the compiled call); ``compiled_first``: also the
    first run with ``--path compiled`` in another empty cache (compiling in the foreground); ``alone``: also,
    before those, the first run without the leaves' helper in another empty cache (its build ended first)."""
    path = ROOT / "sims" / f"{scene}.toml"
    path = path if path.is_file() else ROOT / scene  # a scene name of sims/, or a path in the checkout
    target = str(path) if path.is_file() else scene
    args = ["-m", "contactdyn.cli", "run", target, "--json"]
    row: dict = {"scene": scene, "load_before": round(os.getloadavg()[0], 2), "ref_s": round(reference_time(work), 3)}
    if alone:
        with tempfile.TemporaryDirectory(prefix="first_run_cache_") as cache:
            wall, cpu, rc0, _ = timed(args, cache, work, helper=False)
            _wait_for_build(cache)  # (its background build: not beside the next first run)
        row.update(alone_s=round(wall, 2), alone_cpu_s=round(cpu, 2), alone_exit_code=rc0)
    with tempfile.TemporaryDirectory(prefix="first_run_cache_") as cache:
        first, first_cpu, rc1, err1 = timed(args, cache, work)
        first_paths = _paths()
        during, during_cpu, rc2, _ = timed(args, cache, work)
        build_s, marked = _wait_for_build(cache)
        later, later_cpu, rc3, err3 = timed(args, cache, work)
        row["paths"] = [first_paths, _paths()]
    row.update(first_s=round(first, 2), first_cpu_s=round(first_cpu, 2), during_s=round(during, 2),
               build_wait_s=round(build_s, 1), built=marked, later_s=round(later, 2), later_cpu_s=round(later_cpu, 2),
               notice="compiling" in err1, exit_codes=[rc1, rc2, rc3], stderr_first=err1.strip()[-400:],
               stderr_later=err3.strip()[-400:], first_per_ref=round(first / row["ref_s"], 2))
    if compiled_first:
        with tempfile.TemporaryDirectory(prefix="first_run_cache_") as cache:
            compiled, compiled_cpu, rc4, _ = timed([*args, "--path", "compiled"], cache, work)
        row.update(compiled_first_s=round(compiled, 2), compiled_first_cpu_s=round(compiled_cpu, 2))
        row["exit_codes"].append(rc4)
    return row


def help_time(repeats: int, work: str) -> dict:
    """``contactdyn --help``: median wall [s] of ``repeats`` processes."""
    walls = [timed(HELP, None, work)[0] for _ in range(repeats)]
    return {"median_s": round(statistics.median(walls), 3), "walls_s": [round(w, 3) for w in walls]}


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("scenes", nargs="*", help="scene names in sims/ or paths in the checkout (default: b1 and every "
                   "sims/*.toml)")
    p.add_argument("--help-repeats", type=int, default=5, help="processes timed for contactdyn --help")
    p.add_argument("--compiled-first", action="store_true",
                   help="also time a first run with --path compiled (compiling in the foreground)")
    p.add_argument("--alone", action="store_true", help="also time a first run without the leaves' helper "
                   "(CONTACTDYN_LEAVES_AHEAD=0), before the one with it")
    args = p.parse_args()
    scenes = args.scenes or default_scenes()
    rows = []
    with tempfile.TemporaryDirectory(prefix="first_run_work_") as work:
        helps = help_time(args.help_repeats, work)
        print(f"contactdyn --help: {helps['median_s']:.3f} s (median of {args.help_repeats})", flush=True)
        heads = ("first [s]", "during [s]", "build [s]", "later [s]", "first CPU", "later CPU", "compiled 1st",
                 "alone [s]", "ref [s]")
        print(f"{'scene':24s} " + " ".join(f"{h:>12s}" for h in heads) + "  built  load", flush=True)
        for scene in scenes:
            row = scene_row(scene, work, args.compiled_first, args.alone)
            rows.append(row)
            flag = "" if not any(row["exit_codes"]) else f"  exit codes {row['exit_codes']}: {row['stderr_first']}"
            print(f"{scene:24s} " + " ".join(f"{row.get(k, float('nan')):12.2f}" for k in (
                "first_s", "during_s", "build_wait_s", "later_s", "first_cpu_s", "later_cpu_s", "compiled_first_s",
                "alone_s", "ref_s"))
                + f"  {str(row['built']):5s}  {row['load_before']:.2f}  {row['paths']}{flag}", flush=True)
    OUT.mkdir(parents=True, exist_ok=True)
    doc = {"help": helps, "scenes": rows, "cpus": os.cpu_count(), "python": platform.python_version(),
           "git": subprocess.run(["git", "-C", str(ROOT), "rev-parse", "--short", "HEAD"], capture_output=True,
                                 text=True).stdout.strip()}
    (OUT / "first_run.json").write_text(json.dumps(doc, indent=1))
    with open(OUT / "first_run.csv", "w", newline="") as f:
        w = csv.DictWriter(f, ["scene", "first_s", "during_s", "build_wait_s", "built", "later_s", "first_cpu_s",
                               "later_cpu_s", "compiled_first_s", "compiled_first_cpu_s", "alone_s", "notice",
                               "load_before", "ref_s", "first_per_ref"],
                           extrasaction="ignore")
        w.writeheader()
        w.writerows(rows)
    print(f"-> {OUT / 'first_run.json'}, {OUT / 'first_run.csv'}")


if __name__ == "__main__":
    main()
