"""Speed against error: ``contactdyn bench SCENE``.

Runs a scene over integrators and tolerances (and fixed steps for ``RK4``) and compares
every run with a *reference run* of the same scene at a much tighter tolerance, whose own
error is estimated by running it once more at half that tolerance. For each setting it
reports the wall time (median of ``--repeats``; CPU time too), right-hand-side
evaluations, steps, events, and the errors:

- force: max |F_n − F_n,ref| over the output samples with t ≥ ``SKIP`` [s] (B1's metric;
  the first samples hold the start-up transient), the largest over the contacts [N];
- position: max |tip − tip_ref| over all samples and the three components [m].

Timing covers :func:`contactdyn.simulate.run_system` on a built system: integration,
events, impacts and the sampled output, not reading the scene and loading the robot
(reported separately as ``build_ms``). Writes ``NAME.csv``, ``NAME.json``, ``NAME.md``
(the table) and ``NAME.png`` (the plot) to ``--out`` (default ``out/bench/NAME``).

The defaults the project uses (method, tolerances) were chosen from these tables; the
rule and the measurements are in docs/performance.md. :func:`recommend` applies the rule
to one scene.
"""

from __future__ import annotations

import json
import math
import statistics
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import ContactdynError, SceneError
from ..model.system import System
from ..numerics.integrators import FIXED, METHODS
from ..output.result import Result
from ..scene.scene_file import Scene, load_scene, parse_override
from ..simulate import run_system

__all__ = ["WorkPoint", "Reference", "bench", "bench_command", "errors", "recommend", "reference_run", "replot",
           "OTHER_SIMULATORS", "compare_with_others"]

SKIP = 0.05  #: [s] force errors are taken from this time on (B1.md's metric)
REFERENCE_RTOL = 1e-12  #: tolerance of the reference run (atol scales with the scene's atol/rtol)
#: The reference is integrated by DOP853 even for stiff scenes: at these tolerances its
#: stability-bound steps cost little, while Radau's steps collapse (1e10 N/m contact, rtol
#: 1e-10: 1.4 million steps, 11 min).
DEFAULT_RTOLS = {  # per method: the tightest ones cost too much for the low orders
    "DOP853": (3e-3, 1e-3, 3e-4, 1e-4, 3e-5, 1e-5, 3e-6, 1e-6, 3e-7, 1e-7, 1e-8, 1e-9, 1e-10),
    "RK45": (1e-3, 1e-4, 1e-5, 1e-6, 1e-7, 1e-8),
    "RK23": (1e-3, 1e-4, 1e-5, 1e-6),
    "Radau": (1e-3, 1e-4, 1e-5, 1e-6, 1e-7, 1e-8),
    "BDF": (1e-3, 1e-4, 1e-5, 1e-6, 1e-7),
    "LSODA": (1e-3, 1e-4, 1e-5, 1e-6, 1e-7, 1e-8),
    "auto": (1e-4, 1e-6, 1e-8),
}
DEFAULT_STEPS = (1e-3, 3e-4, 1e-4)  #: [s] fixed steps of RK4
DEFAULT_METHODS = ("DOP853", "RK45", "RK23", "Radau", "RK4")
#: the rule for defaults: the cheapest setting whose force error is within this fraction of the peak force
RECOMMEND_RELATIVE = 1e-6

#: B1.md's measurements of other simulators on B1 (same machine, whole 2 s run): (label, F_n error [N], wall [s])
OTHER_SIMULATORS: dict[str, list[tuple[str, float, float]]] = {
    "b1": [
        ("MuJoCo 4.0 Euler dt=1e-3", 1.24, 0.028),
        ("MuJoCo 4.0 Euler dt=1e-4", 0.126, 0.14),
        ("MuJoCo 4.0 Euler dt=1e-5", 0.0124, 1.2),
        ("MuJoCo 4.0 RK4 dt=1e-5", 0.0056, 3.0),
        ("Drake 1.51 TAMSI dt=1e-3", 0.83, 2000 * 30e-6),
        ("Drake 1.51 TAMSI dt=1e-5", 0.0085, 200000 * 30e-6),
    ],
}


