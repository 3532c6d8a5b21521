"""A fit's report: terminal text, ``fit.json``, ``fit.md``, ``fit.png``, and the fitted scene (TOML)."""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import numpy as np

from ..output.result import atomic_path, atomic_write
from .fitting import FitResult

__all__ = ["as_dict", "text", "markdown", "figure", "write_report", "save_scene"]


def as_dict(res: FitResult) -> dict[str, Any]:
    """Everything but the time series, JSON-ready (non-finite numbers as null)."""
    doc = {
        "scene": res.scene, "scene_file": res.scene_file, "data": res.data_file,
        "estimates": [{"key": e.key, "value": e.value, "start": e.start, "se": e.se, "ci95": [e.low, e.high],
                       "log_scale": e.log, "bounds": list(e.bounds), "at_bound": e.at_bound,
                       "determined": e.determined, "warnings": list(e.warnings)} for e in res.estimates],
        "correlation": {"keys": [e.key for e in res.estimates], "matrix": res.correlation.tolist()},
        "channels": [{"column": c.name, "samples": c.samples, "noise": c.sigma, "noise_source": c.sigma_source,
                      "residual_rms": c.rms, "rms_over_noise": c.ratio, "warning": c.warning} for c in res.channels],
        "chi2_reduced": res.chi2_red, "dof": res.dof,
        "starts": [{"start": s.start, "end": s.values, "cost": s.cost, "evaluations": s.evaluations,
                    "status": s.status} for s in res.starts],
        "stages": [{"window_s": st.window, "samples": st.samples, "cost": st.cost, "values": st.values,
                    "runs": st.runs} for st in res.stages],
        "failed_runs": [{"values": f.values, "error": f.error} for f in res.failures],
        "runs": res.runs, "wall_s": res.wall_s,
        "settings": {"rtol": res.settings.rtol, "atol": res.settings.atol, "workers": res.settings.workers},
    }
    return _finite(doc)


def _finite(obj: Any) -> Any:
    if isinstance(obj, dict):
        return {k: _finite(v) for k, v in obj.items()}
    if isinstance(obj, list | tuple):
        return [_finite(v) for v in obj]
    if isinstance(obj, float | np.floating):
        return float(obj) if math.isfinite(obj) else None
    return obj


def _note(e) -> str:
    """ok, CORRELATED (only |correlation| > 0.99 with another) or NOT DETERMINED."""
    if e.determined:
        return "ok"
    return "CORRELATED" if all(w.startswith("not determined separately") for w in e.warnings) else "NOT DETERMINED"


def _rows(res: FitResult) -> list[list[str]]:
    rows = []
    for e in res.estimates:
        note = _note(e)
        rows.append([e.key, f"{e.value:.6g}", f"{e.se:.3g}", f"[{e.low:.6g}, {e.high:.6g}]", f"{e.start:.6g}",
                     "log" if e.log else "linear", note])
    return rows


HEADER = ["parameter", "estimate", "std. error", "95 % interval", "start", "scale", ""]


def text(res: FitResult) -> str:
    """The terminal report."""
    rows = [HEADER, *_rows(res)]
    widths = [max(len(r[i]) for r in rows) for i in range(len(HEADER))]
    out = [f"fit of {res.scene} to {res.data_file}: {res.runs} simulations in {res.wall_s:.1f} s, "
           f"reduced chi2 {res.chi2_red:.3f} ({res.dof} degrees of freedom)"]
    out += ["  " + "  ".join(c.ljust(w) for c, w in zip(r, widths, strict=True)).rstrip() for r in rows]
    out.append("  residual RMS per channel (against its noise level):")
    for c in res.channels:
        out.append(f"    {c.name}: {c.rms:.4g} vs noise {c.sigma:.4g} ({c.sigma_source}), ratio {c.ratio:.3f}, "
                   f"{c.samples} samples")
    out += _correlation_lines(res, "  ")
    out += [f"  warning: {e.key}: {w}" for e in res.estimates for w in e.warnings]
    out += [f"  warning: {c.warning}" for c in res.channels if c.warning]
    out += [f"  failed run at {f.values}: {f.error}" for f in res.failures]
    if len(res.starts) > 1:
        out.append("  starts: " + ", ".join(f"cost {s.cost:.6g}" for s in res.starts))
    return "\n".join(out)


def _correlation_lines(res: FitResult, indent: str) -> list[str]:
    if len(res.estimates) < 2:
        return []
    names = [str(i + 1) for i in range(len(res.estimates))]
    out = [f"{indent}correlation matrix (" + ", ".join(f"{n} = {e.key}" for n, e in zip(names, res.estimates,
                                                                                     strict=True)) + "):"]
    for n, row in zip(names, res.correlation, strict=True):
        out.append(f"{indent}  {n}: " + " ".join(f"{v:+.3f}" for v in row))
    return out


