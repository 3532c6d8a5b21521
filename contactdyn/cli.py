"""The ``contactdyn`` command line: thin dispatch to plain functions.

Exit codes: 0 ok; 1 a run failed (a sweep: at least one run failed, all are recorded);
2 bad input (unknown key, wrong type or value, unknown scene or robot, unreadable or
malformed file, an output path that cannot be written, command-line misuse);
130 interrupted (a sweep resumes when run again).
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
from pathlib import Path
from typing import Any

from .errors import ContactdynError, RobotError, RunFileError, SceneError, close_matches, is_plain_name

__all__ = ["main", "build_parser", "EXIT_OK", "EXIT_FAILED", "EXIT_USAGE", "EXIT_INTERRUPTED"]

EXIT_OK, EXIT_FAILED, EXIT_USAGE, EXIT_INTERRUPTED = 0, 1, 2, 130
MAX_MESSAGE = 1000  #: characters of an error line at most
LIST_SECTIONS = ("scenes", "robots", "models", "controllers", "integrators")
LIST_MORE = ("frames",)  #: sections listed only by name: ``list frames ROBOT``


class _Usage(Exception):
    """Command-line misuse found by argparse (exit 2, one line, no traceback)."""


class _Parser(argparse.ArgumentParser):
    def error(self, message: str):  # noqa: D102 (argparse hook)
        raise _Usage(f"{self.prog}: {message}")


def _out(args: argparse.Namespace, text: str) -> None:
    if not getattr(args, "quiet", False) and not getattr(args, "json", False):
        print(_printable(text))


def _printable(text: str) -> str:
    """Control characters (terminal escape codes from a scene name, say) shown as escapes, not obeyed."""
    return "".join(c if c.isprintable() or c == "\n" else repr(c)[1:-1] for c in text)


def _emit_json(obj: Any) -> None:
    print(json.dumps(_plain(obj), indent=1, allow_nan=False))


def _plain(obj: Any) -> Any:
    """JSON-ready: numpy to Python, NaN and infinities (undefined metrics) to null."""
    import numpy as np

    if isinstance(obj, dict):
        return {str(k): _plain(v) for k, v in obj.items()}
    if isinstance(obj, list | tuple | np.ndarray):
        return [_plain(v) for v in obj]
    if isinstance(obj, np.generic):
        obj = obj.item()
    if isinstance(obj, float) and not math.isfinite(obj):
        return None
    if obj is None or isinstance(obj, str | int | float | bool):
        return obj
    return str(obj)


# ---- list ------------------------------------------------------------------------------------
def _catalog(sections: list[str]) -> dict[str, Any]:
    """The ``list`` sections asked for (each imports only what it lists)."""
    return {s: _SECTIONS[s]() for s in sections}


def _scenes() -> list[dict[str, str]]:
    from .scene.reader import read_toml
    from .scene.scene_file import scene_dirs

    scenes, seen = [], set()
    for path in (p for folder in scene_dirs() for p in sorted(folder.glob("*.toml"))):
        if path.stem in seen:  # the name runs the first one found (./sims before the installed scenes)
            continue
        seen.add(path.stem)
        try:
            description = read_toml(path).get("description", "")
        except SceneError as exc:
            description = f"(unreadable: {exc})"
        scenes.append({"name": path.stem, "file": str(path), "description": str(description)})
    return scenes


def _robots() -> list[dict[str, Any]]:
    from .robot.listing import robot_entries

    return robot_entries()


def _models() -> dict[str, list[dict[str, str]]]:
    from .scene.scene_file import NORMAL_MODELS, TANGENT_MODELS

    normal = {"rigid": "constraint, impact at touch", "a": "ground -[k'', b'']- m' -[k', b']- tip (continuous)",
              "b": "ground -[k, b]- m', struck by the tip (impact at touch)", "c": "massless Kelvin-Voigt stage k, b",
              "chain": "explicit stages {k, b} and masses {m}, environment and robot side"}
    tangent = {"free": "no tangential force", "friction": "Coulomb stick/slip (mu or mu_s, mu_k; viscous)",
               "chain": "tangential deformation chain, bonded at touch"}
    return {"normal": [{"name": m, "description": normal.get(m, "")} for m in NORMAL_MODELS],
            "tangent": [{"name": m, "description": tangent.get(m, "")} for m in TANGENT_MODELS]}


def _controllers() -> list[dict[str, str]]:
    from .laws.controllers import CONTROLLERS

    out = []
    for name in sorted(CONTROLLERS):
        doc = (CONTROLLERS[name].__doc__ or "").strip().splitlines()
        out.append({"name": name, "description": doc[0] if doc else ""})
    return out


def _integrators() -> list[dict[str, Any]]:
    from .numerics.integrators import FIXED, IMPLICIT, METHODS

    return [{"name": m, "implicit": m in IMPLICIT, "description": _integrator(m, IMPLICIT, FIXED)} for m in METHODS]


_SECTIONS = {"scenes": _scenes, "robots": _robots, "models": _models, "controllers": _controllers,
             "integrators": _integrators}


def _integrator(name: str, implicit: tuple[str, ...], fixed: tuple[str, ...]) -> str:
    if name == "auto":
        return "DOP853C, switching to Radau where a decaying stiff mode holds the step"
    if name == "DOP853C":
        return "DOP853 on scipy's compiled core: solve_ivp's steps and events, less work per step (default)"
    if name == "DOP853":
        return "DOP853 by scipy's solve_ivp (the same steps as DOP853C, ~65 µs more work per step)"
    if name in fixed:
        return "fixed-step explicit Runge-Kutta, step solver.max_step, no error control"
    return "implicit, for stiff scenes" if name in implicit else "explicit Runge-Kutta with error control"


def _cmd_list(args: argparse.Namespace) -> int:
    if args.what == "frames":
        from .robot.listing import frames_command

        return frames_command(args)
    if args.what == "keys" or args.prefix:
        from .scene.keys import list_keys

        return list_keys(args)
    sections = [args.what] if args.what else list(LIST_SECTIONS)
    catalog = _catalog(sections)
    if args.json:
        _emit_json(catalog)
        return EXIT_OK
    for s in sections:
        print(f"{s}:")
        if s == "models":
            for kind in ("normal", "tangent"):
                print(f"  {kind} (contact.<c>.{kind}.model):")
                for m in catalog[s][kind]:
                    print(f"    {m['name']:<8} {m['description']}")
        elif s == "robots":
            from .robot.listing import print_robots

            print_robots(catalog[s])
        else:
            width = max((len(item["name"]) for item in catalog[s]), default=0)
            for item in catalog[s]:
                print(f"  {item['name']:<{max(width, 16)}} {item['description']}")
    return EXIT_OK


# ---- run -------------------------------------------------------------------------------------
def _cmd_run(args: argparse.Namespace) -> int:
    from .scene.scene_file import load_scene, parse_override

    overrides = dict(parse_override(s) for s in args.set)
    scene = load_scene(args.scene, overrides)
    _out(args, f"scene {scene.name}: {scene.file}")
    from .scene.user_laws import IMPORTED

    for module in scene.imports:  # importing runs code: say what ran
        _out(args, f"imported {module} from {IMPORTED.get(module, '?')}")
    from .first_run import arrivals, build_in_background, choose, default_path, leaves_ahead, leaves_first, mark_built

    choice = choose(scene, args.path or default_path())
    helped = choice.build and leaves_ahead(scene)  # a first run's helper, started before the simulator's imports
    from .model.paths import slower_paths
    from .output.metrics import metrics
    from .simulate import simulate

    if helped:  # a first run: its leaves compiled from both ends, on two cores
        leaves_first(scene)
    with arrivals(choice):  # (interpreted: the late leaves compiled by the helper meanwhile, once they arrive)
        result = _simulate_quietly(simulate, scene, progress=not (args.quiet or args.json), compiled=choice.compiled,
                                   interpreted=choice.interpreted)
    if choice.compiled:
        mark_built(scene)
    building = choice.build and build_in_background(scene)
    from .robot.listing import run_warnings

    # sanity, then inertia and limits, then the run's physics checks
    warnings = result.meta.get("warnings", []) + run_warnings(result.meta) + result.meta.get("check_warnings", [])
    if not args.quiet and not args.json:
        for note in warnings:
            print(f"contactdyn: warning: {note}", file=sys.stderr)
    saved = str(result.save(args.out)) if args.out else None
    if args.json:
        _emit_json({"scene": scene.name, "file": scene.file, "status": "ok", "out": saved,
                    "warnings": warnings,
                    "metrics": metrics(result), "stats": result.stats, "impacts": result.impacts})
    else:
        s = result.stats
        _out(args, f"{result.meta['name']}: {result.meta['duration']:g} s simulated in {s['wall_s']:.3f} s "
                   f"(real-time factor {s['real_time_factor']:.1f}), {s['steps']} steps, {s['rhs_evals']} rhs "
                   f"evaluations, {s['events']} events, {len(result.impacts)} impacts")
        for line in slower_paths(s.get("paths", {})):
            _out(args, f"  path of {line}")
        from .model.joint_friction import summary

        if summary(result.meta.get("joint_friction", {})):
            _out(args, "  " + summary(result.meta["joint_friction"]))
        if args.verbose:
            from .robot.listing import run_details

            for line in run_details(result.meta):
                _out(args, line)
        for name in result.meta["contacts"]:
            F = result[f"contact.{name}.F_n"]
            _out(args, f"  contact {name}: normal force peak {F.max():.4g} N, final {F[-1]:.4g} N")
        for imp in result.impacts:
            friction = ", ".join(f"{v:.6g}" for v in imp["friction_impulse"])
            friction = f", F_fΔt = [{friction}] N·s, jammed = {imp['jammed']}" if friction else " (no friction)"
            together = f" (touching with {imp['with']})" if "with" in imp else ""
            _out(args, f"  impact t = {imp['t']:.6g} s on {imp['contact']}{together}: FΔt = {imp['normal_impulse']:.6g}"
                       f" N·s{friction}")
        for e in result.events:
            if e["kind"] in ("limit", "release"):
                what = f"stops at its {e['side']} limit, impulse {e['impulse']:.6g} {e['impulse_unit']}" \
                    if e["kind"] == "limit" else "leaves its limit"
                _out(args, f"  joint limit t = {e['t']:.6g} s: {e['name']} {what}")
        if saved:
            _out(args, f"  saved {saved} and {saved.removesuffix('.npz')}.json")
    if (building or choice.failed is not None) and not (args.quiet or args.json):
        print(choice.line(), file=sys.stderr, flush=True)
    if args.view:
        view_result = _lazy("viewer", "view_result")
        if view_result is None:
            return EXIT_FAILED
        return view_result(result, args) or EXIT_OK
    return EXIT_OK


def _simulate_quietly(simulate, scene, progress: bool = True, compiled: bool = True, interpreted: bool = False):
    """Simulate without Python's own warning lines (the command prints the sanity and check warnings itself)."""
    from .simulate import without_warning_lines

    with without_warning_lines():
        return simulate(scene, progress=progress, compiled=compiled, interpreted=interpreted)


