"""Case 1 (the cart): what holds the step, and cost against error for a few step settings.

For each setting of ``solver.max_step`` (and rtol) the full scene is run ``--repeats`` times,
interleaved with the hand-written closed-form B1 (``b1_reference.run``, the issue's yardstick);
reported: steps, right-hand-side calls, CPU ms per simulated second and its ratio to the
hand-written model's (medians), and the force / tip / stage errors against the rtol 1e-11
reference of ``scenes.py`` (whose own check difference is printed: an error below it is not
resolved). Then the Jacobian's eigenvalues at one state of each phase: the fastest decaying
modes are what an explicit method's step must stay stable on (DOP853: |h λ| ≲ 6).

    PYTHONPATH=. python3 benchmarks/case1_steps.py [--repeats 3]

Prints a table; writes benchmarks/out/case1_steps.json.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import b1_reference
from rhs_cost import _mode_at
from scenes import CHECK, REFERENCE, errors
from timing import interleaved, write_report

from contactdyn import simulate
from contactdyn.hybrid.pipeline_mode import PipelineMode
from contactdyn.model.pipeline.pipeline import Pipeline
from contactdyn.numerics.integrators import jacobian_eigenvalues
from contactdyn.scene.scene_file import load_scene

SCENE = "case1_cart"
OUT = Path(__file__).parent / "out" / "case1_steps.json"
#: the scene's default first; then max_step 6 ms, 12 ms (inside the cart servo's -500 1/s stability bound
#: of ~12 ms) and none (the integrator's own choice)
SETTINGS = {
    "default": {},
    "max_step 6 ms": {"solver.max_step": 6e-3},
    "max_step 12 ms": {"solver.max_step": 1.2e-2},
    "no max_step": {"solver.max_step": float("inf")},
    "no max_step, rtol 1e-10": {"solver.max_step": float("inf"), "solver.rtol": 1e-10, "solver.atol": 1e-12},
}
PHASE_TIMES = (0.5, 2.0)  #: [s] one state in the approach, one in the push


def eigenvalues(at: float, n_show: int = 4) -> list[complex]:
    """The fastest eigenvalues [1/s] of the one pipeline's finite-difference Jacobian at ``at``."""
    system, modes, phase, t, x = _mode_at(load_scene(SCENE), at)
    lam = jacobian_eigenvalues(PipelineMode(Pipeline(system, modes, phase)).rhs, t, x)
    return sorted(lam, key=lambda w: -abs(w))[:n_show]


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args(argv)
    ref, check = simulate(SCENE, REFERENCE), simulate(SCENE, CHECK)
    own = errors(check, ref)
    duration = load_scene(SCENE).duration
    variants = {"hand-written B1": b1_reference.run}
    variants.update({name: (lambda ov=ov: simulate(SCENE, ov)) for name, ov in SETTINGS.items()})
    times = interleaved(variants, args.repeats)
    hw_ms = times["hand-written B1"].cpu / b1_reference.T_END * 1e3
    rows = []
    print(f"reference self-check: force {own['force_all']:.1e} N, tip {own['tip_all']:.1e} m, "
          f"stage {own['stage_all']:.1e} m; hand-written B1 {hw_ms:.1f} ms CPU per simulated s")
    print("| setting | steps | rhs calls | ms CPU / sim. s | × hand-written | force err [N] | tip err [m] | "
          "stage err [m] |")
    print("|---|---|---|---|---|---|---|---|")
    for name in SETTINGS:
        run = times[name].last
        ms = times[name].cpu / duration * 1e3
        e = errors(run, ref)
        rows.append({"setting": name, "overrides": {k: str(v) for k, v in SETTINGS[name].items()},
                     "steps": run.stats["steps"], "rhs_evals": run.stats["rhs_evals"], "ms_cpu_per_s": ms,
                     "ratio_hand_written": ms / hw_ms, **{f"err_{k}": v for k, v in e.items()}})
        print(f"| {name} | {run.stats['steps']} | {run.stats['rhs_evals']} | {ms:.0f} | {ms / hw_ms:.1f} | "
              f"{e['force_all']:.1e} | {e['tip_all']:.1e} | {e['stage_all']:.1e} |")
    modes = {}
    for at in PHASE_TIMES:
        lam = eigenvalues(at)
        modes[str(at)] = [[w.real, w.imag] for w in lam]
        print(f"fastest modes at t = {at} s [1/s]: " + ", ".join(f"{w.real:.0f}{w.imag:+.0f}j" for w in lam))
    write_report(OUT, {"scene": SCENE, "repeats": args.repeats, "hand_written_ms_per_s": hw_ms,
                       "reference_check": own, "fastest_modes": modes}, rows)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