def markdown(res: FitResult, figure_name: str | None = "fit.png") -> str:
    out = [f"# Fit of `{res.scene}` to `{res.data_file}`", "",
           f"{res.runs} simulations (rtol {res.settings.rtol:g}, atol {res.settings.atol:g}) in {res.wall_s:.1f} s; "
           f"reduced χ² {res.chi2_red:.3f} with {res.dof} degrees of freedom.", "",
           "| " + " | ".join(HEADER[:-1]) + " | note |", "|" + "---|" * len(HEADER)]
    out += ["| " + " | ".join(f"`{c}`" if i == 0 else c for i, c in enumerate(r)) + " |" for r in _rows(res)]
    out += ["", "| channel | samples | noise σ | source | residual RMS | RMS / σ |", "|---|---|---|---|---|---|"]
    out += [f"| `{c.name}` | {c.samples} | {c.sigma:.4g} | {c.sigma_source} | {c.rms:.4g} | {c.ratio:.3f} |"
            for c in res.channels]
    if len(res.estimates) > 1:
        keys = [e.key for e in res.estimates]
        out += ["", "Correlation matrix:", "", "| | " + " | ".join(f"`{k}`" for k in keys) + " |",
                "|---|" + "---|" * len(keys)]
        out += [f"| `{k}` | " + " | ".join(f"{v:+.3f}" for v in row) + " |"
                for k, row in zip(keys, res.correlation, strict=True)]
    warnings = [f"- **{e.key}**: {w}" for e in res.estimates for w in e.warnings]
    warnings += [f"- {c.warning}" for c in res.channels if c.warning]
    if warnings:
        out += ["", "## Warnings", "", *warnings]
    if res.failures:
        out += ["", "## Failed runs", "", *[f"- at `{f.values}`: {f.error}" for f in res.failures]]
    if figure_name:
        out += ["", f"![data against the fitted run]({figure_name})"]
    return "\n".join(out) + "\n"


def figure(res: FitResult, path: str | Path) -> Path:
    """One panel per column: the data, the run at the start and the fitted run, and the residual."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    n = len(res.series)
    fig, axes = plt.subplots(n, 2, figsize=(11, 2.6 * n), squeeze=False, gridspec_kw={"width_ratios": [3, 2]})
    for (ax, ax_r), s, c in zip(axes, res.series, res.channels, strict=True):
        ax.plot(s["t"], s["data"], ".", ms=2, color="0.6", label="data")
        ax.plot(s["t"], s["start"], "--", lw=1, color="tab:orange", label="scene's values")
        ax.plot(s["t"], s["fitted"], "-", lw=1.2, color="tab:blue", label="fitted")
        ax.set_ylabel(c.name)
        ax_r.plot(s["t"], s["data"] - s["fitted"], ".", ms=2, color="tab:blue")
        ax_r.axhline(c.sigma, color="0.4", lw=0.8, ls=":")
        ax_r.axhline(-c.sigma, color="0.4", lw=0.8, ls=":")
        ax_r.set_ylabel(f"data − fitted (±σ = {c.sigma:.3g})")
    axes[0, 0].legend(loc="best", fontsize=8)
    axes[-1, 0].set_xlabel("t [s]")
    axes[-1, 1].set_xlabel("t [s]")
    fig.tight_layout()
    path = Path(path)
    atomic_path(path, lambda tmp: fig.savefig(tmp, dpi=110, format=path.suffix.lstrip(".") or "png"))
    plt.close(fig)
    return path


def write_report(res: FitResult, out: str | Path) -> dict[str, Path]:
    """fit.json, fit.md and fit.png in ``out``."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    paths = {"json": out / "fit.json", "md": out / "fit.md", "png": out / "fit.png"}
    atomic_write(paths["json"], json.dumps(as_dict(res), indent=1, allow_nan=False))
    atomic_write(paths["md"], markdown(res, paths["png"].name))
    figure(res, paths["png"])
    return paths


def save_scene(res: FitResult, path: str | Path) -> Path:
    """The scene document with the fitted values, as TOML (comments list the estimates)."""
    from ..scene.scene_file import apply_overrides, urdf_beside_scene
    from ..scene.toml_writer import dumps

    doc = apply_overrides(res.document, res.values, res.scene_file)
    robot = doc.get("robot", {})
    if isinstance(robot.get("urdf"), str):  # a URDF beside the original scene stays found from the new file
        robot["urdf"] = urdf_beside_scene(robot["urdf"], res.scene_file)
    lines = [f"Scene {res.scene} with values fitted by `contactdyn fit` to {res.data_file}",
             f"(from {res.scene_file}); estimate ± standard error [95 % interval]:"]
    for e in res.estimates:
        flag = "" if e.determined else f"  {_note(e)}"
        lines.append(f"  {e.key} = {e.value:.6g} ± {e.se:.3g} [{e.low:.6g}, {e.high:.6g}]{flag}")
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    atomic_write(path, dumps(doc, "\n".join(lines)))
    return path


