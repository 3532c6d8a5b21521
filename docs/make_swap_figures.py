"""Figures of the robot swap (README, "Swapping the robot"): the writing task on each arm of the swap matrix.

Usage (from the checkout): first ``python benchmarks/robot_swap.py`` (it saves every run under
benchmarks/out/robot_swap/), then ``python docs/make_swap_figures.py``. Writes
docs/figures/robot_swap/pressure.png (the pencil's normal force against the 5 N set-point, ±10 %
shaded) and docs/figures/robot_swap/circle.png (the pencil point's path on the paper against the
reference circle), one panel per arm that ran, and lists the arms that stopped and why.
"""

from __future__ import annotations

import json
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

from contactdyn.result import load_result  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent
RUNS = ROOT / "benchmarks" / "out" / "robot_swap"
SUMMARY = ROOT / "benchmarks" / "out" / "robot_swap.json"
OUT = ROOT / "docs" / "figures" / "robot_swap"
SET_POINT = 5.0  #: [N]


def main() -> None:
    if not SUMMARY.is_file():
        raise SystemExit(f"{SUMMARY} not found: run `python benchmarks/robot_swap.py` first")
    rows = json.loads(SUMMARY.read_text())["rows"]
    ran = [r for r in rows if r["exit"] == 0]
    OUT.mkdir(parents=True, exist_ok=True)
    results = {r["robot"]: load_result(RUNS / f"{r['robot']}.npz") for r in ran}
    n = len(results)
    cols = min(3, n)
    rows_n = (n + cols - 1) // cols

    fig, axes = plt.subplots(rows_n, cols, figsize=(4.2 * cols, 2.6 * rows_n), sharex=True, sharey=True,
                             squeeze=False)
    for ax, (robot, res) in zip(axes.flat, results.items(), strict=False):
        ax.axhspan(0.9 * SET_POINT, 1.1 * SET_POINT, color="0.85", label="5 N ± 10 %")
        ax.plot(res.t, res["contact.pencil.F_n"], lw=0.8, color="C0", label="F_n")
        ax.axvline(0.5, color="0.5", lw=0.6, ls="--")
        ax.set_title(f"{robot} ({len(res.meta['joints'])} DOF)", fontsize=9)
        ax.set_ylim(0, 12)
    for ax in axes[-1]:
        ax.set_xlabel("t [s]")
    for ax in axes[:, 0]:
        ax.set_ylabel("pencil force [N]")
    for ax in list(axes.flat)[n:]:
        ax.axis("off")
    axes.flat[0].legend(fontsize=7, loc="lower right")
    fig.suptitle("case 2's writing task, only robot.urdf and robot.tip changed: pencil pressure", fontsize=10)
    fig.tight_layout()
    fig.savefig(OUT / "pressure.png", dpi=90)

    fig, axes = plt.subplots(rows_n, cols, figsize=(3.2 * cols, 3.0 * rows_n), squeeze=False)
    for ax, (robot, res) in zip(axes.flat, results.items(), strict=False):
        drawing = res.t > 0.5
        ax.plot(1e3 * res["tip_ref"][drawing, 0], 1e3 * res["tip_ref"][drawing, 1], color="0.6", lw=2.5,
                label="reference")
        ax.plot(1e3 * res["tip"][drawing, 0], 1e3 * res["tip"][drawing, 1], color="C3", lw=0.9, label="pencil point")
        ax.set_aspect("equal")
        ax.set_title(robot, fontsize=9)
        ax.set_xlabel("x [mm]", fontsize=8)
        ax.set_ylabel("y [mm]", fontsize=8)
        ax.tick_params(labelsize=7)
    for ax in list(axes.flat)[n:]:
        ax.axis("off")
    axes.flat[0].legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(OUT / "circle.png", dpi=90)
    for r in rows:
        if r["exit"]:
            print(f"{r['robot']}: exit {r['exit']}: {r['reason']}")
    print(f"wrote {OUT / 'pressure.png'} and {OUT / 'circle.png'}")


if __name__ == "__main__":
    main()
