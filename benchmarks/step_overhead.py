"""Where B1's time goes: right-hand side, the integrator's own work per step, output sampling.

    PYTHONPATH=. python3 benchmarks/step_overhead.py [--repeats 7] [--rtols 1e-6,1e-7,1e-8]
    PYTHONPATH=. python3 benchmarks/step_overhead.py --baseline TREE [--repeats 5] [--inner 1] [--rtols ...]

For each rtol (atol = rtol/100) and each integrator (``solve_ivp``'s DOP853, the compiled
``DOP853C`` of contactdyn.numerics.dop853), B1 is run on a built system (``run_system``: no robot
loading) at its 1 kHz output and again at 10 Hz output; the hand-written closed-form B1
(``b1_reference.run``, scipy's ``solve_ivp`` DOP853 — the issue's "hand-written floor") and
the same closed form on the compiled integrator run in the same loop. All variants are
interleaved, repeat by repeat; times are medians of process CPU time (see CLOCK). Split of one run:

- rhs [ms] = time spent inside the compiled call's right-hand side (the one pipeline's, as the loop
  wraps it: ``PipelineMode.rhs``), summed call by call in a separate instrumented run of the same
  system (the timer's own cost, measured on an empty function, is taken off both sides; the timed
  right-hand side has no ``step`` attribute, so DOP853C calls it per stage there instead of taking a
  whole step in one compiled call);
- output [ms] = CPU time at 1 kHz − CPU time at 10 Hz (sampling the channels, and for DOP853C the
  interpolants it builds only for steps that hold samples);
- integrator [µs per step] = (CPU time at 10 Hz − rhs) / accepted steps, both from the instrumented
  run: step control, error norm, stage sums, dense output, event tests, segment bookkeeping.

Errors: B1.md's F_n error against the hand-written model at rtol 1e-13. Writes
benchmarks/out/step_overhead.json.

``--baseline TREE``: before/after. The measurement (``--inner`` repeats) runs alternately in
child processes importing ``contactdyn`` from TREE (e.g. an export of ``main``) and from this
tree, ``--repeats`` times each (:mod:`before_after`); the hand-written model is this tree's in
both. Prints DOP853C's CPU time before and after, medians over the children, against the
hand-written model's median over all children; writes benchmarks/out/step_overhead_before_after.json.
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from before_after import HERE, alternate, use_tree  # noqa: E402

use_tree()

import b1_reference  # noqa: E402
import numpy as np  # noqa: E402

import contactdyn.hybrid.loop as hybrid  # noqa: E402
from contactdyn.hybrid.pipeline_mode import PipelineMode  # noqa: E402
from contactdyn.model.system import System  # noqa: E402
from contactdyn.numerics import dop853  # noqa: E402
from contactdyn.scene.scene_file import load_scene  # noqa: E402
from contactdyn.simulate import run_system  # noqa: E402

OUT = Path(__file__).parent / "out"
#: process CPU time: the 2-core machine is shared (load average up to 7 while measuring), and
#: wall time would measure the others; a run is single-threaded, so its CPU time is its cost
CLOCK = time.process_time
METHODS = ("DOP853", "DOP853C")
SPARSE_RATE = 10.0  #: [Hz] output rate of the run without (almost) any output


class _Timed:
    """A right-hand side that sums the time spent inside it [s]."""

    def __init__(self, fun):
        self.fun, self.inside, self.calls = fun, 0.0, 0

    def __call__(self, t, x):
        t0 = CLOCK()
        out = self.fun(t, x)
        self.inside += CLOCK() - t0
        self.calls += 1
        return out


def _timer_cost() -> float:
    """[s] what wrapping one call in _Timed adds (measured on an empty function)."""
    timed = _Timed(lambda t, x: x)
    t0 = CLOCK()
    for _ in range(20000):
        timed(0.0, None)
    return (CLOCK() - t0 - timed.inside) / 20000


def _instrumented(system: System) -> tuple[float, float, int]:
    """(CPU time [s], time inside the rhs [s], rhs calls) of one run with every compiled mode's rhs timed (each run
    builds its own modes, :class:`~contactdyn.model.paths.LivePipelines`: the loop's wrap is swapped for one that
    times the wrapped mode's ``rhs``)."""
    run_system(system)  # compiles the pipeline (numba's cache)
    timers = []

    def timed_mode(pipe):
        mode = PipelineMode(pipe)
        timers.append(_Timed(mode.rhs))
        mode.rhs = timers[-1]
        return mode

    hybrid.PipelineMode = timed_mode
    try:
        t0 = CLOCK()
        run_system(system)
        wall = CLOCK() - t0
    finally:
        hybrid.PipelineMode = PipelineMode
    return wall, sum(t.inside for t in timers), sum(t.calls for t in timers)


