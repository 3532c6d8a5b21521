"""The README's example laws against their built-in twins on the same scene, in one process.

    PYTHONPATH=. python3 benchmarks/user_law_cost.py [--repeats 7] [--out FILE.json]

Three pairs, each the same run to within the solver's tolerance: examples/my_laws.py's impedance
controller vs ``task_pd`` (kp = K, kd = D, gravity feedforward) on examples/impedance_press.toml;
examples/cubic_stage.py's cubic law with k3 = 0 vs the linear law on examples/cubic_press.toml;
the Stribeck friction law with v_s = 1e-9 m/s (μ = μ_k once moving) vs Coulomb on B1 with μ_s = 0.6,
μ_k = 0.4. Timed interleaved after an untimed run each; CPU medians, each law's ratio to its twin,
the largest relative difference of the normal force, and the path each law's modes ran on
(``stats["paths"]``: every mode on the one pipeline's compiled call, a law numba cannot compile a Python stage in
it). Each law also runs with the one pipeline interpreted (``LivePipelines.use = False``: every mode on the same call
run as its Python twins), in the same interleaved rounds: ``off_cpu_s`` and ``off_ratio`` (to the twin),
``off_paths``. ("Twin" here
is the built-in law a user law is compared with, not the deleted probed twin.)
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
from contactdyn.model.paths import LivePipelines  # noqa: E402

EXAMPLES = Path(__file__).resolve().parent.parent / "examples"
SIMS = Path(__file__).resolve().parent.parent / "sims"


def pairs() -> dict[str, tuple]:
    """law -> (its scene, its twin's scene), parsed."""
    imp = tomllib.loads((EXAMPLES / "impedance_press.toml").read_text())
    imp_twin = copy.deepcopy(imp)
    imp_twin["controller"] = {"kind": "task_pd", "kp": 2000.0, "kd": 100.0, "feedforward": "gravity"}
    cubic = tomllib.loads((EXAMPLES / "cubic_press.toml").read_text())
    cubic["contact"]["tip"]["normal"]["k3"] = 0.0
    linear = copy.deepcopy(cubic)
    del linear["contact"]["tip"]["normal"]["k3"], linear["contact"]["tip"]["normal"]["law"]
    b1 = tomllib.loads((SIMS / "b1.toml").read_text())
    tangent = {"model": "friction", "directions": [[1.0, 0.0, 0.0]], "mu_s": 0.6, "mu_k": 0.4}
    stribeck, coulomb = copy.deepcopy(b1), copy.deepcopy(b1)
    stribeck["contact"]["tip"]["tangent"] = {**tangent, "law": "stribeck", "v_s": 1e-9}
    coulomb["contact"]["tip"]["tangent"] = tangent

    def parsed(doc, file):
        return parse_scene(doc, file=str(file))

    return {"impedance (user controller) vs task_pd": (parsed(imp, EXAMPLES / "impedance_press.toml"),
                                                       parsed(imp_twin, EXAMPLES / "impedance_press.toml")),
            "cubic (user stage law, k3 = 0) vs linear": (parsed(cubic, EXAMPLES / "cubic_press.toml"),
                                                         parsed(linear, EXAMPLES / "cubic_press.toml")),
            "stribeck (v_s = 1e-9) vs coulomb on b1": (parsed(stribeck, SIMS / "b1.toml"),
                                                       parsed(coulomb, SIMS / "b1.toml"))}


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--repeats", type=int, default=7)
    p.add_argument("--out")
    args = p.parse_args(argv)
    scenes = {}
    for name, (law, twin) in pairs().items():
        scenes[(name, "law")], scenes[(name, "twin")], scenes[(name, "off")] = law, twin, law
    runs = {k: (lambda s=s, off=k[1] == "off": _simulate(s, pipeline=not off)) for k, s in scenes.items()}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        for run in runs.values():
            run()  # untimed
        times = interleaved(runs, args.repeats)
    rows = []
    for name in pairs():
        law, twin, off = times[(name, "law")], times[(name, "twin")], times[(name, "off")]
        F, G = law.last["contact.tip.F_n"], twin.last["contact.tip.F_n"]
        rows.append({"pair": name, "law_cpu_s": law.cpu, "twin_cpu_s": twin.cpu, "ratio": law.cpu / twin.cpu,
                     "max_rel_diff_F": float(abs(F - G).max() / abs(G).max()),
                     "law_paths": sorted({r["path"] for r in law.last.stats["paths"].values()}),
                     "twin_paths": sorted({r["path"] for r in twin.last.stats["paths"].values()}),
                     "off_cpu_s": off.cpu, "off_ratio": off.cpu / twin.cpu,
                     "off_paths": sorted({r["path"] for r in off.last.stats["paths"].values()})})
    report(rows, args.out)
    return 0


def _simulate(scene, pipeline: bool):
    """simulate(scene) with the one pipeline compiled or interpreted (contactdyn.model.paths.LivePipelines)."""
    LivePipelines.use = pipeline
    try:
        return simulate(scene)
    finally:
        LivePipelines.use = True


if __name__ == "__main__":
    raise SystemExit(main())
