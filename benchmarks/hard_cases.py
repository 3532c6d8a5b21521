"""The hard cases (benchmarks/hard/*.toml) at default settings: integrator, cost, error.

    python benchmarks/hard_cases.py [--out benchmarks/out/hard_cases] [--repeats 3] [CASE ...]

Each case runs at its scene's settings (``solver.method = "auto"``, rtol 1e-8) and is
compared with a reference run of the same scene by DOP853 at rtol 1e-11 (explicit even for
the stiff cases: at such tolerances its stability-bound steps are no burden, while Radau's
steps collapse — the 1e10 N/m contact at rtol 1e-10 takes it 1.4 million steps), its own
error estimated against half that tolerance, with the metrics of ``contactdyn bench``. Extra checks: the
near-rigid cases against the rigid model (their k → ∞ limit), B1 unbonded (a grazing
first touch) against B1 bonded, and the energy drift of the undamped ringing. Writes
``hard_cases.md`` and ``hard_cases.json``.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

import numpy as np  # noqa: E402
from timing import interleaved  # noqa: E402

from contactdyn.analysis.workprecision import errors  # noqa: E402
from contactdyn.errors import ContactdynError  # noqa: E402
from contactdyn.model.system import System  # noqa: E402
from contactdyn.output.result import Result  # noqa: E402
from contactdyn.scene.scene_file import load_scene  # noqa: E402
from contactdyn.simulate import run_system  # noqa: E402

HARD = Path(__file__).resolve().parent / "hard"
RIGID = {"contact.tip.normal": {"direction": [0.0, 1.0, 0.0], "model": "rigid"}}
REFERENCE_RTOL = {}  #: per case, default 1e-11
CASES = {  # name: (scene, overrides)
    "stiff_1e8": (HARD / "stiff.toml", {}),
    "stiff_1e10": (HARD / "stiff.toml", {"contact.tip.normal.k": 1e10, "contact.tip.normal.b": 3.0e5}),
    "fast_mass": (HARD / "fast_mass.toml", {}),
    "undamped_10s": (HARD / "undamped.toml", {}),
    "grazing_first_touch": ("b1", {"contact.tip.bonded": False, "solver.method": "auto"}),
    "grazing_landing": (HARD / "grazing.toml", {}),
    "bounce": (HARD / "bounce.toml", {}),
    "stick_slip": (HARD / "stickslip.toml", {}),
    "singular_pose": (HARD / "singular.toml", {}),
    "mass_ratio_1e4": (HARD / "mass_ratio.toml", {}),
}


def run(scene_path, overrides: dict, repeats: int = 1) -> tuple[Result | None, float, str]:
    """(result, median wall [s], status) of one setting."""
    try:
        system = System(load_scene(scene_path, overrides))
        times = interleaved({"run": lambda: run_system(system)}, repeats)["run"]
        return times.last, times.wall, "ok"
    except ContactdynError as exc:
        return None, float("nan"), str(exc)


def energy_drift(result: Result, scene_path, overrides: dict) -> float:
    """max |E(t) − E(0)| [J] of the conservative undamped case (see benchmarks/hard/undamped.toml)."""
    scene = load_scene(scene_path, overrides)
    system = System(scene)
    robot = system.robot
    ks = scene.contacts["tip"].normal_chain.environment[0].k
    me = scene.contacts["tip"].normal_chain.environment[1].m
    ys = scene.contacts["tip"].point[1]
    kp = scene.phases[0].controller.kp[0]
    fd = scene.phases[0].forces[0].ramp.value
    x_d = scene.phases[0].reference.start[0]
    label = system.mass_labels[0]
    E = []
    for k in range(len(result.t)):
        q, v = result["q"][k], result["v"][k]
        T = robot.kinetic_energy(q, v)
        ym, vm = result[f"mass.{label}.x"][k], result[f"mass.{label}.v"][k]
        tip = result["tip"][k]
        E.append(T + 0.5 * me * vm**2 + 0.5 * ks * (ym - ys) ** 2 + 0.5 * kp * (x_d - tip[0]) ** 2 + fd * tip[1])
    E = np.asarray(E)
    return float(np.max(np.abs(E - E[0])))


def case(name: str, repeats: int) -> dict:
    scene_path, overrides = CASES[name]
    res, wall, status = run(scene_path, overrides, repeats)
    row: dict = {"case": name, "status": status, "wall_s": wall}
    if res is None:
        return row
    s = res.stats
    row.update(integrator=s.get("segments_by_method", {}), rhs_evals=s["rhs_evals"], steps=s["steps"],
               events=s["events"], impacts=len(res.impacts), stiffness=s.get("stiffness", 0.0),
               finite=bool(all(np.all(np.isfinite(v)) for v in res.channels.values())))
    r = REFERENCE_RTOL.get(name, 1e-11)
    explicit = {**overrides, "solver.method": "DOP853"}
    ref, _, ref_status = run(scene_path, {**explicit, "solver.rtol": r, "solver.atol": r * 1e-2})
    half, _, _ = run(scene_path, {**explicit, "solver.rtol": r / 2, "solver.atol": r * 0.5e-2})
    row["reference_rtol"] = r
    if ref is not None and half is not None:
        try:
            row["force_error_N"], row["position_error_m"] = errors(res, ref)
            row["reference_error_N"], _ = errors(ref, half)
        except ContactdynError as exc:  # a different event sequence: no common grid to compare on
            row["reference_status"] = str(exc)
    else:
        row["reference_status"] = ref_status
    if name.startswith("stiff"):
        rigid, _, _ = run(scene_path, {**overrides, **RIGID})
        if rigid is not None:
            row["vs_rigid_force_N"], row["vs_rigid_position_m"] = errors(res, rigid)
    if name == "grazing_first_touch":
        bonded, _, _ = run("b1", {})
        if bonded is not None:
            row["vs_bonded_force_N"], row["vs_bonded_position_m"] = errors(res, bonded)
            row["first_touch_impulse_Ns"] = res.impacts[0]["normal_impulse"] if res.impacts else None
    if name == "undamped_10s":
        row["energy_drift_J"] = energy_drift(res, scene_path, overrides)
    return row


def markdown(rows: list[dict]) -> str:
    lines = ["| case | integrator (segments) | wall [s] | rhs evals | events | F_n error [N] | tip error [m] | "
             "reference's own F_n error [N] | other check | status |", "|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        integ = ", ".join(f"{k}×{v}" for k, v in r.get("integrator", {}).items())
        other = []
        if "vs_rigid_force_N" in r:
            other.append(f"vs rigid: F_n {r['vs_rigid_force_N']:.2e} N, tip {r['vs_rigid_position_m']:.1e} m")
        if "vs_bonded_force_N" in r:
            other.append(f"vs bonded B1: F_n {r['vs_bonded_force_N']:.1e} N")
        if "energy_drift_J" in r:
            other.append(f"energy drift {r['energy_drift_J']:.1e} J")
        status = r["status"] if r["status"] == "ok" else r["status"].replace("|", "/")[:200]
        lines.append(f"| {r['case']} | {integ} | {r['wall_s']:.3g} | {r.get('rhs_evals', '')} | "
                     f"{r.get('events', '')} | "
                     f"{r.get('force_error_N', float('nan')):.1e} | {r.get('position_error_m', float('nan')):.1e} | "
                     f"{r.get('reference_error_N', float('nan')):.1e} | {'; '.join(other)} | {status} |")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("cases", nargs="*", default=list(CASES))
    p.add_argument("--out", default=str(Path(__file__).resolve().parent / "out" / "hard_cases"))
    p.add_argument("--repeats", type=int, default=3)
    args = p.parse_args(argv)
    rows = []
    for name in args.cases:
        rows.append(case(name, args.repeats))
        print(json.dumps(rows[-1], default=str), flush=True)
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.with_suffix(".json").write_text(json.dumps(rows, indent=1, default=str))
    out.with_suffix(".md").write_text(markdown(rows) + "\n")
    print(markdown(rows))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
