"""Case 3's stability maps: A7 over (K_p, K_v), A10 over (K_F, K_v), two readings of H, surfaces (a) and (b).

White circles: the scenes' gains (A7: K_p = 100, K_v = 20; A10: K_F = 3, K_v = 40, which has no
effect along case 3's single, force-controlled direction); stars: the most stable (or least
unstable) grid point.
A10's panels use the law as written (cancel = "target") except the last column, which cancels the
measured force as the scenes do. Each point is the dominant pole of the contact phase linearised
about its 100 N equilibrium (``contactdyn.stability``: finite differences of the simulator's own
right-hand side), with the
paper's drive as written (no twist damping). Writes docs/figures/case3_stability/*.png and
benchmarks/out/case3_stability.json.

    PYTHONPATH=$PWD python3 docs/case3_stability.py
"""

from __future__ import annotations

import json
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from contactdyn.stability import ContactLoop, contact_phase_scene, stability_map  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
FIG = ROOT / "docs" / "figures" / "case3_stability"
OUT = ROOT / "benchmarks" / "out" / "case3_stability.json"
Q0 = [1.0]  # [m] q3 with the tip on the undeformed surface
NOMINAL = {"b": {"k": 1e5, "b": 0.5, "m": 10.0}, "a": {"k": 5e4, "b": 0.333, "m": 10.0}}  # exact (b); (a) its (b)-type
MASSLESS = {"b": {"k": 1e5, "b": 2000.0, "m": 0.0}, "a": {"k": 5e4, "b": 2000.0, "m": 0.0}}
KP = np.logspace(0, 5, 41)  # [1/s²]
KV = np.logspace(-1, 3, 33)  # [1/s]
KF = np.logspace(-1, 3, 33)  # [1/s]


def loop(surface: str, law: str, inertia: str, nominal: dict | None = None, cancel: str = "target"
         ) -> ContactLoop:
    over = {"robot.drive.twist_damping": 0.0, "phase.0.controller.inertia": inertia}
    if law == "force":
        over["phase.0.controller.cancel"] = cancel
    if nominal is not None:
        over["phase.0.controller.nominal"] = nominal
    return ContactLoop(contact_phase_scene(f"case3_{surface}_{law}", Q0, over))


def panels() -> list[dict]:
    out = []
    for surface in "ba":
        for inertia in ("link", "model"):
            out.append({"law": "A7", "surface": surface, "inertia": inertia, "nominal": None,
                        "x": ("kp", KP), "y": ("kv", KV), "scene": (100.0, 20.0) if inertia == "link" else None})
    for surface in "ba":
        for nominal_kind, table, inertia, cancel in (("exact", NOMINAL, "link", "target"),
                                                     ("exact", NOMINAL, "model", "target"),
                                                     ("massless", MASSLESS, "link", "target"),
                                                     ("massless", MASSLESS, "model", "target"),
                                                     ("massless", MASSLESS, "link", "measured")):
            out.append({"law": "A10", "surface": surface, "inertia": inertia, "nominal": nominal_kind,
                        "cancel": cancel, "nominal_table": table[surface], "x": ("kf", KF), "y": ("kv", KV),
                        "scene": (3.0, 40.0) if (nominal_kind, inertia) == ("massless", "link") else None})
    return out


def draw(ax, p: dict, poles: np.ndarray):
    (xn, xs), (_, ys) = p["x"], p["y"]
    re = poles.real
    lim = 10.0  # [1/s] colour range
    mesh = ax.pcolormesh(xs, ys, np.clip(re, -lim, lim), cmap="RdBu_r", vmin=-lim, vmax=lim, shading="auto")
    if re.min() < 0.0 < re.max():
        ax.contour(xs, ys, re, levels=[0.0], colors="k", linewidths=1.2)
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel({"kp": "K_p [1/s²]", "kf": "K_F [1/s]"}[xn])
    ax.set_ylabel("K_v [1/s]")
    nominal = "" if p["nominal"] is None else f", {p['nominal']} nominal, {p['cancel']}"
    ax.set_title(f"{p['law']} on ({p['surface']}), H = {p['inertia']}{nominal}", fontsize=9)
    i, j = np.unravel_index(np.argmin(re), re.shape)
    ax.plot(xs[j], ys[i], "k*", ms=8)  # the most stable grid point
    if p.get("scene") is not None:  # the scene's own gains
        ax.plot(*p["scene"], "wo", mec="k", ms=7)
    return mesh


def main() -> None:
    FIG.mkdir(parents=True, exist_ok=True)
    OUT.parent.mkdir(parents=True, exist_ok=True)
    records = []
    figs = {"A7": plt.subplots(2, 2, figsize=(10, 8), constrained_layout=True),
            "A10": plt.subplots(2, 5, figsize=(22, 8), constrained_layout=True)}
    counters = {"A7": 0, "A10": 0}
    meshes = {}
    for p in panels():
        poles = stability_map(loop(p["surface"], "position" if p["law"] == "A7" else "force", p["inertia"],
                                   p.get("nominal_table"), p.get("cancel", "target")), p["x"], p["y"])
        fig, axes = figs[p["law"]]
        ax = axes.flat[counters[p["law"]]]
        counters[p["law"]] += 1
        meshes[p["law"]] = draw(ax, p, poles)
        re = poles.real
        i, j = np.unravel_index(np.argmin(re), re.shape)
        rec = {k: p.get(k) for k in ("law", "surface", "inertia", "nominal", "cancel")}
        rec.update({"stable_fraction": float(np.mean(re < 0.0)), "best": {p["x"][0]: float(p["x"][1][j]),
                    p["y"][0]: float(p["y"][1][i]), "pole": [float(poles[i, j].real), float(poles[i, j].imag)]},
                    "max_kv_effect": float(np.max(np.ptp(re, axis=0))) if p["law"] == "A10" else None})
        records.append(rec)
        print(f"{rec['law']:4s} ({rec['surface']}) H={rec['inertia']:5s} nominal={str(rec['nominal']):8s} "
              f"{str(rec['cancel']):8s} stable {100 * rec['stable_fraction']:5.1f} %  best {rec['best']}")
    for law, (fig, axes) in figs.items():
        fig.colorbar(meshes[law], ax=axes, label="Re(dominant pole) [1/s] (blue: stable; black line: Re = 0)")
        fig.savefig(FIG / f"{law.lower()}_map.png", dpi=90)
    OUT.write_text(json.dumps(records, indent=1))


if __name__ == "__main__":
    main()
