"""Paper-style figures from a run: the equivalents of Figs. 10–19 of Potkonjak et al. (1999).

:func:`plot_result` draws every figure a run's channels support and writes each as PNG and/or
SVG; :func:`plot_command` is the ``contactdyn plot RUN`` entry point. A figure is drawn only
when its channels exist (a run without motors has no voltage figure). Every axis names its
quantity and unit; time axes mark the run's touch, separation and phase events.

=================================  =========================================================
file name                          content (paper figure)
=================================  =========================================================
``fig10_voltages``                 motor voltages u [V] (Fig. 10, case 1)
``fig10b_body_velocity``           environment body velocity and its set-point (case 1's cart)
``fig11_deformations_horizontal``  chain stage deformations, horizontal directions (Fig. 11)
``fig12_deformations_vertical``    chain stage deformations, vertical directions (Fig. 12)
``fig13_contact_forces``           contact forces per direction with set-points (Fig. 13)
``fig14_tip_motion``               tip motion: (a) along the surface, (b) across it (Fig. 14)
``fig15_forces_friction``          (a) pressure force, (b) friction, (c) slip velocity (Fig. 15)
``fig16_tracking_errors``          tip tracking errors before the first touch (Fig. 16)
``fig17_force_position_errors``    force error and position errors in contact (Figs. 17–19)
=================================  =========================================================
"""

from __future__ import annotations

import argparse
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import ContactdynError, SceneError
from .result import Result, atomic_path, load_result, run_files
from .run_check import check_drawable

__all__ = ["FIGURES", "FORMATS", "plot_result", "plot_command", "figure_names"]

FORMATS = ("png", "svg")
DPI = 100  #: PNG resolution [dots per inch]; 7 × 5 in figures stay well under 200 kB
FIGSIZE = (7.0, 5.0)  #: [in]
EVENT_STYLE = {"touch": ("tab:green", "touch"), "separate": ("tab:red", "separation"),
               "phase": ("0.5", "phase change")}
VERTICAL_COS = 0.7  #: a chain direction with |u_z| above this is "vertical" (cos 45.6°)
MM = 1e3  #: [mm/m]


@dataclass(frozen=True)
class Line:
    t: np.ndarray  #: [s]
    y: np.ndarray  #: in the panel's unit
    label: str
    style: str = "-"
    color: str | None = None  #: matplotlib colour; None: the next in the cycle


@dataclass(frozen=True)
class Panel:
    ylabel: str  #: quantity and [unit]
    lines: tuple[Line, ...]
    title: str = ""


@dataclass(frozen=True)
class FigureSpec:
    name: str
    title: str
    build: Callable[[Result], list[Panel] | None]


# ---- reading a run ------------------------------------------------------------------------
def _contacts(result: Result) -> list[str]:
    names = result.meta.get("contacts")
    if names:
        return list(names)
    return sorted({k.split(".")[1] for k in result.channels if k.startswith("contact.") and k.endswith(".F_n")})


def _scene_contact(result: Result, contact: str) -> dict[str, Any]:
    table = result.scene.get("contact", {}).get(contact, {})
    return table if isinstance(table, dict) else {}


def _direction(result: Result, contact: str, label: str) -> np.ndarray | None:
    """World direction of a contact's chain ``n``, ``t1`` or ``t2``, from the saved scene document."""
    table = _scene_contact(result, contact)
    try:
        if label == "n":
            u = np.asarray(table["normal"]["direction"], float)
        else:
            u = np.asarray(table["tangent"]["directions"][int(label[1:]) - 1], float)
    except (KeyError, IndexError, TypeError, ValueError):
        return None
    return u / np.linalg.norm(u) if u.shape == (3,) and np.linalg.norm(u) > 0 else None


def _is_vertical(result: Result, contact: str, label: str) -> bool:
    """Along gravity (|cos| > VERTICAL_COS); without gravity (B1's horizontal plane) or a scene
    document, the paper's reading: the normal is "vertical", the tangents "horizontal"."""
    u = _direction(result, contact, label)
    robot = result.scene.get("robot", {}) if isinstance(result.scene, dict) else {}
    try:
        g = np.asarray(robot.get("gravity", [0.0, 0.0, -9.81]) if isinstance(robot, dict) else [], float)
    except (TypeError, ValueError):
        g = np.zeros(0)
    if u is None or g.shape != (3,) or np.linalg.norm(g) == 0.0:
        return label == "n"
    return abs(u @ g) / np.linalg.norm(g) > VERTICAL_COS


