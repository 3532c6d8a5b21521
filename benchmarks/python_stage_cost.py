"""What a declared Python stage costs per call: one compiled right-hand-side call of a mode whose stage law numba
cannot compile (called back through ctypes, contactdyn.laws.abi) against the same mode with the built-in linear law;
and of a mode whose controller numba cannot compile (contactdyn.laws.controllers.abi.python_controller_address)
against its compiled twin.

    PYTHONPATH=. python3 benchmarks/python_stage_cost.py [--repeats 7] [--calls 20000] [--out FILE.json]

The scene: tests/test_python_stages.py's bonded chain, anchor —[law]— mass —[linear]— surface, touching, with the
energy audit (each stage's force also at ẋ = 0: two callbacks per call). The laws: ``linear`` (compiled, by address),
``python_linear`` (the same F = k x + b ẋ reading a Python dict: a Python stage), and, for scale, the same call
interpreted (its Python twins, :mod:`contactdyn.numerics.twins`: what ``compiled=False`` runs; once the readable
model) of the Python-stage mode. Each variant times ``--calls`` calls of
``Pipeline.rhs`` at the same state; the variants interleaved ``--repeats`` times in one process, CPU medians [µs per
call], each ratio to ``linear``.

The controller: examples/force_pi_press.toml (a bonded surface: the force-reading law folded, its callback called
once more per row) under ``force_pi`` (examples/force_law.py, compiled, by address: the twin) and
``dict_force_pi_test`` (tests/test_python_controller.py's DictForcePI: the same law reading ControlInput's
dictionaries and a Python dict, a Python stage), and the Python-stage mode's call interpreted; ratios to
``force_pi``.
"""

from __future__ import annotations

import argparse
import statistics
import sys
import tomllib
import warnings
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
from test_python_controller import DictForcePI  # noqa: E402  (the tests' scene and law: one source)
from test_python_stages import _bonded as bonded  # noqa: E402
from timing import interleaved, write_report  # noqa: E402

from contactdyn import parse_scene  # noqa: E402
from contactdyn.laws import register  # noqa: E402
from contactdyn.laws.stage_laws import StageLaw, register_stage_law  # noqa: E402
from contactdyn.model.pipeline.pipeline import Pipeline  # noqa: E402
from contactdyn.numerics.twins import Twins  # noqa: E402
from contactdyn.scene.user_laws import import_scene_modules  # noqa: E402
from contactdyn.simulate import prepare  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]

_SCALE = {"k": 1.0}  #: a Python dict: numba cannot type it


@register_stage_law
class PythonLinear(StageLaw):
    """F = k x + b ẋ through a dict: a declared Python stage."""

    name, affine = "python_linear", True

    @staticmethod
    def force(k, b, p, x, xdot):
        return _SCALE["k"] * k * x + b * xdot


def press(kind: str):
    """examples/force_pi_press.toml under controller ``kind``, its bonded surface touching."""
    path = ROOT / "examples" / "force_pi_press.toml"
    doc = tomllib.loads(path.read_text())
    doc["controller"]["kind"] = kind
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return parse_scene(doc, file=str(path))


def controller_variants(calls: int) -> tuple[dict, dict, dict]:
    """(variants, calls per variant, Python stages) of the controller comparison."""
    import_scene_modules(["force_law"], str(ROOT / "examples" / "force_pi_press.toml"))
    register(DictForcePI)
    variants, n_calls, stages = {}, {}, {}
    for kind in ("force_pi", DictForcePI.name):
        system, modes, phase, x = prepare(press(kind))
        modes = [m.with_(touching=True) for m in modes]
        pipe = Pipeline(system, modes, phase)
        stages[kind] = pipe.python_stages
        pipe.rhs(0.01, x)
        variants[kind], n_calls[kind] = (lambda pipe=pipe, x=x, n=calls: [pipe.rhs(0.01, x) for _ in range(n)][-1]), \
            calls
        if kind == DictForcePI.name:
            n_calls["interpreted_ctl"] = max(calls // 20, 1)
            slow = Pipeline(system, modes, phase, Twins())
            variants["interpreted_ctl"] = (lambda slow=slow, x=x, n=n_calls["interpreted_ctl"]:
                                           [slow.rhs(0.01, x) for _ in range(n)][-1])
    return variants, n_calls, stages


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
            n_interpreted = max(args.calls // 20, 1)
            slow = Pipeline(system, modes, phase, Twins())
            variants["interpreted"] = (lambda slow=slow, x=x, n=n_interpreted:
                                       [slow.rhs(0.0, x) for _ in range(n)][-1])
    ctl_variants, ctl_calls, ctl_stages = controller_variants(args.calls)
    times = interleaved({**variants, **ctl_variants}, args.repeats)
    calls = {"linear": args.calls, "python_linear": args.calls, "interpreted": max(args.calls // 20, 1), **ctl_calls}
    stages.update(ctl_stages)
    us = {k: 1e6 * statistics.median(t.cpu_s) / calls[k] for k, t in times.items()}
    diff = float(abs(times["python_linear"].last - times["linear"].last).max())
    ctl_diff = float(abs(times[DictForcePI.name].last - times["force_pi"].last).max())
    rows = []
    for k, v in us.items():
        base = "force_pi" if k in ctl_variants else "linear"
        rows.append({"variant": k, "us_per_call": round(v, 3), "ratio_to": base, "ratio": round(v / us[base], 3),
                     "python_stages": stages.get(k, [])})
        print(f"{k:>14}: {v:9.3f} µs/call  ×{v / us[base]:.2f} {base}")
    print(f"python_linear vs linear: max |Δẋ| = {diff:.3g}; {DictForcePI.name} vs force_pi: max |Δẋ| = {ctl_diff:.3g}")
    if args.out:
        write_report(Path(args.out), {"calls": args.calls, "repeats": args.repeats, "max_abs_diff_xdot": diff,
                                      "max_abs_diff_xdot_controller": ctl_diff}, rows)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