# ---- sweep -----------------------------------------------------------------------------------
def _cmd_sweep(args: argparse.Namespace) -> int:
    from .sweep import make_sweep, run_sweep

    sweep = make_sweep(args.scene, args.set, args.grid, args.range, args.file)
    if not args.out and not is_plain_name(sweep.name):  # a received scene never chooses where files go
        raise SceneError("--out", f"a folder for this sweep: its scene's name {sweep.name!r} cannot name one "
                         "(sweeps/<name> needs letters, digits, '_', '.', '+', '-' only, no leading '.')",
                         "no --out")
    out = str(Path(args.out or f"sweeps/{sweep.name}").absolute())  # workers may run elsewhere (Dask)
    if (args.plot is None) != (args.over is None):
        raise SceneError("--plot/--over", "both: --plot METRIC --over PARAMETER", args.plot or args.over)
    if args.over is not None and args.over not in sweep.parameter_keys():
        raise SceneError("--over", f"a swept parameter ({', '.join(sweep.parameter_keys()) or 'none'})", args.over)
    if args.plot is not None:
        _check_metric(args.plot, sweep)
    if args.workers is not None and args.workers < 0:
        raise SceneError("--workers", "an integer >= 0 (0: run in this process)", args.workers)
    if args.chunk is not None and args.chunk < 1:
        raise SceneError("--chunk", "an integer >= 1", args.chunk)
    n = len(sweep.cases())
    where = f"Dask scheduler {args.scheduler}" if args.scheduler else (
        "this process" if args.workers == 0 else f"{args.workers or 'all'} local workers")
    _out(args, f"sweep {sweep.name}: {n} runs on {where} -> {out}")
    report = run_sweep(sweep, out, workers=args.workers, scheduler=args.scheduler, chunk=args.chunk, csv=args.csv,
                       retry_failed=args.retry_failed, progress=not (args.quiet or args.json))
    bad = report.counts["failed"] + report.counts["crashed"]
    if args.json:
        _emit_json(report.as_dict())
    else:
        _out(args, f"  {report.counts['ok']} ok, {report.counts['failed']} failed, {report.counts['crashed']} crashed"
                   f" ({report.skipped} already done) in {report.wall_s:.2f} s; summary {report.summary}")
        if report.warned and not args.quiet:
            print(f"contactdyn: warning: {report.warned} of {report.total} runs gave sanity or physics-check "
                  "warnings: the summary's warnings and check_violations count them, each run's result holds them",
                  file=sys.stderr)
    from .sweep.report import failure_lines, failures, plot_over

    if bad and not args.json:
        print(f"contactdyn: {bad} of {report.total} runs failed:", file=sys.stderr)
        print("\n".join(failure_lines(failures(report.summary, sweep.parameter_keys()))), file=sys.stderr)
    if args.plot:
        figure = plot_over(report.summary, args.plot, args.over, sweep.parameter_keys(), report.out)
        _out(args, f"  plot {figure}")
    return EXIT_FAILED if bad else EXIT_OK


