"""Where the 5-DOF writer's integration steps go, and what bounds them.

    PYTHONPATH=. python3 benchmarks/writer_steps.py [--scene case2_writer5dof] [--switch 3.7]

1. **Steps per time window** (press, stuck drawing, the 2-D launch, the steady slide, the
   deceleration, the last 0.1 s before the final stop) at rtol 1e-6, 1e-7 (the scene's) and 1e-8:
   a window whose count follows the tolerance is accuracy-bound, one that does not is
   stability-bound.
2. **The fastest mode** at a few times of the slide: the eigenvalue λ [1/s] of the right-hand
   side's finite-difference Jacobian of largest modulus, the step h [s] taken there and h|λ|,
   with Coulomb's μ as in the scene and with μ = 0 (no friction); DOP853's stability limit on
   the negative real axis (computed from its Butcher tableau) for comparison.
3. **What if** the segments from ``--switch`` [s] on (the circle's deceleration corner) ran on
   LSODA, the method the launch from rest already uses: steps, right-hand-side calls, CPU [s]
   and the errors against the rtol 1e-11 reference (:func:`scenes.errors`), the scene's own
   DOP853C run beside it. (A run-time experiment: a subclass of the hybrid loop picks the method.)

Writes benchmarks/out/writer_steps.json.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np
from scipy.integrate._ivp import dop853_coefficients as dop

sys.path.insert(0, str(Path(__file__).resolve().parent))
from scenes import errors  # noqa: E402

from contactdyn.hybrid.loop import HybridRun  # noqa: E402
from contactdyn.model.system import System  # noqa: E402
from contactdyn.numerics.integrators import jacobian_eigenvalues  # noqa: E402
from contactdyn.scene.scene_file import load_scene  # noqa: E402

OUT = Path(__file__).parent / "out"
WINDOWS = (0.0, 0.5, 0.715, 1.5, 3.7, 4.4, 4.49, 4.5)  #: [s] press | stuck | launch | slide | decel | tail
PROBES = (2.0, 3.0, 4.3, 4.45, 4.49)  #: [s] where the fastest mode is computed


class _Recorded(HybridRun):
    """The hybrid loop, keeping each segment's (solution, right-hand side); from ``switch`` [s]
    on, segments run on ``method``."""

    def __init__(self, system, switch: float | None = None, method: str = "LSODA"):
        super().__init__(system)
        self.switch, self.switch_method, self.record, self._t0 = switch, method, [], 0.0

    def _segment(self, t, t_end, x, modes, phase, t_sample=None):
        self._t0 = t
        sol, events, fun, held = super()._segment(t, t_end, x, modes, phase, t_sample)
        self.record.append((sol, fun))
        return sol, events, fun, held

    def _method(self, modes, method):
        if self.switch is not None and self._t0 >= self.switch:
            return self.switch_method
        return super()._method(modes, method)


def run(scene: str, overrides: dict | None = None, switch: float | None = None):
    """(Result, recorder, CPU [s]) of one run."""
    system = System(load_scene(scene, overrides))
    loop = _Recorded(system, switch)
    c0 = time.process_time()
    result = loop.run(time.perf_counter())
    return result, loop, time.process_time() - c0


def windows(loop) -> list[int]:
    """Accepted steps per WINDOWS interval."""
    ends = np.concatenate([np.asarray(sol.t)[1:] for sol, _ in loop.record])
    return np.histogram(ends, WINDOWS)[0].tolist()


def fastest_modes(loop) -> list[dict]:
    """At each PROBES time: the step there, the fastest eigenvalue and h|λ|."""
    out = []
    for tq in PROBES:
        for sol, fun in loop.record:
            t = np.asarray(sol.t)
            if t[0] < tq < t[-1]:
                k = int(np.searchsorted(t, tq))
                lam = jacobian_eigenvalues(fun, t[k], sol.y[:, k])
                top = lam[np.argmax(np.abs(lam))]
                h = float(t[k + 1] - t[k])
                out.append({"t": float(t[k]), "h": h, "lambda_re": float(top.real), "lambda_im": float(top.imag),
                            "h_abs_lambda": h * float(abs(top))})
    return out


def dop853_real_limit() -> float:
    """Where |R(z)| = 1 on the negative real axis for DOP853 (its 12 stages, eighth-order weights)."""
    A, B = dop.A[:12, :12], dop.B

    def amplification(z: float) -> float:
        k = np.linalg.solve(np.eye(12) - z * A, z * np.ones(12))
        return abs(1.0 + B @ k)

    lo, hi = -1.0, -10.0  # |R| < 1 at lo, > 1 at hi
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if amplification(mid) < 1.0 else (lo, mid)
    return lo


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--scene", default="case2_writer5dof")
    p.add_argument("--switch", type=float, default=3.7, help="[s] segments from here on run on LSODA (what-if)")
    args = p.parse_args(argv)
    report: dict = {"scene": args.scene, "windows_s": WINDOWS, "dop853_real_axis_limit": dop853_real_limit()}
    print(f"DOP853 stability limit on the negative real axis: h|λ| = {-report['dop853_real_axis_limit']:.2f}")
    print("steps per window [s]: " + " | ".join(f"{a}-{b}" for a, b in zip(WINDOWS[:-1], WINDOWS[1:], strict=True)))
    report["rtol"] = {}
    for rtol in (1e-6, 1e-7, 1e-8):
        result, loop, _ = run(args.scene, {"solver.rtol": rtol})
        report["rtol"][f"{rtol:g}"] = {"steps": result.stats["steps"], "windows": windows(loop)}
        print(f"  rtol {rtol:g}: {result.stats['steps']} steps: {windows(loop)}")
    report["modes"] = {}
    for label, ov in (("scene", {}), ("mu=0", {"contact.pencil.tangent.mu": 0.0})):
        _, loop, _ = run(args.scene, ov)
        report["modes"][label] = modes = fastest_modes(loop)
        print(f"fastest mode ({label}): " + "; ".join(
            f"t={m['t']:.3f} s λ={m['lambda_re']:.0f}{m['lambda_im']:+.0f}i h={m['h']:.2e} h|λ|={m['h_abs_lambda']:.2f}"
            for m in modes))
    ref, _, _ = run(args.scene, {"solver.rtol": 1e-11, "solver.atol": 1e-13})
    report["what_if"] = {}
    for label, switch in (("scene (DOP853C)", None), (f"LSODA from {args.switch:g} s", args.switch)):
        result, loop, cpu = run(args.scene, switch=switch)
        err = errors(result, ref)
        row = {"steps": result.stats["steps"], "calls": result.stats["rhs_evals"], "cpu_s": cpu,
               "windows": windows(loop), "force_err_N": err["force_all"], "tip_err_m": err["tip_all"],
               "segments_by_method": result.stats["segments_by_method"]}
        report["what_if"][label] = row
        print(f"{label:22s} steps {row['steps']:5d} calls {row['calls']:6d} CPU {cpu:.2f} s "
              f"F_n error {row['force_err_N']:.2e} N tip error {row['tip_err_m']:.2e} m {row['windows']}")
    OUT.mkdir(exist_ok=True)
    (OUT / "writer_steps.json").write_text(json.dumps(report, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