def _hand_compiled(rtol: float, atol: float) -> dict:
    """The closed-form B1 on the compiled integrator (same sampling as b1_reference.run)."""
    t0 = CLOCK()
    sol = dop853.solve(b1_reference.rhs, (0.0, b1_reference.T_END), [*b1_reference.Q0, *b1_reference.QD0],
                       rtol=rtol, atol=atol)
    t = np.linspace(0.0, b1_reference.T_END, b1_reference.N_OUT)
    states = sol.sol(t)
    fn, xt = np.empty(len(t)), np.empty(len(t))
    for i in range(len(t)):
        _, _, fn[i], xt[i], _ = b1_reference.accelerations(t[i], *states[:, i])
    return {"t": t, "x_tip": xt, "F_n": fn, "cpu_s": CLOCK() - t0, "rhs_evals": sol.nfev + sol.sol.late_calls,
            "steps": len(sol.t) - 1}


def bare_overhead(repeats: int = 5) -> dict[str, float]:
    """CPU µs per accepted step of each integrator alone: 8 states, a right-hand side that returns a
    constant array, 1000 steps of 1 s (max_step), no events, no output."""
    from scipy.integrate import solve_ivp

    const = np.ones(8)
    runs = {"DOP853": lambda: solve_ivp(lambda t, y: const, (0.0, 1000.0), np.zeros(8), method="DOP853", rtol=1e-8,
                                        atol=1e-10, max_step=1.0, dense_output=True),
            "DOP853C": lambda: dop853.solve(lambda t, y: const, (0.0, 1000.0), np.zeros(8), rtol=1e-8, atol=1e-10,
                                            max_step=1.0)}
    per_step: dict[str, list[float]] = {m: [] for m in runs}
    for _ in range(repeats):
        for m, run in runs.items():
            t0 = CLOCK()
            sol = run()
            per_step[m].append((CLOCK() - t0) / (len(sol.t) - 1) * 1e6)
    return {m: statistics.median(v) for m, v in per_step.items()}


def measure(rtol: float, repeats: int, ref: dict) -> dict:
    atol = rtol * 1e-2
    systems = {(m, rate): System(load_scene("b1", {"solver.method": m, "solver.rtol": rtol, "solver.atol": atol,
                                                    "solver.output_rate": rate}))
               for m in METHODS for rate in (1000.0, SPARSE_RATE)}
    walls: dict = {k: [] for k in [*systems, "hand", "hand_compiled"]}
    split: dict = {m: [] for m in METHODS}
    last: dict = {}
    timer = _timer_cost()
    for _ in range(repeats):
        for key, system in systems.items():
            t0 = CLOCK()
            last[key] = run_system(system)
            walls[key].append(CLOCK() - t0)
        for m in METHODS:
            wall, inside, calls = _instrumented(systems[(m, SPARSE_RATE)])
            split[m].append((wall - calls * timer - inside, inside, calls))
        t0 = CLOCK()
        last["hand"] = b1_reference.run(rtol, atol)
        walls["hand"].append(CLOCK() - t0)
        last["hand_compiled"] = _hand_compiled(rtol, atol)
        walls["hand_compiled"].append(last["hand_compiled"]["cpu_s"])
    row: dict = {"rtol": rtol, "atol": atol, "timer_us": timer * 1e6}
    for m in METHODS:
        full, sparse = last[(m, 1000.0)], last[(m, SPARSE_RATE)]
        w_full, w_sparse = statistics.median(walls[(m, 1000.0)]), statistics.median(walls[(m, SPARSE_RATE)])
        steps, nfev = sparse.stats["steps"], sparse.stats["rhs_evals"]
        outside = statistics.median(v[0] for v in split[m])
        inside = statistics.median(v[1] for v in split[m])
        e_f, _ = b1_reference.errors({"F_n": full["contact.tip.F_n"], "x_tip": full["tip"][:, 0]}, ref)
        row[m] = {"cpu_ms": w_full * 1e3, "cpu_sparse_ms": w_sparse * 1e3, "steps": steps,
                  "rhs_evals_sparse": nfev, "rhs_evals": full.stats["rhs_evals"], "rhs_ms": inside * 1e3,
                  "rhs_us_per_call": inside / max(split[m][-1][2], 1) * 1e6,
                  "output_ms": (w_full - w_sparse) * 1e3,
                  "integrator_us_per_step": outside / steps * 1e6, "F_n_error": e_f}
    for key in ("hand", "hand_compiled"):
        e_f, _ = b1_reference.errors(last[key], ref)
        row[key] = {"cpu_ms": statistics.median(walls[key]) * 1e3, "steps": last[key]["steps"],
                    "rhs_evals": last[key]["rhs_evals"], "F_n_error": e_f}
    return row