def _check_metric(name: str, sweep) -> None:
    """``--plot``'s metric, checked before the sweep runs: one its runs give (output.metrics), for the contacts of
    its scene and of its overrides."""
    from .output.metrics import CONTACT_METRICS, RUN_METRICS

    table = sweep.document.get("contact")
    contacts = dict.fromkeys([*(table if isinstance(table, dict) else {}),
                              *(k.split(".")[1] for k in [*sweep.fixed, *sweep.axes] if k.startswith("contact."))])
    known = [*RUN_METRICS, *(f"contact.{c}.{m}" for c in contacts for m in CONTACT_METRICS)]
    if name not in known:
        close = close_matches(name, known, n=1)
        hint = f"did you mean {close[0]!r}? " if close else ""
        raise SceneError("--plot", f"a metric of the sweep's runs ({hint}known: {', '.join(known)})", name)


# ---- plot, view, bench: other modules, imported when used ---------------------------------------
def _lazy(module: str, function: str):
    import importlib

    name = f"{__package__}.{module}"
    try:
        return getattr(importlib.import_module(name), function)
    except ModuleNotFoundError as exc:
        if exc.name not in (name, None):  # the module exists but needs something missing
            print(f"contactdyn: error: {module} cannot be used here: {exc}", file=sys.stderr)
            return None
    except (ImportError, AttributeError):
        pass
    print(f"contactdyn: error: {module}.{function} is not available yet in this version", file=sys.stderr)
    return None


