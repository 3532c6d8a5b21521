"""Regenerate docs/figures/: run each case scene in full and draw the figures reproduction.md shows.

Usage (from the checkout): ``python docs/make_figures.py [scene ...]``. Each run is also saved
as ``runs/<scene>.npz`` + ``.json`` (not committed), and its statistics and impacts are printed.
"""

from __future__ import annotations

import sys
from pathlib import Path

from contactdyn import simulate
from contactdyn.plots import plot_result

ROOT = Path(__file__).resolve().parent.parent
OUT = ROOT / "docs" / "figures"
RUNS = ROOT / "runs"

#: scene -> the figures reproduction.md shows (PNG only, each < 200 kB)
SHOWN = {
    "case1_cart": ["fig10_voltages", "fig10b_body_velocity", "fig11_deformations_horizontal",
                   "fig12_deformations_vertical", "fig13_contact_forces"],
    "case2_writer_b": ["fig14_tip_motion", "fig15_forces_friction", "fig16_tracking_errors"],
    "case2_writer_rigid": ["fig15_forces_friction"],
    "case2_writer_motors": ["fig10_voltages", "fig15_forces_friction"],
    "case2_writer5dof": ["fig15_forces_friction"],
    "case3_b_position": ["fig10_voltages", "fig16_tracking_errors", "fig17_force_position_errors"],
    "case3_a_position": ["fig17_force_position_errors"],
    "case3_b_force": ["fig17_force_position_errors"],
    "case3_a_force": ["fig17_force_position_errors"],
    "case3_b_force_varied": ["fig17_force_position_errors"],
}


def main(names: list[str]) -> int:
    for name in names or list(SHOWN):
        result = simulate(name)
        result.save(RUNS / name)
        s = result.stats
        print(f"{name}: {result.meta['duration']:g} s in {s['wall_s']:.2f} s wall, {s['steps']} steps, "
              f"{s['events']} events")
        for imp in result.impacts:
            print(f"  impact t = {imp['t']:.6f} s: FΔt = {imp['normal_impulse']:.5f} N·s, "
                  f"F_fΔt = {imp['friction_impulse']} N·s, jammed = {imp['jammed']}")
        for path in plot_result(result, OUT / name, "png", only=SHOWN[name]):
            print(f"  {path.relative_to(ROOT)} ({path.stat().st_size // 1000} kB)")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