def _direction_name(result: Result, contact: str, label: str) -> str:
    u = _direction(result, contact, label)
    if u is None:
        return "normal" if label == "n" else f"tangent {label}"
    axes = "xyz"
    k = int(np.argmax(np.abs(u)))
    sign = "+" if u[k] > 0 else "−"
    return f"{'normal' if label == 'n' else 'tangent'} {sign}{axes[k]}" if abs(u[k]) > 0.999 else \
        f"{'normal' if label == 'n' else 'tangent'} {label}"


def _stage_label(stage: str, siblings: Iterable[str]) -> str:
    """Paper notation: x″ internal (next to the body or tip), x′ external (at the interface)."""
    side = "e" if stage.startswith("env") else "r"
    same = sorted(s for s in siblings if s[:3] == stage[:3])
    if len(same) == 1:
        return f"x_{side} ({stage})"
    index = int(stage[3:])
    if len(same) == 2:
        return f"x″_{side} internal ({stage})" if index == 1 else f"x′_{side} external ({stage})"
    return f"x_{side}{index} ({stage})"


def _stages(result: Result) -> dict[tuple[str, str], list[str]]:
    """(contact, direction) -> stage names, from channels ``stage.<c>.<dir>.<stage>.x``."""
    found: dict[tuple[str, str], list[str]] = {}
    for key in result.channels:
        parts = key.split(".")
        if len(parts) == 5 and parts[0] == "stage" and parts[4] == "x":
            found.setdefault((parts[1], parts[2]), []).append(parts[3])
    return {k: sorted(v, key=lambda s: (s[:3] != "env", int(s[3:]) if s[3:].isdigit() else 0)) for k, v in
            found.items()}


def _touch_time(result: Result) -> float | None:
    times = [e["t"] for e in result.events if e.get("kind") == "touch"]
    return min(times) if times else None


def _moving(y: np.ndarray, tol: float = 1e-9) -> bool:
    finite = y[np.isfinite(y)]
    return finite.size > 0 and float(np.ptp(finite)) > tol


# ---- the figures ---------------------------------------------------------------------------
def _voltages(result: Result) -> list[Panel] | None:
    lines = []
    t = result.t
    if "u" in result.channels:
        u = np.atleast_2d(result["u"].T).T
        joints = result.meta.get("joints") or [f"joint {i + 1}" for i in range(u.shape[1])]
        lines += [Line(t, u[:, i], f"u_{joints[i]}" if i < len(joints) else f"u_{i + 1}") for i in range(u.shape[1])]
    for key in sorted(result.channels):
        if key.endswith(".u") and key != "u":
            values = np.asarray(result[key])
            if values.ndim == 1:
                lines.append(Line(t, values, f"u_{key[:-2].split('.')[-1]}"))
            else:
                lines += [Line(t, values[:, i], f"u_{key[:-2].split('.')[-1]}{i + 1}") for i in range(values.shape[1])]
    return [Panel("motor voltage u [V]", tuple(lines))] if lines else None


def _body_velocity(result: Result) -> list[Panel] | None:
    bodies = result.meta.get("bodies") or sorted({k.split(".")[1] for k in result.channels
                                                  if k.startswith("body.") and k.endswith(".v")})
    lines = []
    for b in bodies:  # one line per coordinate: body.<b>.v, or body.<b>.<joint>.v for a body with several
        keys = sorted(k for k in result.channels if k.startswith(f"body.{b}.") and k.endswith(".v"))
        if not keys:
            continue
        lines += [Line(result.t, result[key], "v_" + key[len("body."):-len(".v")]) for key in keys]
        servo = result.scene.get("body", {}).get(b, {}).get("servo", {})
        if isinstance(servo, dict) and "velocity" in servo:
            lines.append(Line(result.t, np.full_like(result.t, float(servo["velocity"])), f"v_{b} set-point", "--"))
    return [Panel("body velocity v [m/s]", tuple(lines))] if lines else None


def _deformations(vertical: bool) -> Callable[[Result], list[Panel] | None]:
    def build(result: Result) -> list[Panel] | None:
        panels = []
        for (contact, label), stages in sorted(_stages(result).items()):
            if _is_vertical(result, contact, label) != vertical:
                continue
            lines = tuple(Line(result.t, MM * result[f"stage.{contact}.{label}.{s}.x"], _stage_label(s, stages))
                          for s in stages)
            title = f"contact {contact}, {_direction_name(result, contact, label)}"
            panels.append(Panel("deformation x [mm]", lines, title))
        return panels or None

    return build


