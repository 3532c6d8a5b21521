"""Where a compiled call's time goes: the one pipeline's call, stage by stage, in CPU cycles (a steadier clock).

    PYTHONPATH=. python3 benchmarks/call_cycles.py [SCENE[@T] ...] [--calls 2000] [--repeats 40] [--out FILE.csv]
    PYTHONPATH=. python3 benchmarks/call_cycles.py [SCENE ...] --baseline TREE

On this shared machine a run's wall and CPU times move by tens of per cent with the hour, and a cProfile cannot see
inside compiled code. Here the package's compiled call (:func:`contactdyn.model.pipeline.pipeline.call`, as a step
calls it) is timed by the processor's time-stamp counter (LLVM's ``readcyclecounter``: ``rdtsc`` on x86), and so is a
copy of its source with the counter read after each stage (:data:`STAGES`: the statement that ends the stage),
compiled beside it. Both run ``--calls`` times in a compiled loop on the scene's state, in ``--repeats`` alternated
rounds; each figure is the round with the fewest cycles per call (the least disturbed one: another tenant only ever
adds cycles). ``plain`` is the package's call, ``stamped`` the copy's total: their difference is what the stamps
cost. A stage's cycles include what its arrays cost (allocation, reference counts). Cycles become µs at the
counter's rate, measured against ``time.perf_counter``.

Default scenes: b1 (2 DOF, one model-(b) contact with Coulomb friction, task PD), the real cell (sampled hybrid law,
DC motors, joint friction), the 5-DOF writer and case 1's cart. ``SCENE@T``: the mode the run is in at T [s]
(``rhs_cost.py``'s). ``--baseline TREE``: before/after in this one process: TREE's package (e.g. an export of
``main``) imported beside this tree's as ``contactdyn_baseline`` (a copy in a temporary folder), both calls
compiled, and each round runs both, alternated; per stage before, after and after / before. (Across processes the
fewest cycles move by ±15 % with the machine's state; within one, by ~1 %.) Writes benchmarks/out/call_cycles.json
and .csv.
"""

from __future__ import annotations

import argparse
import csv
import hashlib
import importlib
import inspect
import shutil
import statistics
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

import numba  # noqa: E402
import numpy as np  # noqa: E402
from llvmlite import ir  # noqa: E402
from numba import types  # noqa: E402
from numba.extending import intrinsic  # noqa: E402
from rhs_cost import _mode_at, _scene_at  # noqa: E402
from timing import write_report  # noqa: E402

OUT = Path(__file__).parent / "out"
SCENES = ("b1", "force_loop_real_cell", "case2_writer5dof", "case1_cart")
BASELINE = "contactdyn_baseline"  #: the name --baseline's package is imported as
#: (stage, a text of the statement of pipeline.call that ends it), in the call's order
STAGES = (
    ("robot terms", "H, h, g, Jw, W = robot_terms("),
    ("rotors reflected", "M, Hc = inertias("),
    ("frames", "FJ, Fa, Fp, Fv, FR = frame_terms("),
    ("forces on Q", "M = add_riding("),
    ("arrays", "pending = np.zeros("),
    ("contacts", "if not contact_terms("),
    ("limit and joint rows", "joint_rows(x, ints, reals, first_joint"),
    ("robot part", "Hr, hr, gr, FJr = robot_part("),
    ("controller", '"pipeline.controller"'),
    ("joint torques", "joint_torques(x, ints, reals, f)"),
    ("drives and solve", '"pipeline.solve"'),
    ("rates", "put(xdot, 2 * nQ, ydot)"),
    ("events", "joint_events(x, ints, reals, lam"),
    ("energy, record", "events[events.size - 1] = 0.0 if outcome"),
)


@intrinsic
def cycles(typingctx):
    """The time-stamp counter [cycles]."""
    def codegen(context, builder, signature, args):
        fn = builder.module.declare_intrinsic("llvm.readcyclecounter", fnty=ir.FunctionType(ir.IntType(64), []))
        return builder.call(fn, [])
    return types.uint64(), codegen


def _statement_ends(lines: list[str], start: int) -> int:
    """The index of the last line of the statement that starts at lines[start] (brackets balanced)."""
    depth, i = 0, start
    while True:
        code = lines[i].split("#")[0]
        depth += sum(code.count(c) for c in "([{") - sum(code.count(c) for c in ")]}")
        if depth <= 0 and not code.rstrip().endswith("\\"):
            return i
        i += 1