def _delegate(module: str, function: str):
    def handler(args: argparse.Namespace) -> int:
        if getattr(args, "run", None) is not None:
            _check_saved_run(args.run)
        fn = _lazy(module, function)
        return EXIT_FAILED if fn is None else int(fn(args) or EXIT_OK)

    return handler


def _check_saved_run(run: str) -> None:
    from .output.result import missing_run_message, run_files

    if not all(f.is_file() for f in run_files(run)):
        raise RunFileError(missing_run_message(run))


# ---- parser ----------------------------------------------------------------------------------
def _scripting(p: argparse.ArgumentParser) -> None:
    p.add_argument("--quiet", "-q", action="store_true", help="print nothing but errors")
    p.add_argument("--json", action="store_true", help="print one JSON document on stdout (for scripts)")


def _imports_option(p: argparse.ArgumentParser) -> None:
    p.add_argument("--no-imports", action="store_true",
                   help="refuse a scene that names modules to import (imports = [...]): for scenes from others")


def _set_option(p: argparse.ArgumentParser) -> None:
    p.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                   help="override a scene key, value read as TOML (repeatable), e.g. contact.tip.normal.k=1e4")


def _speed(text: str) -> float:
    """A playback speed: a finite number > 0 (argparse turns the ValueError into exit 2)."""
    value = float(text)
    if not (math.isfinite(value) and value > 0):
        raise ValueError(text)
    return value


