"""sims/force_loop_real_cell.toml three ways: continuous, sampled without joint friction, sampled with it.

The scene is a planar 2R pressing 50 N on a compliant workpiece under A10 with integral action, its joints with
Coulomb friction (3 and 1.5 N·m), its controller at 500 Hz with a 2-sample delay. This runs it

- continuous: the scene with ``controller.sample_rate`` and ``controller.delay`` removed from its document;
- sampled, no joint friction: ``robot.joint.q1.friction = 0``, ``robot.joint.q2.friction = 0`` (overrides);
- sampled, with joint friction: the scene as written,

prints per run the contact force's steady behaviour (over the last second: half its peak-to-peak [N], the mean
period of its oscillation about its mean [s], its mean [N]; a run whose |F_n| passes 1000 N is "diverged", with
the time) and its CPU time and path, and draws F_n over time into docs/figures/real_cell/force_loop_real_cell.png.

    PYTHONPATH=$PWD python3 benchmarks/real_cell_demo.py [--duration 3.0]
"""

from __future__ import annotations

import argparse
import time
import tomllib
import warnings
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from contactdyn import parse_scene, simulate  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
SCENE = ROOT / "sims" / "force_loop_real_cell.toml"
FIGURE = ROOT / "docs" / "figures" / "real_cell" / "force_loop_real_cell.png"
DIVERGED = 1000.0  #: [N] |F_n| beyond this: the run has diverged
NO_FRICTION = {"robot.joint.q1.friction": 0.0, "robot.joint.q2.friction": 0.0}


def continuous_document() -> dict:
    """The scene's document with its controller's sampling removed."""
    doc = tomllib.loads(SCENE.read_text())
    for key in ("sample_rate", "delay"):
        doc["controller"].pop(key)
    return doc


def runs(duration: float) -> dict:
    """{label: Result} of the three runs."""
    cases = {"continuous, joint friction": (continuous_document(), {}),
             "500 Hz, 2 samples, no joint friction": (tomllib.loads(SCENE.read_text()), NO_FRICTION),
             "500 Hz, 2 samples, joint friction": (tomllib.loads(SCENE.read_text()), {})}
    out = {}
    for label, (doc, over) in cases.items():
        doc["duration"] = duration
        t0 = time.process_time()
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            result = simulate(parse_scene(doc, over, SCENE))
        out[label] = (result, time.process_time() - t0)
    return out


def steady(t: np.ndarray, f: np.ndarray) -> dict:
    """The last second's amplitude (half the peak-to-peak) [N], period [s] and mean [N], or where it diverged."""
    over = np.flatnonzero(np.abs(f) > DIVERGED)
    if over.size:
        return {"diverged_at": float(t[over[0]])}
    last = t >= t[-1] - 1.0
    ft, ff = t[last], f[last]
    e = ff - ff.mean()
    up = ft[1:][(e[:-1] < 0.0) & (e[1:] >= 0.0)]  # upward crossings of the mean
    period = float(np.mean(np.diff(up))) if up.size > 2 else float("nan")
    return {"amplitude": float(np.ptp(ff)) / 2.0, "period": period, "mean": float(ff.mean())}


def figure(results: dict) -> None:
    fig, axes = plt.subplots(2, 1, figsize=(9, 6.5), sharex=True)
    colors = ["tab:blue", "tab:red", "tab:green"]
    for (label, (r, _)), c in zip(results.items(), colors, strict=True):
        f = r["contact.tip.F_n"]
        keep = np.cumsum(np.abs(f) > DIVERGED) == 0  # up to the divergence
        for ax in axes:
            ax.plot(r.t[keep], f[keep], color=c, lw=0.9, label=label)
    axes[0].set_ylim(-5.0, 110.0)
    axes[0].set_title("sims/force_loop_real_cell.toml: F_d = 50 N, K_F = 400/s (curves cut where |F_n| > 1 kN)")
    axes[1].set_ylim(48.5, 51.5)
    axes[1].set_title("zoom on the set-point")
    for ax in axes:
        ax.axhline(50.0, color="k", lw=0.5, ls=":")
        ax.set_ylabel("F_n [N]")
        ax.grid(alpha=0.3)
    axes[0].legend(loc="upper right", fontsize=8)
    axes[1].set_xlabel("t [s]")
    fig.tight_layout()
    FIGURE.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(FIGURE, dpi=110)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--duration", type=float, default=3.0, help="[s] each run's duration")
    args = parser.parse_args()
    results = runs(args.duration)
    print(f"{'run':40s} {'amplitude [N]':>14s} {'period [s]':>11s} {'mean F_n [N]':>13s} {'CPU [s]':>8s}  path")
    for label, (r, cpu) in results.items():
        s = steady(r.t, r["contact.tip.F_n"])
        paths = ", ".join(sorted({p["path"] for p in r.stats["paths"].values()}))
        if "diverged_at" in s:
            diverged = f"diverged at t = {s['diverged_at']:.3f} s"
            print(f"{label:40s} {diverged:>40s} {cpu:8.2f}  {paths}")
        else:
            print(f"{label:40s} {s['amplitude']:14.3f} {s['period']:11.4f} {s['mean']:13.3f} {cpu:8.2f}  {paths}")
    figure(results)
    print(f"figure: {FIGURE.relative_to(ROOT)}")


if __name__ == "__main__":
    main()