def _indent(line: str) -> int:
    return len(line) - len(line.lstrip())


def _block_ends(lines: list[str], header: int, indent: int) -> int:
    """The index of the last line of the block after lines[header] (an if's last line): the lines indented deeper
    than ``indent``, the if's own."""
    end = header
    while end + 1 < len(lines) and _indent(lines[end + 1]) > indent:
        end += 1
    return end


def stamped_call(pipeline):
    """``pipeline.call``'s source (a module of a tree) with the counter read after each of STAGES into ``acc``,
    compiled."""
    lines = inspect.getsource(pipeline.call.py_func).splitlines()[1:]  # (without the decorator)
    lines[0] = lines[0].replace("events):", "events, acc):")
    if not lines[0].endswith("acc):"):
        raise SystemExit(f"pipeline.call's signature changed: {lines[0]!r}; update call_cycles.py")
    out, k, i = [], 0, 0
    while i < len(lines):
        line = lines[i]
        if line.strip() == "while True:":
            out.append(line.replace("while True:", "_c0 = cycles()"))
        found = k < len(STAGES) and STAGES[k][1] in line and not line.lstrip().startswith("#")
        end = _statement_ends(lines, i) if found else i
        if found and lines[end].rstrip().endswith(":"):  # (an if: the stamp after its block)
            end = _block_ends(lines, end, _indent(line))
        out.extend(lines[i:end + 1])
        if found:
            out.append(f"{' ' * _indent(line)}_c = cycles(); acc[{k}] += _c - _c0; _c0 = _c")
            k += 1
        i = end + 1
    if k != len(STAGES):
        raise SystemExit(f"pipeline.call: stage {STAGES[k][0]!r} ({STAGES[k][1]!r}) not found; update call_cycles.py")
    namespace = {**vars(pipeline), "cycles": cycles}
    exec("\n".join(out).replace('"""', "'''"), namespace)  # noqa: S102 (our own source, stamped)
    return numba.njit(namespace["call"])


class Tree:
    """One source tree's package (this one's ``contactdyn``, or a baseline's): its call, plain and stamped, and the
    state of a scene's mode to call it at."""

    def __init__(self, package: str):
        self.package = package
        self.pipeline = importlib.import_module(f"{package}.model.pipeline.pipeline")
        stamped, call = stamped_call(self.pipeline), self.pipeline.call

        @numba.njit
        def plain_loop(n, t, x, ints, reals, work, events):
            s, c0 = 0.0, cycles()
            for _ in range(n):
                s += call(t, x, ints, reals, work, events)[0]
            return cycles() - c0, s

        @numba.njit
        def stamped_loop(n, t, x, ints, reals, work, events, acc):
            s, c0 = 0.0, cycles()
            for _ in range(n):
                s += stamped(t, x, ints, reals, work, events, acc)[0]
            return cycles() - c0, s

        self.plain_loop, self.stamped_loop = plain_loop, stamped_loop

    def _module(self, name: str):
        return importlib.import_module(f"{self.package}.{name}")

    def arguments(self, name: str) -> tuple:
        """(t, x, ints, reals, work, events, n) of the mode a scene's run is in at T [s] (``SCENE@T``; else its
        first: rhs_cost's ``_mode_at``, by this tree's package)."""
        scene_name, at = _scene_at(name)
        scene = self._module("scene.scene_file").load_scene(scene_name)
        system, modes, phase, t, x = _mode_at(scene, at, self.package)
        p = self._module("hybrid.pipeline_mode").mode_runner(system)(modes, phase).pipe.packed
        return float(t), np.ascontiguousarray(x, dtype=float), p.ints, p.reals, p.work, p.events, system.n


def baseline_package(tree: str) -> str:
    """``tree``'s package imported as BASELINE: a copy in a temporary folder (one per tree: its compiled code cached
    for the next comparison, the files' times copied), its sims/ and urdf/ beside it."""
    key = hashlib.sha1(str(Path(tree).resolve()).encode()).hexdigest()[:10]
    root = Path(tempfile.gettempdir()) / f"call_cycles_{key}"
    shutil.rmtree(root, ignore_errors=True)
    shutil.copytree(Path(tree) / "contactdyn", root / BASELINE, ignore=shutil.ignore_patterns("__pycache__"))
    for folder in ("sims", "urdf"):
        if (Path(tree) / folder).is_dir():
            shutil.copytree(Path(tree) / folder, root / folder)
    sys.path.insert(0, str(root))
    return BASELINE