_speed.__name__ = "speed (a number > 0)"  # argparse: "invalid speed (a number > 0) value: '0'"


def _port(text: str) -> int:
    """A TCP port to listen on: 1 ... 65535."""
    value = int(text)
    if not 1 <= value <= 65535:
        raise ValueError(text)
    return value


_port.__name__ = "port (an integer 1 ... 65535)"


def _host(text: str) -> str:
    """An address this machine can listen on: a name or a literal that resolves."""
    import socket

    try:
        socket.getaddrinfo(text, None)
    except (OSError, UnicodeError):
        raise ValueError(text) from None
    return text


_host.__name__ = "host (an address of this machine that resolves)"


def _csv_list(text: str) -> list[str]:
    return [s.strip() for s in text.split(",") if s.strip()]


def build_parser() -> argparse.ArgumentParser:
    fmt = argparse.RawDescriptionHelpFormatter
    parser = _Parser(prog="contactdyn", description=__doc__, formatter_class=fmt)
    from . import __version__

    parser.add_argument("--version", action="version", version=f"contactdyn {__version__}")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND", parser_class=_Parser)

    for add in (_list_parser, _run_parser, _sweep_parser, _new_parser, _view_parser, _plot_parser, _bench_parser,
                _fit_parser):
        add(sub, fmt)
    return parser


def _list_parser(sub, fmt) -> None:
    ls = sub.add_parser("list", help="list scenes, robots, contact models, controllers, integrators",
                        description="List what a scene can name.", formatter_class=fmt,
                        epilog="examples:\n  contactdyn list\n  contactdyn list robots --json\n"
                               "  contactdyn list keys contact   (the scene keys, as docs/scenes.md)\n"
                               "  contactdyn list frames panda   (a robot's kinematic tree)")
    ls.add_argument("what", nargs="?", choices=(*LIST_SECTIONS, *LIST_MORE, "keys"), help="one section only")
    ls.add_argument("prefix", nargs="?", help="with keys: only the keys starting with it (e.g. contact, "
                                              "phase.force, contact.pencil.normal); with frames: the robot")
    _scripting(ls)
    ls.set_defaults(func=_cmd_list)


def _run_parser(sub, fmt) -> None:
    run = sub.add_parser("run", help="simulate a scene", description="Simulate one scene and print its key figures.",
                         formatter_class=fmt,
                         epilog="examples:\n  contactdyn run b1 --set solver.rtol=1e-6 --out runs/b1\n"
                                "  contactdyn run sims/b1.toml --set duration=0.5 --json")
    run.add_argument("scene", help="scene file or name in sims/")
    _set_option(run)
    run.add_argument("--out", help="save the run as OUT.npz + OUT.json")
    run.add_argument("--verbose", "-v", action="store_true",
                     help="also print the active and locked joints and how the start posture was found")
    run.add_argument("--view", action="store_true", help="show the run in the meshcat viewer afterwards")
    run.add_argument("--html", help="with --view: write a self-contained HTML player instead of serving")
    run.add_argument("--port", type=_port, help="with --view: meshcat server port")
    run.add_argument("--host", type=_host,
                     help="with --view: listen on this address (default 127.0.0.1, this machine only)")
    run.add_argument("--speed", type=_speed, default=1.0,
                     help="with --view: playback speed factor (> 0; 1 = real time)")
    run.add_argument("--path", choices=("auto", "compiled", "interpreted"),
                     help="auto (default, or $CONTACTDYN_PATH): the compiled call once this kind of scene was "
                          "compiled, else the same call interpreted while it compiles in the background; compiled: "
                          "compile now if needed; interpreted: the call's functions interpreted (its rigid-body "
                          "leaves compiled)")
    _scripting(run)
    _imports_option(run)
    run.set_defaults(func=_cmd_run)