@dataclass
class WorkPoint:
    """One setting's cost and error."""

    method: str
    rtol: float | None
    atol: float | None
    step: float | None  #: [s] fixed step (RK4), else None
    wall_ms: float = math.nan  #: median wall time of the repeats
    cpu_ms: float = math.nan  #: median process CPU time of the repeats
    rhs_evals: int = 0
    steps: int = 0
    events: int = 0
    force_error: float = math.nan  #: [N]
    position_error: float = math.nan  #: [m]
    status: str = "ok"  #: "ok" or the failure's message
    methods_used: dict[str, int] = field(default_factory=dict)  #: integrator per segment (``auto``)
    walls_ms: list[float] = field(default_factory=list)

    @property
    def label(self) -> str:
        return f"{self.method} h={self.step:g}" if self.step is not None else f"{self.method} rtol={self.rtol:g}"


@dataclass
class Reference:
    """The reference run and its own error estimate (against the run at half its tolerance)."""

    result: Result
    rtol: float
    atol: float
    force_error: float  #: [N] estimate of the reference's own force error
    position_error: float  #: [m]
    wall_ms: float


# ---- runs ----------------------------------------------------------------------------------
def _setting(method: str, rtol: float | None, atol: float | None, step: float | None) -> dict[str, Any]:
    out: dict[str, Any] = {"solver.method": method}
    if rtol is not None:
        out["solver.rtol"], out["solver.atol"] = rtol, atol
    if step is not None:
        out["solver.max_step"] = step
    return out


def _timed(scene: Scene, repeats: int) -> tuple[Result, list[float], list[float]]:
    system = System(scene)
    walls, cpus = [], []
    result = None
    for _ in range(max(repeats, 1)):
        w0, c0 = time.perf_counter(), time.process_time()
        result = run_system(system)
        walls.append(time.perf_counter() - w0)
        cpus.append(time.process_time() - c0)
    assert result is not None
    return result, walls, cpus


def errors(result: Result, ref: Result) -> tuple[float, float]:
    """(force error [N], position error [m]) of a run against a reference on the same output grid."""
    t = ref.t
    if len(result.t) != len(t) or np.max(np.abs(result.t - t)) > 1e-9:
        raise ContactdynError("bench: run and reference have different output grids")
    late = t >= min(SKIP, t[-1]) - 1e-12
    force = 0.0
    for name in ref.meta.get("contacts", []):
        key = f"contact.{name}.F_n"
        force = max(force, float(np.max(np.abs(result[key][late] - ref[key][late]))))
    position = float(np.max(np.abs(result["tip"] - ref["tip"])))
    return force, position


def reference_run(scene_path: str | Path, overrides: dict[str, Any], rtol: float = REFERENCE_RTOL,
                  method: str = "DOP853") -> Reference:
    """The reference of a scene at ``rtol`` and its error estimate from a run at ``rtol / 2``."""
    base = load_scene(scene_path, overrides)
    ratio = base.solver.atol / base.solver.rtol
    runs = []
    for r in (rtol, 0.5 * rtol):
        scene = load_scene(scene_path, {**overrides, **_setting(method, r, r * ratio, None)})
        result, walls, _ = _timed(scene, 1)
        runs.append((result, walls[0]))
    (ref, wall), (half, _) = runs
    f_err, x_err = errors(ref, half)
    return Reference(ref, rtol, rtol * ratio, f_err, x_err, wall * 1e3)


def run_point(scene_path: str | Path, overrides: dict[str, Any], ref: Result, method: str,
              rtol: float | None = None, atol: float | None = None, step: float | None = None,
              repeats: int = 3) -> WorkPoint:
    """One setting: run it ``repeats`` times and compare with the reference."""
    point = WorkPoint(method, rtol, atol, step)
    try:
        scene = load_scene(scene_path, {**overrides, **_setting(method, rtol, atol, step)})
        result, walls, cpus = _timed(scene, repeats)
    except ContactdynError as exc:
        point.status = str(exc)
        return point
    point.wall_ms = statistics.median(walls) * 1e3
    point.cpu_ms = statistics.median(cpus) * 1e3
    point.walls_ms = [w * 1e3 for w in walls]
    s = result.stats
    point.rhs_evals, point.steps, point.events = int(s["rhs_evals"]), int(s["steps"]), int(s["events"])
    point.methods_used = dict(s.get("segments_by_method", {}))
    point.force_error, point.position_error = errors(result, ref)
    return point