def counter_rate() -> float:
    """[cycles/s] of the time-stamp counter, against perf_counter over ~0.2 s."""
    @numba.njit
    def now():
        return cycles()
    now()
    rates = []
    for _ in range(5):
        c0, t0 = now(), time.perf_counter()
        time.sleep(0.04)
        rates.append((now() - c0) / (time.perf_counter() - t0))
    return statistics.median(rates)


def measure(name: str, trees: dict[str, Tree], calls: int, repeats: int) -> dict:
    """Per tree, the fewest cycles per call of its plain call and per stage of its stamped one, the trees alternated
    round by round."""
    args = {key: tree.arguments(name) for key, tree in trees.items()}
    acc = np.zeros(len(STAGES), np.uint64)
    best = {key: [np.inf, np.inf, None] for key in trees}  # plain, stamped, its stages
    for key, tree in trees.items():
        tree.plain_loop(5, *args[key][:6])
        tree.stamped_loop(5, *args[key][:6], acc)
    for _ in range(repeats):
        for key, tree in trees.items():
            b = best[key]
            b[0] = min(b[0], tree.plain_loop(calls, *args[key][:6])[0] / calls)
            acc[:] = 0
            total = tree.stamped_loop(calls, *args[key][:6], acc)[0] / calls
            if total < b[1]:
                b[1], b[2] = total, acc / calls
    row = {"scene": name, "n_states": args["this"][6]}
    for key, (plain, stamped, stages) in best.items():
        tag = "" if key == "this" else f"{key}_"
        row.update({f"{tag}plain_cycles": plain, f"{tag}stamped_cycles": stamped,
                    **{f"{tag}{label}_cycles": float(c) for (label, _), c in zip(STAGES, stages, strict=True)}})
    return row


def _print(rows: list[dict], rate: float, args) -> None:
    width = max(len(s) for s, _ in STAGES)
    print(f"cycles per call (the fewest over {args.repeats} rounds of {args.calls}); counter {rate / 1e9:.2f} GHz")
    keys = [label for label, _ in STAGES] + ["stamped", "plain"]
    if args.baseline:
        for r in rows:
            print(f"{r['scene']}: before (baseline) -> after (this tree)")
            for key in keys:
                before, after = r[f"baseline_{key}_cycles"], r[f"{key}_cycles"]
                print(f"  {key:{width}s} {before:>9.0f} -> {after:>9.0f}  {after / before:6.3f}")
        return
    print(" " * (width + 2) + "".join(f"{r['scene'][:16]:>18s}" for r in rows))
    for key in keys:
        cells = []
        for r in rows:
            c = r[key + "_cycles"]
            share = f"{c / rate * 1e6:5.2f}µs" if key in ("stamped", "plain") else f"{c / r['stamped_cycles']:5.0%} "
            cells.append(f"{c:>11.0f} {share}")
        print(f"{key:{width}s}  " + "".join(cells))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("scenes", nargs="*", default=list(SCENES))
    ap.add_argument("--calls", type=int, default=2000, help="calls per round")
    ap.add_argument("--repeats", type=int, default=40, help="alternated rounds (the fewest cycles kept)")
    ap.add_argument("--baseline", help="source tree to compare against, in this process (before/after)")
    ap.add_argument("--out", default=str(OUT / "call_cycles.csv"))
    args = ap.parse_args()
    trees = {"this": Tree("contactdyn")}
    if args.baseline:
        trees["baseline"] = Tree(baseline_package(args.baseline))
    rate = counter_rate()
    rows = [measure(name, trees, args.calls, args.repeats) for name in args.scenes]
    for r in rows:
        r["counter_hz"], r["plain_us"] = rate, r["plain_cycles"] / rate * 1e6
    _print(rows, rate, args)
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    with out.open("w", newline="") as fh:
        writer = csv.DictWriter(fh, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)
    write_report(out.with_suffix(".json"), {"calls": args.calls, "repeats": args.repeats, "stages": STAGES,
                                            "baseline": args.baseline}, rows)


if __name__ == "__main__":
    main()