def _contact_forces(result: Result) -> list[Panel] | None:
    panels = []
    for c in _contacts(result):
        if f"contact.{c}.F_n" not in result.channels:
            continue
        for label in ("n", "t1", "t2"):
            key = f"contact.{c}.F_n" if label == "n" else f"contact.{c}.{label}.F"
            if key not in result.channels:
                continue
            name = _direction_name(result, c, label)
            lines = [Line(result.t, result[key], f"F ({name})")]
            ref = f"contact.{c}.F_d" if label == "n" else f"contact.{c}.{label}.F_d"
            if ref in result.channels and np.any(np.isfinite(result[ref])):
                lines.append(Line(result.t, result[ref], "set-point F_d", "--"))
            panels.append(Panel("contact force F [N]", tuple(lines), f"contact {c}, {name}"))
    has_chain_or_plain = any(f"contact.{c}.F_f" not in result.channels or f"contact.{c}.t1.F" in result.channels
                             for c in _contacts(result))
    return panels if panels and has_chain_or_plain else None


def _surface(result: Result) -> tuple[np.ndarray, np.ndarray] | None:
    """(point, unit normal) of the first contact, from the saved scene document."""
    for c in _contacts(result):
        table = _scene_contact(result, c)
        u = _direction(result, c, "n")
        if u is not None and "point" in table and table.get("body", "ground") == "ground":
            return np.asarray(table["point"], float), u
    return None


def _tip_motion(result: Result) -> list[Panel] | None:
    if "tip" not in result.channels:
        return None
    tip, t = result["tip"], result.t
    ref = result.channels.get("tip_ref")
    surface = _surface(result)
    normal = surface[1] if surface is not None else np.array([0.0, 0.0, 1.0])
    along = [k for k in range(3) if abs(normal[k]) < 0.5 and (_moving(tip[:, k]) or (ref is not None and
                                                                                   _moving(ref[:, k])))]
    lines_a: list[Line] = []
    for k in along:
        lines_a.append(Line(t, tip[:, k], f"tip {'xyz'[k]}"))
        if ref is not None:
            lines_a.append(Line(t, ref[:, k], f"reference {'xyz'[k]}_d", "--"))
    panels = [Panel("tip position [m]", tuple(lines_a), "(a) along the surface")] if lines_a else []
    if surface is not None:  # Fig. 14(b): in contact the tip's height is the surface's deformation
        point, n = surface
        t_touch = _touch_time(result)
        shown = t >= t_touch if t_touch is not None else np.ones_like(t, bool)
        height = np.where(shown, MM * ((tip - point) @ n), np.nan)
        lines_b = [Line(t, height, "tip height n·(p − p_s)")]
        if ref is not None:
            lines_b.append(Line(t, np.where(shown, MM * ((ref - point) @ n), np.nan), "reference", "--"))
        when = "from the first touch; < 0: surface deformation" if t_touch is not None else "whole run"
        panels.append(Panel("tip height [mm]", tuple(lines_b), f"(b) across the surface, {when}"))
    else:
        k = int(np.argmax(np.abs(normal)))
        lines_b = [Line(t, tip[:, k], f"tip {'xyz'[k]}")]
        if ref is not None:
            lines_b.append(Line(t, ref[:, k], f"reference {'xyz'[k]}_d", "--"))
        panels.append(Panel(f"tip {'xyz'[k]} [m]", tuple(lines_b), "(b) across the surface (normal direction)"))
    return panels


def _friction(result: Result) -> list[Panel] | None:
    for c in _contacts(result):
        if f"contact.{c}.F_f" not in result.channels:
            continue
        t = result.t
        lines_a = [Line(t, result[f"contact.{c}.F_n"], "pressure force F")]
        if np.any(np.isfinite(result[f"contact.{c}.F_d"])):
            lines_a.append(Line(t, result[f"contact.{c}.F_d"], "set-point F_d", "--"))
        F_f = np.atleast_2d(result[f"contact.{c}.F_f"].T).T
        v = np.atleast_2d(result[f"contact.{c}.v_slip"].T).T
        names = [_direction_name(result, c, f"t{i + 1}") for i in range(F_f.shape[1])]
        mu = _scene_contact(result, c).get("tangent", {}).get("mu_k", _scene_contact(result, c).get("tangent", {})
                                                               .get("mu"))
        lines_b = [Line(t, F_f[:, i], f"F_f ({names[i]})") for i in range(F_f.shape[1])]
        if F_f.shape[1] == 2:  # 2-D friction: the cone bounds the magnitude
            lines_b.append(Line(t, np.linalg.norm(F_f, axis=1), "|F_f|", "-", "k"))
        if mu is not None:
            bound = float(mu) * np.maximum(result[f"contact.{c}.F_n"], 0.0)
            lines_b += [Line(t, bound, f"±μF, μ = {float(mu):g}", ":", "0.4"), Line(t, -bound, "", ":", "0.4")]
        touching = result.channels.get(f"contact.{c}.touching", np.ones_like(t))[:, None] > 0.5
        v = np.where(touching, v, np.nan)  # slip exists only in contact
        lines_c = [Line(t, v[:, i], f"v_slip ({names[i]})") for i in range(v.shape[1])]
        return [Panel("contact force F [N]", tuple(lines_a), f"(a) pressure, contact {c}"),
                Panel("friction force F_f [N]", tuple(lines_b), "(b) friction"),
                Panel("slip velocity v [m/s]", tuple(lines_c), "(c) slip")]
    return None


