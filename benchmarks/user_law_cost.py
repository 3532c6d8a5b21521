"""A user's law against its built-in twin on the same scene: examples/my_laws.py's impedance vs task_pd.

    PYTHONPATH=. python3 benchmarks/user_law_cost.py [--repeats 7] [--out FILE.json]

Both runs of examples/impedance_press.toml (the twin: task_pd with kp = K, kd = D, gravity
feedforward, the same run to 1e-9), timed interleaved in one process after an untimed run
each; CPU medians, their ratio, the largest relative difference of the normal force, and
whether each ran on the compiled path (``stats["compiled_modes"]``, ``fallback_modes``).
"""

from __future__ import annotations

import argparse
import copy
import sys
import tomllib
import warnings
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from scene_cost import report  # noqa: E402
from timing import interleaved  # noqa: E402

from contactdyn import parse_scene, simulate  # noqa: E402

SCENE = Path(__file__).resolve().parent.parent / "examples" / "impedance_press.toml"


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--repeats", type=int, default=7)
    p.add_argument("--out")
    args = p.parse_args(argv)
    doc = tomllib.loads(SCENE.read_text())
    twin = copy.deepcopy(doc)
    twin["controller"] = {"kind": "task_pd", "kp": 2000.0, "kd": 100.0, "feedforward": "gravity"}
    scenes = {"user_impedance": parse_scene(doc, file=str(SCENE)),
              "builtin_task_pd": parse_scene(twin, file=str(SCENE))}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        for s in scenes.values():
            simulate(s)  # untimed
        times = interleaved({k: (lambda s=s: simulate(s)) for k, s in scenes.items()}, args.repeats)
    mine, twin_r = times["user_impedance"].last, times["builtin_task_pd"].last
    F, G = mine["contact.tip.F_n"], twin_r["contact.tip.F_n"]
    rows = [{"law": k, "cpu_s": times[k].cpu, "ratio_to_builtin": times[k].cpu / times["builtin_task_pd"].cpu,
             "compiled_modes": times[k].last.stats["compiled_modes"], "fallbacks": str(times[k].last.stats[
                 "fallback_modes"]), "max_rel_diff_F": float(abs(F - G).max() / abs(G).max())} for k in scenes]
    report(rows, args.out)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