def _sweep_parser(sub, fmt) -> None:
    sw = sub.add_parser(
        "sweep", help="run a scene over a grid of parameters (process pool or Dask)", formatter_class=fmt,
        description="Run every combination of the axes; results in OUT/runs/, one summary row per run in "
                    "OUT/summary.parquet. Re-running the same command resumes (finished runs are skipped).",
        epilog="examples:\n"
               "  contactdyn sweep b1 --grid contact.tip.normal.k=1e4,1e5,1e6 --range controller.kp=500:5000:4 "
               "--out sweeps/b1 --csv\n"
               "  contactdyn sweep b1 --range contact.tip.tangent.mu=0.1:0.8:8 --set duration=0.5 --workers 2\n"
               "  contactdyn sweep --file mysweep.toml --scheduler tcp://10.0.0.5:8786\n"
               "  contactdyn sweep b1 --range contact.tip.normal.k=1e4:1e6:5:log --plot contact.tip.F_peak "
               "--over contact.tip.normal.k\n"
               "exit codes: 0 all runs ok, 1 some run failed (recorded in the summary), 2 bad input")
    sw.add_argument("scene", nargs="?", help="scene file or name in sims/ (or `scene` in the sweep file)")
    _set_option(sw)
    sw.add_argument("--grid", action="append", default=[], metavar="KEY=V1,V2,...", help="an axis of given values")
    sw.add_argument("--range", action="append", default=[], metavar="KEY=LO:HI:N[:log]",
                    help="an axis of N values from LO to HI, linear or log spaced")
    sw.add_argument("--file", help="a sweep file (TOML: scene, [set], [grid], [range], [[run]])")
    sw.add_argument("--out", help="output folder (default sweeps/<scene name>)")
    sw.add_argument("--workers", type=int, help="local worker processes (default: all cores; 0: this process)")
    sw.add_argument("--scheduler", metavar="ADDRESS", help="run on this Dask distributed scheduler instead")
    sw.add_argument("--chunk", type=int, help="runs per task sent to a worker (default: about 4 tasks per worker)")
    sw.add_argument("--csv", action="store_true", help="also write OUT/summary.csv")
    sw.add_argument("--retry-failed", action="store_true", help="run the failed runs again on resume")
    sw.add_argument("--plot", metavar="METRIC", help="draw this metric of the summary (e.g. contact.tip.F_final) ...")
    sw.add_argument("--over", metavar="KEY", help="... against this swept parameter: OUT/plot_METRIC_over_KEY.png")
    _scripting(sw)
    _imports_option(sw)
    sw.set_defaults(func=_cmd_sweep)


