"""A box landing on four frictional corners in hostile ways: does the run end, what does it cost, does the audit close?

    PYTHONPATH=. python3 benchmarks/hostile_landings.py [--duration 0.6]

``sims/drop_box.toml``'s box (1 kg, 0.1 × 0.2 × 0.3 m) released 0.1 m above the table with Coulomb friction μ on its
four bottom corners (two tangents each) and a start velocity (x, y, z [m/s], yaw, pitch, roll rates [rad/s]):
sliding slowly, spinning, sliding fast with high friction (it trips over its front edge), tumbling. Per case: whether
the run ended (else its error, first line), impacts, events by kind, CPU [s] (after an untimed short run that loads
the compiled code), and the energy audit's residual [J]
against its tolerance. With friction the four corners' impulse split decides the friction impulses
(``model/impact.py``); these are the cases that exercise it.

Writes benchmarks/out/hostile_landings.json.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
import warnings
from collections import Counter
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from contactdyn import load_scene, simulate  # noqa: E402
from contactdyn.errors import ContactdynError  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent
OUT = Path(__file__).parent / "out"
#: (name, μ, start velocity of the box's six coordinates)
CASES = [
    ("slides and spins", 0.2, [0.5, 0.3, 0.0, 3.0, 0.0, 0.0]),
    ("spins in place", 0.5, [0.0, 0.0, 0.0, 5.0, 0.0, 0.0]),
    ("slides fast, trips", 0.9, [1.0, 0.0, 0.0, 0.0, 0.0, 0.0]),
    ("tumbles", 0.3, [0.2, -0.1, 0.0, 0.0, 0.4, 0.2]),
]


def landing(mu: float, velocity0: list[float], duration: float) -> dict:
    """One case's run and what it shows."""
    overrides = {f"contact.c{k}.tangent": {"model": "friction", "mu": mu,
                                           "directions": [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]} for k in range(1, 5)}
    overrides.update({"body.box.velocity0": velocity0, "duration": duration})
    scene = load_scene(ROOT / "sims" / "drop_box.toml", overrides)
    c0 = time.process_time()
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            r = simulate(scene)
    except ContactdynError as err:
        return {"ended": False, "error": str(err).splitlines()[0], "cpu_s": time.process_time() - c0}
    residual = r.meta["checks"]["energy_residual"]
    return {"ended": True, "cpu_s": time.process_time() - c0, "impacts": len(r.impacts),
            "events": dict(Counter(e["kind"] for e in r.events)), "audit_J": residual["value"],
            "audit_tol_J": residual["tol"]}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--duration", type=float, default=0.6, help="simulated time per case [s]")
    args = parser.parse_args(argv)
    rows = []
    landing(*CASES[0][1:], 0.01)  # (untimed: numba's code loaded or compiled)
    print("| case | μ | ended | impacts | events | CPU [s] | audit [J] (tol) |\n|---|---|---|---|---|---|---|")
    for name, mu, v0 in CASES:
        row = {"case": name, "mu": mu, "velocity0": v0, **landing(mu, v0, args.duration)}
        rows.append(row)
        if row["ended"]:
            print(f"| {name} | {mu} | yes | {row['impacts']} | {sum(row['events'].values())} | {row['cpu_s']:.2f} | "
                  f"{row['audit_J']:.1e} ({row['audit_tol_J']:.1e}) |")
        else:
            print(f"| {name} | {mu} | no: {row['error'][:90]} | | | {row['cpu_s']:.2f} | |")
    OUT.mkdir(exist_ok=True)
    (OUT / "hostile_landings.json").write_text(json.dumps({"duration_s": args.duration, "rows": rows}, indent=1))
    print(f"wrote {OUT / 'hostile_landings.json'}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