def bench(scene_path: str | Path, overrides: dict[str, Any] | None = None, methods: tuple[str, ...] | None = None,
          rtols: tuple[float, ...] | None = None, steps: tuple[float, ...] | None = None, repeats: int = 3,
          progress=None) -> tuple[Reference, list[WorkPoint], float]:
    """The work-precision sweep of one scene: (reference, points, build time [ms])."""
    overrides = dict(overrides or {})
    t0 = time.perf_counter()
    base = load_scene(scene_path, overrides)
    System(base)
    build_ms = (time.perf_counter() - t0) * 1e3
    ratio = base.solver.atol / base.solver.rtol
    methods = tuple(methods or DEFAULT_METHODS)
    for m in methods:
        if m not in METHODS:
            raise SceneError("--methods", f"methods among {', '.join(METHODS)}", m)
    tightest = min(rtols) if rtols else 1e-10
    ref = reference_run(scene_path, overrides, min(REFERENCE_RTOL, max(tightest * 1e-2, 1e-13)))
    points = []
    for m in methods:
        if m in FIXED:
            settings = [(None, None, h) for h in (steps or DEFAULT_STEPS)]
        else:
            settings = [(r, r * ratio, None) for r in (rtols or DEFAULT_RTOLS.get(m, DEFAULT_RTOLS["DOP853"]))]
        for rtol, atol, step in settings:
            p = run_point(scene_path, overrides, ref.result, m, rtol, atol, step, repeats)
            points.append(p)
            if progress:
                progress(p)
    return ref, points, build_ms


# ---- what the numbers say --------------------------------------------------------------------
def recommend(points: list[WorkPoint], peak_force: float, relative: float = RECOMMEND_RELATIVE) -> WorkPoint | None:
    """The cheapest completed setting whose force error is within ``relative`` × the peak force."""
    good = [p for p in points if p.status == "ok" and p.force_error <= relative * max(peak_force, 1e-300)]
    return min(good, key=lambda p: p.wall_ms) if good else None


def compare_with_others(points: list[WorkPoint], others: list[tuple[str, float, float]],
                        factor_below: float = 1e-2, factor: float = 20.0) -> list[dict[str, Any]]:
    """For each other simulator's (error, time): our cheapest completed setting at least as accurate.

    ``ahead``: ours takes less wall time; ``factor_ok``: where their error is ≤ ``factor_below``
    [N], ours takes at least ``factor`` times less.
    """
    rows = []
    ok = [p for p in points if p.status == "ok"]
    for label, err, wall in others:
        cands = [p for p in ok if p.force_error <= err]
        best = min(cands, key=lambda p: p.wall_ms) if cands else None
        ratio = wall / (best.wall_ms * 1e-3) if best else math.nan
        rows.append({"other": label, "other_error_N": err, "other_wall_s": wall,
                     "ours": best.label if best else "none", "ours_error_N": best.force_error if best else math.nan,
                     "ours_wall_s": best.wall_ms * 1e-3 if best else math.nan, "speedup": ratio,
                     "ahead": bool(best) and ratio > 1.0,
                     "factor_ok": (bool(best) and ratio >= factor) if err <= factor_below else None})
    return rows


# ---- report --------------------------------------------------------------------------------
def table(points: list[WorkPoint]) -> str:
    """The work-precision table (markdown)."""
    head = ("| setting | wall [ms] | CPU [ms] | rhs evals | steps | events | F_n error [N] | tip error [m] | "
            "status |\n|---|---|---|---|---|---|---|---|---|\n")
    lines = []
    for p in points:
        used = "" if not p.methods_used or list(p.methods_used) == [p.method] else \
            " (" + ", ".join(f"{k}×{v}" for k, v in p.methods_used.items()) + ")"
        status = "ok" if p.status == "ok" else p.status.replace("|", "/")[:160]
        lines.append(f"| {p.label}{used} | {p.wall_ms:.1f} | {p.cpu_ms:.1f} | {p.rhs_evals} | {p.steps} | "
                     f"{p.events} | {p.force_error:.2e} | {p.position_error:.2e} | {status} |")
    return head + "\n".join(lines)