def _new_parser(sub, fmt) -> None:
    new = sub.add_parser("new", help="write a commented starter scene (press, then slide)", formatter_class=fmt,
                         description="Write sims/NAME.toml: the robot's tip approaches a table, presses 20 N and "
                                     "slides 10 cm. It runs as written; edit it from there.",
                         epilog="examples:\n  contactdyn new mine && contactdyn run mine\n"
                                "  contactdyn new press_ur5 --robot ur5 --contact c --friction\n"
                                "  contactdyn new cubic --imports cubic_stage --law cubic --friction-law stribeck "
                                "--out cubic.toml\n"
                                "    (in the folder of your cubic_stage.py: the scene beside it; then "
                                "contactdyn run cubic.toml)")
    new.add_argument("name", help="scene name (written to sims/NAME.toml in the working directory)")
    new.add_argument("--robot", default="writer2r", help="robot: a name in urdf/, of example-robot-data, or a path "
                                                        "(default writer2r)")
    new.add_argument("--tip", help="tip frame (default: known for writer2r, planar2r_b1, writer5dof, ur5; else tip)")
    new.add_argument("--contact", default="b", choices=("b", "a", "c", "rigid"), help="normal contact model")
    new.add_argument("--friction", action="store_true", help="Coulomb friction along the slide (mu = 0.3)")
    new.add_argument("--law", help="the normal's stage law (a registered name; yours with --imports), written with "
                                   "its declared parameters")
    new.add_argument("--friction-law", help="friction along the slide under this law (coulomb, stribeck, yours with "
                                            "--imports), written with its declared parameters")
    new.add_argument("--imports", action="append", metavar="MODULE[,MODULE]",
                     help="modules of your laws to import (beside the new scene or on sys.path); the scene names them")
    new.add_argument("--out", metavar="FILE", help="write here instead of sims/NAME.toml")
    new.add_argument("--force", action="store_true", help="overwrite an existing file")
    new.set_defaults(func=_delegate("starter", "new_command"))


def _view_parser(sub, fmt) -> None:
    view = sub.add_parser("view", help="show a saved run in the meshcat viewer", formatter_class=fmt,
                          epilog="examples:\n  contactdyn view runs/b1\n  contactdyn view runs/b1 --html b1.html")
    view.add_argument("run", help="saved run (RUN.npz + RUN.json)")
    view.add_argument("--html", metavar="FILE", help="write a self-contained HTML player instead of serving")
    view.add_argument("--port", type=_port, help="meshcat server port")
    view.add_argument("--host", type=_host, help="listen on this address (default 127.0.0.1, this machine only)")
    view.add_argument("--speed", type=_speed, default=1.0, help="playback speed factor (> 0; 1 = real time)")
    _imports_option(view)
    view.set_defaults(func=_delegate("viewer", "view_command"))


def _plot_parser(sub, fmt) -> None:
    plot = sub.add_parser("plot", help="paper-style figures of a saved run", formatter_class=fmt,
                          epilog="example:\n  contactdyn plot runs/b1 --out figs --format png,svg")
    plot.add_argument("run", help="saved run (RUN.npz + RUN.json)")
    plot.add_argument("--out", metavar="DIR", help="output folder")
    plot.add_argument("--format", type=_csv_list, help="comma-separated formats (default png,svg)")
    plot.set_defaults(func=_delegate("output.plots", "plot_command"))


def _bench_parser(sub, fmt) -> None:
    bench = sub.add_parser("bench", help="work-precision benchmark of the integrators on a scene",
                           formatter_class=fmt,
                           epilog="example:\n  contactdyn bench b1 --methods DOP853,RK45 --rtols 1e-4,1e-6,1e-8 "
                                  "--repeats 3 --out bench/b1")
    bench.add_argument("scene", help="scene file or name in sims/")
    bench.add_argument("--methods", help="comma-separated integrators (see `contactdyn list`; default DOP853,RK45,"
                                         "RK23,Radau,RK4); RK4=1e-3/1e-4 gives RK4's fixed steps (default 1e-3, "
                                         "3e-4, 1e-4 s)")
    bench.add_argument("--rtols", help="comma-separated relative tolerances (default: per method, 1e-3 down to "
                                       "1e-10 for DOP853; the command prints them first)")
    bench.add_argument("--repeats", type=int, default=3, help="timing repeats per point (default 3)")
    bench.add_argument("--out", metavar="DIR", help="output folder (default out/bench/SCENE)")
    _set_option(bench)
    bench.set_defaults(func=_delegate("analysis.workprecision", "bench_command"))


