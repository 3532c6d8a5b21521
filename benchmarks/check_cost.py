"""Cost of a run's physics checks (contactdyn.output.physics_checks): whole runs with and without them.

    PYTHONPATH=. python3 benchmarks/check_cost.py [SCENE ...] [--repeats 7] [--out FILE.json]

Per scene, after one untimed run (compiled code loaded), the whole ``simulate`` is timed
interleaved in one process: as shipped, and with the checks switched off (the segment-start
audit and :func:`~contactdyn.output.physics_checks.run_checks` replaced by no-ops). CPU medians over
the repeats, their ratio, and the checks' own CPU time inside the checked runs (the audit and
``run_checks`` timed where they are called) as a share of the run: on a noisy machine the
ratio of two whole runs scatters by several per cent, the share inside one run does not.
``energy_b1`` is B1 with ``solver.record_energy``
(the one check that evaluates the robot per sample).
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
import warnings
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from scene_cost import report  # noqa: E402
from timing import interleaved  # noqa: E402

import contactdyn.hybrid.loop as hybrid  # noqa: E402
from contactdyn import simulate  # noqa: E402
from contactdyn.output.physics_checks import StartAudit  # noqa: E402
from contactdyn.scene.scene_file import load_scene  # noqa: E402

SCENES = ["b1", "case1_cart", "case2_writer5dof", "case2_writer_ur5", "case2_writer_b", "case2_writer_motors",
          "case3_a_force", "case3_b_force", "energy_b1"]


def _scene(name: str):
    if name == "energy_b1":
        return load_scene("b1", {"solver.record_energy": True})
    return load_scene(name)


def _unchecked(scene):
    """simulate with the checks off."""
    record, checks = StartAudit.record, hybrid.run_checks
    StartAudit.record = lambda self, t, x, events: None
    hybrid.run_checks = lambda *args: {"contacts": {}}
    try:
        return simulate(scene)
    finally:
        StartAudit.record, hybrid.run_checks = record, checks


class _Clock:
    """CPU time [s] spent inside the wrapped functions."""

    def __init__(self):
        self.spent = 0.0

    def wrap(self, fn):
        def timed(*args):
            c0 = time.process_time()
            try:
                return fn(*args)
            finally:
                self.spent += time.process_time() - c0
        return timed


def _checked(scene, shares: list[float]):
    """simulate as shipped; the checks' share of its CPU time appended to ``shares``."""
    clock = _Clock()
    record, checks = StartAudit.record, hybrid.run_checks
    StartAudit.record, hybrid.run_checks = clock.wrap(record), clock.wrap(checks)
    try:
        c0 = time.process_time()
        result = simulate(scene)
        shares.append(clock.spent / (time.process_time() - c0))
        return result
    finally:
        StartAudit.record, hybrid.run_checks = record, checks


def measure(scenes: list[str], repeats: int) -> list[dict]:
    rows = []
    for name in scenes:
        scene = _scene(name)
        simulate(scene)  # untimed: compiled code loaded
        shares: list[float] = []
        times = interleaved({"checked": lambda s=scene, into=shares: _checked(s, into),
                             "unchecked": lambda s=scene: _unchecked(s)}, repeats)
        on, off = times["checked"].cpu, times["unchecked"].cpu
        rows.append({"scene": name, "checked_s": on, "unchecked_s": off, "ratio": on / off,
                     "checks_share": statistics.median(shares),
                     "violations": len(times["checked"].last.meta["check_warnings"])})
    return rows


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("scenes", nargs="*", default=SCENES)
    p.add_argument("--repeats", type=int, default=7)
    p.add_argument("--out", help="JSON file to write")
    args = p.parse_args(argv)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        report(measure(args.scenes, args.repeats), args.out)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