def plot(points: list[WorkPoint], path: Path, title: str, others: list[tuple[str, float, float]] | None = None,
         ref: Reference | None = None) -> None:
    """Wall time against force error and against tip error, log-log, one line per method."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(12, 4.8))
    methods = list(dict.fromkeys(p.method for p in points))
    for m in methods:
        ps = [p for p in points if p.method == m and p.status == "ok"]
        if not ps:
            continue
        for ax, key in zip(axes, ("force_error", "position_error"), strict=True):
            xs = [max(getattr(p, key), 1e-16) for p in ps]
            ax.loglog(xs, [p.wall_ms * 1e-3 for p in ps], "o-", label=f"contactdyn {m}")
    for label, err, wall in others or []:
        style = "s" if label.startswith("MuJoCo") else "^"
        axes[0].loglog([err], [wall], style, markersize=8, label=label)
    if ref is not None:
        for ax, err in zip(axes, (ref.force_error, ref.position_error), strict=True):
            if err > 0:
                ax.axvline(err, color="0.6", ls=":", label="reference's own error")
    axes[0].set_xlabel("max |F_n − F_n,ref| for t ≥ 0.05 s [N]")
    axes[1].set_xlabel("max |tip − tip_ref| [m]")
    for ax in axes:
        ax.set_ylabel("wall time of the run [s]")
        ax.grid(True, which="both", alpha=0.3)
    axes[0].legend(fontsize=7, loc="upper right")
    fig.suptitle(title)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)


def write_report(name: str, ref: Reference, points: list[WorkPoint], build_ms: float, out: Path,
                 changed: bool = False) -> dict[str, Any]:
    """Write NAME.csv, NAME.json, NAME.md and NAME.png into ``out``; return the JSON document. ``changed``: the
    scene was changed (overrides): no comparison with the other simulators, timed on the scene as it is."""
    out.mkdir(parents=True, exist_ok=True)
    peak = max(float(np.max(np.abs(ref.result[f"contact.{c}.F_n"]))) for c in ref.result.meta["contacts"]) \
        if ref.result.meta.get("contacts") else 0.0
    best = recommend(points, peak)
    others = [] if changed else OTHER_SIMULATORS.get(name, [])
    comparison = compare_with_others(points, others) if others else []
    doc = {
        "scene": name, "build_ms": build_ms, "peak_force_N": peak,
        "reference": {"rtol": ref.rtol, "atol": ref.atol, "force_error_N": ref.force_error,
                      "position_error_m": ref.position_error, "wall_ms": ref.wall_ms,
                      "methods": ref.result.stats.get("segments_by_method", {})},
        "points": [asdict(p) for p in points],
        "recommended": best.label if best else None,
        "recommend_rule": f"cheapest setting with force error <= {RECOMMEND_RELATIVE:g} x peak force",
        "others": comparison,
        "changed": changed,  #: overrides changed the scene: no comparison with the other simulators' timings
    }
    (out / f"{name}.json").write_text(json.dumps(doc, indent=1, default=float))
    with open(out / f"{name}.csv", "w") as fh:
        fh.write("method,rtol,atol,step,wall_ms,cpu_ms,rhs_evals,steps,events,force_error_N,position_error_m,status\n")
        for p in points:
            fh.write(f"{p.method},{p.rtol},{p.atol},{p.step},{p.wall_ms:.4f},{p.cpu_ms:.4f},{p.rhs_evals},{p.steps},"
                     f"{p.events},{p.force_error:.6e},{p.position_error:.6e},\"{p.status}\"\n")
    md = [f"# Work-precision: {name}", "",
          f"Reference: DOP853 at rtol {ref.rtol:g}, atol {ref.atol:g} ({ref.wall_ms:.0f} ms); its own error "
          f"(against half its tolerance): F_n {ref.force_error:.1e} N, tip {ref.position_error:.1e} m. "
          f"Build (scene + robot): {build_ms:.1f} ms, not in the times below.", "", table(points), ""]
    if best:
        md.append(f"Recommended by the rule ({doc['recommend_rule']}, peak {peak:.4g} N): **{best.label}** — "
                  f"{best.wall_ms:.1f} ms, F_n error {best.force_error:.1e} N.")
    if comparison:
        md += ["", "| other simulator | its error [N] | its wall [s] | ours (cheapest as accurate) | our error [N] | "
               "our wall [s] | speed-up |", "|---|---|---|---|---|---|---|"]
        md += [f"| {r['other']} | {r['other_error_N']:g} | {r['other_wall_s']:.3g} | {r['ours']} | "
               f"{r['ours_error_N']:.1e} | {r['ours_wall_s']:.3g} | {r['speedup']:.1f}× |" for r in comparison]
    (out / f"{name}.md").write_text("\n".join(md) + "\n")
    plot(points, out / f"{name}.png", f"{name}: wall time against error", others, ref)
    return doc


def replot(json_path: str | Path, png_path: str | Path | None = None) -> Path:
    """Draw a report's plot again from its NAME.json (no runs)."""
    doc = json.loads(Path(json_path).read_text())
    fields = set(WorkPoint.__dataclass_fields__)
    points = [WorkPoint(**{k: v for k, v in p.items() if k in fields}) for p in doc["points"]]
    path = Path(png_path) if png_path else Path(json_path).with_suffix(".png")
    name = doc["scene"]
    plot(points, path, f"{name}: wall time against error", OTHER_SIMULATORS.get(name, []), None)
    return path