def _tracking(result: Result) -> list[Panel] | None:
    if "tip_ref" not in result.channels or "tip" not in result.channels:
        return None
    t_touch = _touch_time(result)
    keep = result.t <= t_touch if t_touch is not None else np.ones_like(result.t, bool)
    if keep.sum() < 2:
        return None
    err = MM * (result["tip_ref"] - result["tip"])[keep]
    lines = tuple(Line(result.t[keep], err[:, k], f"e_{'xyz'[k]} = {'xyz'[k]}_d − {'xyz'[k]}") for k in range(3)
                  if np.any(np.isfinite(err[:, k])) and (_moving(result["tip_ref"][keep, k])
                                                         or _moving(result["tip"][keep, k])))
    title = "approach, until the first touch" if t_touch is not None else "whole run"
    return [Panel("tip tracking error e [mm]", lines, title)] if lines else None


def _force_position_errors(result: Result) -> list[Panel] | None:
    panels = []
    t = result.t
    for c in _contacts(result):
        for label in ("n", "t1", "t2"):
            ref = f"contact.{c}.F_d" if label == "n" else f"contact.{c}.{label}.F_d"
            F = f"contact.{c}.F_n" if label == "n" else f"contact.{c}.{label}.F"
            if ref not in result.channels or F not in result.channels or not np.any(np.isfinite(result[ref])):
                continue
            touching = result.channels.get(f"contact.{c}.touching", np.ones_like(t)) > 0.5
            err = np.where(touching, result[F] - result[ref], np.nan)
            panels.append(Panel("force error F − F_d [N]", (Line(t, err, f"{_direction_name(result, c, label)}"),),
                                f"force error, contact {c}"))
    if not panels:
        return None
    if "tip_ref" in result.channels:
        t_touch = _touch_time(result)
        after = t >= t_touch if t_touch is not None else np.ones_like(t, bool)
        err = MM * (result["tip_ref"] - result["tip"])
        lines = tuple(Line(t, np.where(after, err[:, k], np.nan), f"e_{'xyz'[k]} = {'xyz'[k]}_d − {'xyz'[k]}")
                      for k in range(3) if np.any(np.isfinite(err[after, k])) and
                      (_moving(result["tip"][after, k]) or _moving(result["tip_ref"][after, k])))
        if lines:
            panels.append(Panel("position error e [mm]", lines, "position error in contact"))
            return panels
    surface = _surface(result)  # a pure force law has no reference: show where the tip went
    if surface is not None and "tip" in result.channels:
        point, n = surface
        t_touch = _touch_time(result)
        after = t >= t_touch if t_touch is not None else np.ones_like(t, bool)
        depth = np.where(after, MM * ((point - result["tip"]) @ n), np.nan)
        panels.append(Panel("tip depth [mm]", (Line(t, depth, "depth n·(p_s − p) below the undeformed surface"),),
                            "tip position in contact (no position reference)"))
    return panels


FIGURES: tuple[FigureSpec, ...] = (
    FigureSpec("fig10_voltages", "Control voltages (paper Fig. 10)", _voltages),
    FigureSpec("fig10b_body_velocity", "Environment body velocity (case 1: the cart keeps v0)", _body_velocity),
    FigureSpec("fig11_deformations_horizontal", "Deformations in the horizontal direction (paper Fig. 11)",
               _deformations(vertical=False)),
    FigureSpec("fig12_deformations_vertical", "Deformations in the vertical direction (paper Fig. 12)",
               _deformations(vertical=True)),
    FigureSpec("fig13_contact_forces", "Contact forces (paper Fig. 13)", _contact_forces),
    FigureSpec("fig14_tip_motion", "Motion of the robot tip (paper Fig. 14)", _tip_motion),
    FigureSpec("fig15_forces_friction", "Contact forces with friction (paper Fig. 15)", _friction),
    FigureSpec("fig16_tracking_errors", "Tracking errors in the approach (paper Fig. 16)", _tracking),
    FigureSpec("fig17_force_position_errors", "Force and position errors in contact (paper Figs. 17–19)",
               _force_position_errors),
)