def compare(rtols: str, repeats: int, inner: int, baseline: str) -> list[dict]:
    """Before/after rows per rtol: DOP853C's CPU time and split in TREE's children and this tree's."""
    got = alternate(__file__, ["--rtols", rtols, "--repeats", str(inner)], {"baseline": baseline, "this": str(HERE)},
                    repeats)
    rows = []
    for i, first in enumerate(got["this"][0]):
        row: dict = {"rtol": first["rtol"], "repeats": repeats, "inner": inner}
        for label, runs in got.items():
            row[label] = {key: statistics.median(run[i]["DOP853C"][key] for run in runs)
                          for key in ("cpu_ms", "rhs_ms", "output_ms", "rhs_us_per_call", "integrator_us_per_step")}
            row[label].update({key: runs[-1][i]["DOP853C"][key] for key in ("steps", "rhs_evals", "F_n_error")})
        row["hand"] = {"cpu_ms": statistics.median(run[i]["hand"]["cpu_ms"] for runs in got.values() for run in runs),
                       "F_n_error": first["hand"]["F_n_error"]}
        rows.append(row)
    return rows


def _print_compare(rows: list[dict]) -> None:
    print("| rtol | before [ms] | after [ms] | speed-up | hand-written [ms] | before × hand | after × hand | "
          "rhs before/after [ms] | µs per call before/after | output before/after [ms] | "
          "rest per step before/after [µs] | steps | F_n error before/after [N] | hand-written F_n error [N] |")
    print("|---" * 14 + "|")
    for r in rows:
        b, a, hand = r["baseline"], r["this"], r["hand"]["cpu_ms"]
        cells = [f"{r['rtol']:g}", f"{b['cpu_ms']:.1f}", f"{a['cpu_ms']:.1f}", f"{b['cpu_ms'] / a['cpu_ms']:.2f}",
                 f"{hand:.1f}", f"{b['cpu_ms'] / hand:.2f}", f"{a['cpu_ms'] / hand:.2f}"]
        cells += [f"{b[key]:{fmt}} / {a[key]:{fmt}}" for key, fmt in (
            ("rhs_ms", ".1f"), ("rhs_us_per_call", ".1f"), ("output_ms", ".1f"), ("integrator_us_per_step", ".1f"),
            ("steps", "d"), ("F_n_error", ".1e"))]
        print("| " + " | ".join([*cells, f"{r['hand']['F_n_error']:.1e}"]) + " |")


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--repeats", type=int, default=7)
    p.add_argument("--rtols", default="1e-6,1e-7,1e-8")
    p.add_argument("--baseline", help="source tree to compare against (before/after)")
    p.add_argument("--inner", type=int, default=1, help="repeats inside each child of --baseline")
    p.add_argument("--json", action="store_true", help=argparse.SUPPRESS)  # a child's output
    args = p.parse_args(argv)
    if args.baseline:
        rows = compare(args.rtols, args.repeats, args.inner, args.baseline)
        _print_compare(rows)
        OUT.mkdir(parents=True, exist_ok=True)
        (OUT / "step_overhead_before_after.json").write_text(json.dumps({"baseline": args.baseline, "rows": rows},
                                                                        indent=1))
        print(f"wrote {OUT / 'step_overhead_before_after.json'}")
        return 0
    if args.json:
        ref = b1_reference.reference()
        print(json.dumps([measure(float(r), args.repeats, ref) for r in args.rtols.split(",")], default=float))
        return 0
    bare = bare_overhead()
    print("integrator alone, CPU µs per step (8 states, empty right-hand side): "
          + ", ".join(f"{m} {v:.1f}" for m, v in bare.items()))
    ref = b1_reference.reference()
    rows = [measure(float(r), args.repeats, ref) for r in args.rtols.split(",")]
    print("| rtol | integrator | CPU [ms] | × hand-written | steps | rhs evals | rhs [ms] | output [ms] | "
          "integrator [µs/step] | F_n error [N] |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    for r in rows:
        hand = r["hand"]["cpu_ms"]
        for m in METHODS:
            d = r[m]
            print(f"| {r['rtol']:g} | {m} | {d['cpu_ms']:.1f} | {d['cpu_ms'] / hand:.2f} | {d['steps']} | "
                  f"{d['rhs_evals']} | {d['rhs_ms']:.1f} | {d['output_ms']:.1f} | {d['integrator_us_per_step']:.1f} | "
                  f"{d['F_n_error']:.1e} |")
        for key, label in (("hand", "hand-written, solve_ivp"), ("hand_compiled", "hand-written, DOP853C")):
            d = r[key]
            print(f"| {r['rtol']:g} | {label} | {d['cpu_ms']:.1f} | {d['cpu_ms'] / hand:.2f} | {d['steps']} | "
                  f"{d['rhs_evals']} | | | | {d['F_n_error']:.1e} |")
        print(f"(rtol {r['rtol']:g}: one rhs call inside the run "
              + ", ".join(f"{r[m]['rhs_us_per_call']:.1f} µs ({m})" for m in METHODS) + ")")
    OUT.mkdir(parents=True, exist_ok=True)
    (OUT / "step_overhead.json").write_text(json.dumps({"repeats": args.repeats, "bare_us_per_step": bare,
                                                        "rows": rows}, indent=1))
    print(f"wrote {OUT / 'step_overhead.json'}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
