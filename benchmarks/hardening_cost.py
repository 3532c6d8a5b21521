"""What the hardening costs and how fast a killed sweep is cleaned up.

    python benchmarks/hardening_cost.py [--repeats 15] [--kills 3]

1. URDF loading: ``Robot.load`` of each URDF in urdf/ with the forked Pinocchio probe
   (the first load of a file content: tree check + fork + build in the child) against a
   load whose probe is cached (tree check only), interleaved, medians over REPEATS; the
   ratio is the cost of the first load of a file in a process.
2. Validation: ``load_scene`` of every scene in sims/ (the file read, then ``parse_scene``: all checks incl.
   the run budget), the scenes interleaved, medians over REPEATS.
3. Cleanup: a 2-worker sweep of b1 is killed with SIGKILL after its third run; the time
   until no process of its session remains (the workers, fork server, resource tracker),
   median over KILLS.

Writes benchmarks/out/hardening_cost.json.
"""

from __future__ import annotations

import argparse
import json
import os
import signal
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks"))

from timing import interleaved  # noqa: E402

import contactdyn.robot.urdf_check as urdf_check  # noqa: E402
from contactdyn.robot.robot import Robot, urdf_dir  # noqa: E402
from contactdyn.scene.scene_file import load_scene, sims_dir  # noqa: E402

OUT = ROOT / "benchmarks" / "out" / "hardening_cost.json"


def load_times(repeats: int) -> dict[str, dict[str, float]]:
    table = {}
    for path in sorted(urdf_dir().glob("*.urdf")):
        # interleaved: probe (the cache cleared first: ~0.1 µs of a load of milliseconds), then cached
        times = interleaved({"cold": lambda path=path: (urdf_check._probed.clear(), Robot.load(path)),
                             "warm": lambda path=path: Robot.load(path)}, repeats)
        c, w = times["cold"].wall, times["warm"].wall
        table[path.stem] = {"probed_ms": 1e3 * c, "cached_ms": 1e3 * w, "ratio": c / w}
    return table


def validation_times(repeats: int) -> dict[str, float]:
    times = interleaved({path.stem: lambda path=path: load_scene(path) for path in sorted(sims_dir().glob("*.toml"))},
                        repeats)
    return {name: 1e3 * t.wall for name, t in times.items()}


def _session(sid: int) -> list[int]:
    pids = []
    for entry in Path("/proc").iterdir():
        if entry.name.isdigit():
            try:
                stat = (entry / "stat").read_text()
            except OSError:
                continue
            fields = stat[stat.rindex(")") + 2:].split()
            if int(fields[3]) == sid and fields[0] != "Z":
                pids.append(int(entry.name))
    return pids


def cleanup_time(kills: int) -> list[float]:
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    times = []
    for _ in range(kills):
        with tempfile.TemporaryDirectory() as tmp:
            out = Path(tmp) / "s"
            cmd = [sys.executable, "-m", "contactdyn.cli", "sweep", "b1", "--set", "duration=0.03", "--range",
                   "contact.tip.normal.k=5e4:2e5:200:log", "--workers", "2", "--chunk", "4", "--quiet", "--out",
                   str(out)]
            proc = subprocess.Popen(cmd, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                                    start_new_session=True)
            while len(list((out / "runs").glob("*.npz"))) < 3 and proc.poll() is None:
                time.sleep(0.005)
            os.kill(proc.pid, signal.SIGKILL)
            t0 = time.perf_counter()
            proc.wait()
            while _session(proc.pid) and time.perf_counter() - t0 < 30:
                time.sleep(0.002)
            times.append(time.perf_counter() - t0)
    return times


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--repeats", type=int, default=15)
    parser.add_argument("--kills", type=int, default=3)
    args = parser.parse_args()
    loads = load_times(args.repeats)
    print(f"{'URDF':<18} {'probed [ms]':>12} {'cached [ms]':>12} {'ratio':>7}")
    for name, row in loads.items():
        print(f"{name:<18} {row['probed_ms']:12.2f} {row['cached_ms']:12.2f} {row['ratio']:7.2f}")
    scenes = validation_times(args.repeats)
    print("\nload_scene (read + parse_scene, all checks) [ms]: " + ", ".join(f"{k} {v:.2f}" for k, v in scenes.items()))
    kills = cleanup_time(args.kills)
    print(f"\nSIGKILL of a 2-worker sweep -> no process left after {statistics.median(kills):.3f} s "
          f"(median of {len(kills)}; range {min(kills):.3f}-{max(kills):.3f} s)")
    OUT.parent.mkdir(parents=True, exist_ok=True)
    OUT.write_text(json.dumps({"repeats": args.repeats, "urdf_load": loads, "parse_scene_ms": scenes,
                               "cleanup_after_sigkill_s": kills, "cpu_count": os.cpu_count()}, indent=1))
    print(f"wrote {OUT}")


if __name__ == "__main__":
    main()