def figure_names() -> list[str]:
    return [f.name for f in FIGURES]


# ---- drawing -------------------------------------------------------------------------------
def _parse_formats(formats: str | Iterable[str]) -> list[str]:
    items = [f.strip().lower().lstrip(".") for f in (formats.split(",") if isinstance(formats, str) else formats)]
    items = [f for f in items if f]
    bad = [f for f in items if f not in FORMATS]
    if bad or not items:
        raise SceneError("--format", f"a comma-separated list of {', '.join(FORMATS)}",
                         ",".join(items) if items else "nothing")
    return list(dict.fromkeys(items))


def _draw(spec: FigureSpec, panels: list[Panel], result: Result):
    import matplotlib

    matplotlib.use("Agg", force=False)
    from matplotlib.figure import Figure

    fig = Figure(figsize=(FIGSIZE[0], max(FIGSIZE[1], 2.2 * len(panels))), dpi=DPI, layout="constrained")
    axes = fig.subplots(len(panels), 1, sharex=True, squeeze=False)[:, 0]
    events = [e for e in result.events if e.get("kind") in EVENT_STYLE]
    for ax, panel in zip(axes, panels, strict=True):
        for line in panel.lines:
            ax.plot(line.t, line.y, line.style, label=line.label or None, linewidth=1.2, color=line.color)
        seen: set[str] = set()
        for e in events:
            color, name = EVENT_STYLE[e["kind"]]
            ax.axvline(e["t"], color=color, linewidth=0.6, linestyle=":",
                       label=f"{name}" if name not in seen else None)
            seen.add(name)
        ax.set_ylabel(panel.ylabel)
        if panel.title:
            ax.set_title(panel.title, fontsize=9, loc="left")
        ax.grid(True, linewidth=0.3)
        if any(line.label for line in panel.lines):
            ax.legend(fontsize=7, loc="best")
    axes[-1].set_xlabel("time t [s]")
    fig.suptitle(f"{spec.title} — {result.meta.get('name', 'run')}", fontsize=10)
    return fig


def plot_result(result: Result, out_dir: str | Path, formats: str | Iterable[str] = FORMATS,
                only: Iterable[str] | None = None) -> list[Path]:
    """Draw every figure the run supports into ``out_dir``; return the written files.

    ``formats``: ``"png,svg"`` or a list; ``only``: figure names to restrict to (see FIGURES).
    SVG text stays text (searchable, and labels can be checked by tests).
    """
    import matplotlib

    fmts = _parse_formats(formats)
    wanted = set(only) if only is not None else None
    if wanted is not None and (unknown := wanted - set(figure_names())):
        raise ContactdynError(f"plot: unknown figure(s) {sorted(unknown)}; known: {figure_names()}")
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    written: list[Path] = []
    with matplotlib.rc_context({"svg.fonttype": "none", "svg.hashsalt": "contactdyn", "path.simplify": True}):
        for spec in FIGURES:
            if wanted is not None and spec.name not in wanted:
                continue
            panels = spec.build(result)
            if not panels:
                continue
            fig = _draw(spec, panels, result)
            for fmt in fmts:
                path = out / f"{spec.name}.{fmt}"
                meta = {"Date": None} if fmt == "svg" else None
                atomic_path(path, lambda tmp, f=fig, k=fmt, m=meta: f.savefig(tmp, format=k, metadata=m))
                written.append(path)
    return written


def plot_command(args: argparse.Namespace) -> int:
    """``contactdyn plot RUN [--out DIR] [--format png,svg]``: figures of a saved run.

    ``args.run``: the saved run (``NAME``, ``NAME.npz`` or ``NAME.json``); ``args.out``: the
    folder (default ``NAME_figures`` beside the run); ``args.format``: ``png,svg`` by default.
    """
    run = Path(args.run)
    result = load_result(run)
    check_drawable(result)  # what `view` refuses, `plot` refuses too (contactdyn.output.run_check)
    stem = run_files(run)[0].with_suffix("")
    out = Path(args.out) if getattr(args, "out", None) else stem.parent / f"{stem.name}_figures"
    written = plot_result(result, out, getattr(args, "format", None) or ",".join(FORMATS))
    if not written:
        print(f"{run}: no figure applies to this run's channels")
        return 1
    names = sorted({p.stem for p in written})
    print(f"{len(names)} figures ({', '.join(sorted({p.suffix[1:] for p in written}))}) in {out}: {', '.join(names)}")
    return 0
