"""Reading a sweep's summary back: its failures for the console, a metric plotted against a parameter."""

from __future__ import annotations

import math
import re
from pathlib import Path
from typing import Any

from ..errors import SceneError
from ..output.result import atomic_path

__all__ = ["failures", "failure_lines", "plot_over"]

ERROR_LINES = 3  #: lines of each failed run's error shown on the console
LINE_CHARS = 200  #: longest error line shown


def _read(summary: Path):
    import pandas as pd

    return pd.read_parquet(summary)


def failures(summary: Path, keys: list[str]) -> list[dict[str, Any]]:
    """The runs whose status is not ``ok``: run id, status, their parameters and error text."""
    frame = _read(summary)
    out = []
    for _, row in frame[frame.status != "ok"].iterrows():
        params = {k: row[k] for k in keys if k in frame.columns and not _unset(row[k])}  # ([[run]] rows set some)
        out.append({"run_id": row.run_id, "status": row.status, "params": params, "error": str(row.error)})
    return out


def failure_lines(rows: list[dict[str, Any]]) -> list[str]:
    """Console lines: one header per failed run, then the first lines of its error, indented."""
    lines = []
    for r in rows:
        params = ", ".join(f"{k} = {_value(v)}" for k, v in r["params"].items())
        lines.append(f"  {r['status']} {r['run_id']} ({params}):")
        text = r["error"].strip().splitlines() or ["(no message)"]
        for line in text[:ERROR_LINES]:
            lines.append(f"      {line[:LINE_CHARS]}{'...' if len(line) > LINE_CHARS else ''}")
        if len(text) > ERROR_LINES:
            lines.append(f"      ... ({len(text) - ERROR_LINES} more lines in runs/{r['run_id']}.failed.json)")
    return lines


def _unset(v: Any) -> bool:
    """A key the run does not set: the summary's empty cell (NaN, None)."""
    return v is None or (isinstance(v, float) and math.isnan(v))


def _value(v: Any) -> str:
    return f"{v:g}" if isinstance(v, float) else str(v)


def plot_over(summary: Path, y: str, x: str, keys: list[str], out: Path) -> Path:
    """Draw metric ``y`` against swept parameter ``x`` (one line per value of the other parameters)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    frame = _read(summary)
    metrics = [c for c in frame.columns if c not in (*keys, "run_id", "status", "error")]
    if y not in metrics:
        raise SceneError("--plot", f"a metric of the summary ({', '.join(metrics)})", y)
    others = [k for k in keys if k != x]
    fig, ax = plt.subplots(figsize=(6.4, 4.2))
    groups = frame.groupby(others, dropna=False, sort=True) if others else [((), frame)]
    for label, part in groups:
        part = part.sort_values(x)
        label = label if isinstance(label, tuple) else (label,)
        name = ", ".join(f"{k} = {_value(v)}" for k, v in zip(others, label, strict=True)) or None
        ax.plot(part[x], part[y], marker="o", label=name)
    xs = [float(v) for v in frame[x] if isinstance(v, int | float) and math.isfinite(v)]
    if xs and min(xs) > 0 and max(xs) / min(xs) >= 100:
        ax.set_xscale("log")
    ax.set_xlabel(x)
    ax.set_ylabel(f"{y} [{_unit(y)}]" if _unit(y) else y)
    ax.set_title(f"{y} over {x} ({len(frame)} runs, failed runs left out)", fontsize=9)
    if others:
        ax.legend(fontsize=7)
    ax.grid(alpha=0.3)
    fig.tight_layout()
    path = out / f"plot_{_safe(y)}_over_{_safe(x)}.png"
    atomic_path(path, lambda tmp: fig.savefig(tmp, dpi=120, format="png"))
    plt.close(fig)
    return path


def _unit(metric: str) -> str:
    from ..output.metrics import UNITS

    return {**UNITS, "wall_s": "s"}.get(metric.rpartition(".")[2], "")


def _safe(name: str) -> str:
    return re.sub(r"[^A-Za-z0-9_.-]+", "_", name)