# ---- the CLI entry -----------------------------------------------------------------------
def _floats(text: str | None, what: str) -> tuple[float, ...] | None:
    if not text:
        return None
    try:
        values = tuple(float(v) for v in text.split(",") if v.strip())
    except ValueError:
        raise SceneError(what, "comma-separated numbers like 1e-4,1e-6", text) from None
    if not values or not all(math.isfinite(v) and v > 0 for v in values):
        raise SceneError(what, "comma-separated finite numbers > 0 like 1e-4,1e-6", text)
    return values


def _speed_words(ratio: float) -> str:
    """``2.5× faster`` or ``1.7× slower`` (a ratio below 1 is a slowdown, never "0.6× faster")."""
    return f"{ratio:.1f}× faster" if ratio >= 1.0 else f"{1.0 / ratio:.1f}× slower"


def bench_command(args) -> int:
    """``contactdyn bench SCENE [--methods M,...] [--rtols r,...] [--repeats N] [--out DIR] [--set k=v]...``.

    ``--methods`` entries may carry fixed steps for RK4: ``RK4=1e-3/1e-4``.
    """
    overrides = dict(parse_override(s) for s in (args.set or []))
    methods, steps = None, None
    if args.methods:
        methods = []
        for item in args.methods.split(","):
            name, _, hs = item.strip().partition("=")
            methods.append(name)
            if hs:
                steps = _floats(hs.replace("/", ","), "--methods")
        methods = tuple(methods)
    rtols = _floats(args.rtols, "--rtols")
    if args.repeats < 1:
        raise SceneError("--repeats", "an integer >= 1 (timings are medians of the repeats)", args.repeats)
    scene = load_scene(args.scene, overrides)
    name = scene.name
    out = Path(args.out) if args.out else Path("out") / "bench" / name
    print(f"bench {name}: reference run, then {', '.join(methods or DEFAULT_METHODS)} "
          f"({args.repeats} repeats each)", flush=True)
    for m in methods or DEFAULT_METHODS:  # the settings each method runs at (defaults unless given)
        at = (f"steps {', '.join(f'{h:g}' for h in steps or DEFAULT_STEPS)} s" if m == "RK4" else
              f"rtol {', '.join(f'{r:g}' for r in rtols or DEFAULT_RTOLS.get(m, DEFAULT_RTOLS['DOP853']))}")
        print(f"  {m}: {at}", flush=True)

    def progress(p: WorkPoint) -> None:
        if p.status == "ok":
            print(f"  {p.label:24s} wall {p.wall_ms:9.1f} ms  evals {p.rhs_evals:8d}  F_n err {p.force_error:.2e} N"
                  f"  tip err {p.position_error:.2e} m", flush=True)
        else:
            print(f"  {p.label:24s} failed: {p.status[:200]}", flush=True)

    ref, points, build_ms = bench(args.scene, overrides, methods, rtols, steps, args.repeats, progress)
    doc = write_report(name, ref, points, build_ms, out, changed=bool(overrides))
    if doc["changed"] and OTHER_SIMULATORS.get(name):
        print("  (no comparison with the other simulators: their timings are of the scene as it is, and --set "
              "changed it)")
    print(f"reference: rtol {ref.rtol:g}, own error F_n {ref.force_error:.1e} N, tip {ref.position_error:.1e} m")
    if doc["recommended"]:
        print(f"recommended ({doc['recommend_rule']}): {doc['recommended']}")
    for r in doc["others"]:
        print(f"  vs {r['other']}: ours {r['ours']} {_speed_words(r['speedup'])} at error {r['ours_error_N']:.1e} N"
              if r["ours"] != "none" else f"  vs {r['other']}: no setting of ours reached {r['other_error_N']} N")
    print(f"wrote {out / (name + '.md')}, .csv, .json, .png")
    return 0
