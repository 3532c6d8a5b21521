"""What a declared Python stage costs per call: one compiled right-hand-side call of a mode whose stage law numba
cannot compile (called back through ctypes, contactdyn.laws.abi) against the same mode with the built-in linear law.

    PYTHONPATH=. python3 benchmarks/python_stage_cost.py [--repeats 7] [--calls 20000] [--out FILE.json]

The scene: tests/test_python_stages.py's bonded chain, anchor —[law]— mass —[linear]— surface, touching, with the
energy audit (each stage's force also at ẋ = 0: two callbacks per call). The laws: ``linear`` (compiled, by address),
``python_linear`` (the same F = k x + b ẋ reading a Python dict: a Python stage), and, for scale, the readable model
(``contactdyn.model.dynamics.evaluate``) of the Python-stage mode. Each variant times ``--calls`` calls of
``Pipeline.rhs`` at the same state; the variants interleaved ``--repeats`` times in one process, CPU medians [µs per
call], each ratio to ``linear``.
"""

from __future__ import annotations

import argparse
import statistics
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from timing import interleaved, write_report  # noqa: E402

from contactdyn import parse_scene  # noqa: E402
from contactdyn.laws.stage_laws import StageLaw, register_stage_law  # noqa: E402
from contactdyn.model import dynamics  # noqa: E402
from contactdyn.model.pipeline.pipeline import Pipeline  # noqa: E402
from contactdyn.simulate import prepare  # noqa: E402

K, B = 5e4, 1500.0  #: [N/m], [N·s/m]
_SCALE = {"k": 1.0}  #: a Python dict: numba cannot type it


@register_stage_law
class PythonLinear(StageLaw):
    """F = k x + b ẋ through a dict: a declared Python stage."""

    name, affine = "python_linear", True

    @staticmethod
    def force(k, b, p, x, xdot):
        return _SCALE["k"] * k * x + b * xdot


def bonded(law: str):
    chain = {"model": "chain", "environment": [{"k": K, "b": B, "law": law}, {"m": 2.0}, {"k": 2 * K, "b": 2 * B}]}
    return parse_scene({
        "duration": 0.01, "solver": {"rtol": 1e-10, "atol": 1e-13, "record_energy": True},
        "robot": {"urdf": "cylindrical3", "active_joints": ["q3"], "gravity": [0.0, 0.0, -9.81], "q0": [1.0],
                  "v0": [0.3]},
        "contact": {"tip": {"point": [1.0, 0.0, 0.2], "normal": {"direction": [0, 0, 1], **chain},
                            "bonded": True}},
        "controller": {"kind": "task_pd", "kp": 0.0, "kd": 0.0, "axes": [[1.0, 0.0, 0.0]]},
    })


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--repeats", type=int, default=7)
    p.add_argument("--calls", type=int, default=20000)
    p.add_argument("--out")
    args = p.parse_args(argv)
    variants, stages = {}, {}
    for law in ("linear", "python_linear"):
        system, modes, phase, x = prepare(bonded(law))
        x = x.copy()
        x[system.nv] += 1e-4  # the mass moved [m]: both stages loaded
        pipe = Pipeline(system, modes, phase)
        stages[law] = pipe.python_stages
        pipe.rhs(0.0, x)  # compiled, or loaded, before timing
        variants[law] = (lambda pipe=pipe, x=x, n=args.calls: [pipe.rhs(0.0, x) for _ in range(n)][-1])
        if law == "python_linear":
            n_readable = max(args.calls // 20, 1)
            variants["readable"] = (lambda s=system, m=modes, ph=phase, x=x, n=n_readable:
                                    [dynamics.evaluate(s, 0.0, x, m, ph) for _ in range(n)][-1].xdot)
    times = interleaved(variants, args.repeats)
    calls = {"linear": args.calls, "python_linear": args.calls, "readable": max(args.calls // 20, 1)}
    us = {k: 1e6 * statistics.median(t.cpu_s) / calls[k] for k, t in times.items()}
    diff = float(abs(times["python_linear"].last - times["linear"].last).max())
    rows = [{"variant": k, "us_per_call": round(v, 3), "ratio_to_linear": round(v / us["linear"], 3),
             "python_stages": stages.get(k, [])} for k, v in us.items()]
    for row in rows:
        print(f"{row['variant']:>14}: {row['us_per_call']:9.3f} µs/call  ×{row['ratio_to_linear']:.2f} linear")
    print(f"python_linear vs linear: max |Δẋ| = {diff:.3g}")
    if args.out:
        write_report(Path(args.out), {"calls": args.calls, "repeats": args.repeats, "max_abs_diff_xdot": diff}, rows)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