def _fit_parser(sub, fmt) -> None:
    fit = sub.add_parser("fit", help="fit scene parameters (k, b, m', mu, ...) to a measured log", formatter_class=fmt,
                         description="Identify the environment: least squares on full runs of the scene, with "
                                     "standard errors, 95 % intervals and correlations (contactdyn/identify/).",
                         epilog="example:\n  contactdyn fit b1 --data log.csv --params contact.tip.normal.k,"
                                "contact.tip.normal.m,contact.tip.tangent.mu=0.05:2 --out fit --save-scene fitted.toml")
    fit.add_argument("scene", help="scene file or name in sims/ (it supplies robot, controller, references)")
    fit.add_argument("--data", required=True, metavar="LOG.csv", help="column t [s] and columns named like channels")
    fit.add_argument("--params", required=True, action="append", metavar="KEY[=LOW:HIGH],...",
                     help="scene keys to fit; positive ones on a log scale")
    _set_option(fit)
    fit.add_argument("--noise", action="append", default=[], metavar="COLUMN=SIGMA",
                     help="noise level of a column (default: estimated from the data)")
    fit.add_argument("--starts", type=int, default=1, help="solver starts (the scene's values, then random)")
    fit.add_argument("--seed", type=int, default=0, help="seed of the random starts")
    fit.add_argument("--workers", type=int, default=0, help="processes for the Jacobian's runs (0: this one)")
    fit.add_argument("--stages", type=int, default=6, help="continuation: first fit 1/2^(STAGES-1) of the log, "
                                                          "then double the window (1: the whole log at once)")
    fit.add_argument("--rtol", type=float, default=1e-10, help="relative tolerance of every fit run")
    fit.add_argument("--atol", type=float, default=1e-12, help="absolute tolerance of every fit run")
    fit.add_argument("--out", metavar="DIR", help="write fit.json, fit.md and fit.png here")
    fit.add_argument("--save-scene", metavar="FILE.toml", help="write the scene with the fitted values")
    _scripting(fit)
    _imports_option(fit)
    fit.set_defaults(func=_delegate("identify", "fit_command"))


def main(argv: list[str] | None = None) -> int:
    """Run the command line; return the exit code (never raises for bad input)."""
    parser = build_parser()
    try:
        args = parser.parse_args(argv)
    except _Usage as exc:
        print(f"{exc} (see contactdyn --help)", file=sys.stderr)  # one line, as every bad input
        return EXIT_USAGE
    except SystemExit as exc:  # --help, --version
        return int(exc.code or 0) if isinstance(exc.code, int | None) else EXIT_USAGE
    from .errors import numerical_errors  # (numpy: after --help)
    from .scene.user_laws import refuse_imports

    NUMERICAL = numerical_errors()  # noqa: N806 (the sweep's name for the same tuple)
    refuse_imports(bool(getattr(args, "no_imports", False)))  # this command's policy, not a previous one's
    try:
        return args.func(args)
    except (SceneError, RobotError, RunFileError) as exc:
        return _fail(args, exc, EXIT_USAGE)
    except ContactdynError as exc:
        return _fail(args, exc, EXIT_FAILED)
    except NUMERICAL as exc:  # a blow-up numpy noticed before the simulator did: the run failed
        return _fail(args, f"the run blew up: {type(exc).__name__}: {exc}", EXIT_FAILED)
    except BrokenPipeError:  # the reader of our output left (`contactdyn list | head`): not an error
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())  # no second error at exit's flush
        return EXIT_OK
    except OSError as exc:  # an output path that cannot be written (a file where a folder must go, ...)
        where = exc.filename if exc.filename is not None else "?"
        return _fail(args, f"{where}: {exc.strerror or exc}", EXIT_USAGE)
    except KeyboardInterrupt:
        hint = " (finished runs are saved; run the same command again to resume)" if args.command == "sweep" else ""
        print(f"contactdyn: interrupted{hint}", file=sys.stderr)
        return EXIT_INTERRUPTED


def _fail(args: argparse.Namespace, exc: Exception | str, code: int) -> int:
    text = _printable(f"contactdyn: error: {exc}")
    if len(text) > MAX_MESSAGE:  # whatever a value held, the message stays a readable line
        text = f"{text[:MAX_MESSAGE - 250]} ... {text[-200:]} ({len(text)} characters)"
    print(text, file=sys.stderr)
    if getattr(args, "json", False):
        _emit_json({"status": "bad input" if code == EXIT_USAGE else "failed", "error": str(exc),
                    "exit_code": code})
    return code


if __name__ == "__main__":
    sys.exit(main())
