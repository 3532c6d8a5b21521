"""Case 3's stability maps against simulation: growth or decay rate of the force error in runs of the
contact phase, at gains on both sides of the stable region's boundary, against the real part of the
linearisation's dominant pole (the maps of docs/case3_stability.py). The run's rate is measured two
ways: its own mode nearest the pole in frequency (matrix pencil, ``stability.modal_rate``) and the
envelope's exponential fit (``stability.envelope_rate``, which mixes modes of close rates). Writes
benchmarks/out/case3_stability_check.json.

    PYTHONPATH=$PWD python3 benchmarks/case3_stability_check.py
"""

from __future__ import annotations

import json
from pathlib import Path

from contactdyn.analysis.stability import (
    ContactLoop,
    contact_force_error,
    contact_phase_scene,
    envelope_rate,
    modal_rate,
)

OUT = Path(__file__).resolve().parent / "out" / "case3_stability_check.json"
SOLVER = {"solver.rtol": 1e-9, "solver.atol": 1e-11, "solver.output_rate": 1000.0}
#: (scene, controller overrides, duration [s], fit from [s])
POINTS = [
    ("case3_b_position", {"kp": 1000.0, "kv": 60.0}, 2.0, 1.0),  # link H, just inside
    ("case3_b_position", {"kp": 1000.0, "kv": 100.0}, 0.8, 0.45),  # link H, outside
    ("case3_b_position", {"kp": 400.0, "kv": 40.0, "inertia": "model"}, 0.8, 0.3),  # the former defaults
    ("case3_a_position", {"kp": 1000.0, "kv": 60.0}, 2.0, 1.0),
    ("case3_a_position", {"kp": 1000.0, "kv": 100.0}, 1.2, 0.6),  # two unstable modes, 3.07 and 2.75 /s
    ("case3_a_position", {"kp": 1e4, "kv": 60.0}, 1.2, 0.5),  # one unstable mode
    ("case3_b_force", {"kf": 10.0, "cancel": "target"}, 2.0, 0.8),  # A10 as written, massless nominal;
    # inside, but the next pole (−4.60) is close to the dominant one (−2.90): the fit sees both
    ("case3_b_force", {"kf": 30.0, "cancel": "target"}, 4.0, 1.5),  # inside, next pole −2.78
    ("case3_b_force", {"kf": 60.0, "cancel": "target"}, 2.0, 0.1),  # outside; lifts off at 0.6 s
]


def _relative(rate: float, pole: complex) -> float:
    return rate / pole.real - 1.0


def main() -> None:
    rows = []
    for name, ctl, duration, t_fit in POINTS:
        over = {**SOLVER, "duration": duration, **{f"phase.0.controller.{k}": v for k, v in ctl.items()}}
        scene = contact_phase_scene(name, [1.0], over)
        dom = ContactLoop(scene).linearize().dominant
        t, err = contact_force_error(scene, t_fit)
        modal = modal_rate(t, err, dom)
        try:
            envelope = envelope_rate(t, err, dom)
        except ValueError:  # too few periods in the window
            envelope = float("nan")
        rows.append({"scene": name, "controller": ctl, "pole": [dom.real, dom.imag], "window": [t[0], t[-1]],
                     "modal_rate": modal, "modal_difference": _relative(modal, dom),
                     "envelope_rate": envelope, "envelope_difference": _relative(envelope, dom)})
        print(f"{name:17s} {json.dumps(ctl):45s} pole {dom.real:+8.3f} ± {abs(dom.imag):7.2f}i  "
              f"modal {modal:+8.3f} ({100 * _relative(modal, dom):+.2f} %)  "
              f"envelope {envelope:+8.3f} ({100 * _relative(envelope, dom):+.1f} %)")
    OUT.parent.mkdir(parents=True, exist_ok=True)
    OUT.write_text(json.dumps(rows, indent=1))


if __name__ == "__main__":
    main()
