"""B2 (UR5 press and slide, /work/shared/bench/B2.md): task_pd's orientation hold on the compiled call, before/after.

    PYTHONPATH=. python3 benchmarks/b2_orientation.py [--repeats 7] [--rtols 1e-6,1e-8,1e-10]

Scenes: B2 as shipped (``benchmarks/b2.toml``: task_pd holding the tool axis) and B2 holding tool0's full
orientation instead (``orientation`` = diag(1, −1, −1), the start's). Per scene and rtol (atol = rtol / 100, as
B2's 1e-8 / 1e-10), three variants run interleaved in this process (every variant once per repeat; medians):

* ``before``: the law called from Python per right-hand side (the plan's generic call, the tip's R and J_ω from
  Pinocchio) with cd36de1's numpy ``TaskPD.command`` (:func:`_command_cd36de1`, kept verbatim here): the code
  B2.md profiled (the full orientation did not exist there: that scene has no ``before``);
* ``python``: the same Python path with today's ``TaskPD.command`` (contactdyn.laws.controllers.task_pd_law);
* ``compiled``: the plan's compiled call (contactdyn.compiled.plan_operational with the task PD law; the DOP853 step in
  one compiled call).

The first two are made by switching ``plan_operational.law_in_call`` off for task_pd (monkeypatched). Each run is
``run_system(System(scene))``, timed whole (wall [s], the System's build included). Error: B2.md's metric, max |F_n −
F_n,ref| over the samples with t ∈ [0.05, 1] s, against the compiled call at rtol 1e-12, atol 1e-14 (checked
against the Python path at that tolerance). Ratio: before (or python) / compiled at the same rtol. Writes
benchmarks/out/b2_orientation.json.
"""

from __future__ import annotations

import argparse
import contextlib
import sys
import tomllib
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from timing import interleaved, write_report  # noqa: E402

from contactdyn.compiled import plan_kkt, plan_operational  # noqa: E402
from contactdyn.laws.controllers.pd import TaskPD, _feedforward  # noqa: E402
from contactdyn.model.system import System  # noqa: E402
from contactdyn.scene.scene_file import parse_scene  # noqa: E402
from contactdyn.simulate import run_system  # noqa: E402

HERE = Path(__file__).resolve().parent
OUT = HERE / "out" / "b2_orientation.json"
SCENES = {"B2 (tool axis)": {},
          "B2 full orientation": {"tool_axis": None, "tool_target": None,
                                  "orientation": [[1.0, 0.0, 0.0], [0.0, -1.0, 0.0], [0.0, 0.0, -1.0]]}}
T_FROM = 0.05  #: [s] B2.md's error window starts here


def _command_cd36de1(self, inp):
    """TaskPD.command as it was at cd36de1 (numpy, the tool axis only): B2.md's profiled law."""
    cfg = self.config
    tau = np.zeros(self.nv)
    if inp.x_d is not None:
        tau += inp.J.T @ (self._kp @ (inp.x_d - inp.p_tip) + self._kd @ (inp.v_d - inp.v_tip))
    if cfg.tool_axis is not None:
        a = inp.R_tip @ cfg.tool_axis  # current tool direction (world)
        omega = inp.J_ang @ inp.v
        omega_perp = omega - (omega @ a) * a
        tau += inp.J_ang.T @ (cfg.ko * np.cross(a, cfg.tool_target) - cfg.do * omega_perp)
    if cfg.kd_joint:
        tau -= cfg.kd_joint * inp.v
    f = np.zeros(3)
    for contact, (F_d, _) in inp.force_d.items():
        n = inp.normals[contact]
        f -= F_d * n + cfg.kd_normal * (n @ inp.v_tip) * n
    return tau + inp.J.T @ f + _feedforward(inp, cfg.feedforward), None


@contextlib.contextmanager
def variant(name: str):
    """The code path of a variant (module docstring) while inside."""
    saved = plan_operational.law_in_call, plan_kkt.law_in_call, TaskPD.command
    if name != "compiled":
        def python_path(ctl, original=saved[0]):
            return -1 if isinstance(ctl, TaskPD) else original(ctl)

        plan_operational.law_in_call = plan_kkt.law_in_call = python_path
    if name == "before":
        TaskPD.command = _command_cd36de1
    try:
        yield
    finally:
        plan_operational.law_in_call, plan_kkt.law_in_call, TaskPD.command = saved


def scene(changes: dict, rtol: float):
    doc = tomllib.loads((HERE / "b2.toml").read_text())
    for key, value in changes.items():
        if value is None:
            doc["controller"].pop(key)
        else:
            doc["controller"][key] = value
    return parse_scene(doc, {"solver.rtol": rtol, "solver.atol": rtol * 1e-2})


def run(name: str, changes: dict, rtol: float):
    with variant(name):
        return run_system(System(scene(changes, rtol)))


def force_error(result, reference) -> float:
    """max |F_n − F_n,ref| [N] over the samples with t ≥ T_FROM (the same output grid)."""
    t = np.asarray(result["t"])
    assert np.array_equal(t, np.asarray(reference["t"]))
    keep = t >= T_FROM
    F, F_ref = np.asarray(result["contact.tool.F_n"]), np.asarray(reference["contact.tool.F_n"])  # [N]
    return float(np.max(np.abs(F[keep] - F_ref[keep])))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--repeats", type=int, default=7)
    ap.add_argument("--rtols", default="1e-6,1e-8,1e-10")
    args = ap.parse_args()
    rtols = [float(r) for r in args.rtols.split(",")]
    rows = []
    for label, changes in SCENES.items():
        names = ["compiled", "python"] + (["before"] if "orientation" not in changes else [])
        for name in names:  # compile and warm every path once
            run(name, changes, rtols[0])
        reference = run("compiled", changes, 1e-12)
        check = force_error(run("python", changes, 1e-12), reference)
        print(f"{label}: reference (compiled, rtol 1e-12) vs the Python path at 1e-12: max|dF_n| = {check:.2e} N")
        print(f"{'rtol':>8} {'variant':>9} {'wall [ms]':>10} {'rhs':>6} {'steps':>6} {'max|dF_n| [N]':>14} "
              f"{'fallback':>9} {'ratio':>7}")
        for rtol in rtols:
            times = interleaved({name: (lambda n=name, c=changes, r=rtol: run(n, c, r)) for name in names},
                                args.repeats)
            fast = times["compiled"].wall
            for name in names:
                r = times[name].last
                row = {"scene": label, "rtol": rtol, "atol": rtol * 1e-2, "variant": name,
                       "wall_ms": 1e3 * times[name].wall, "cpu_ms": 1e3 * times[name].cpu,
                       "wall_ms_all": [1e3 * w for w in times[name].wall_s], "rhs_evals": r.stats["rhs_evals"],
                       "steps": r.stats["steps"], "max_dF_n_N": force_error(r, reference),
                       "fallback_modes": r.stats["fallback_modes"], "ratio_to_compiled": times[name].wall / fast,
                       "reference_check_N": check}
                rows.append(row)
                print(f"{rtol:8.0e} {name:>9} {row['wall_ms']:10.1f} {row['rhs_evals']:6d} {row['steps']:6d} "
                      f"{row['max_dF_n_N']:14.2e} {len(row['fallback_modes']):9d} {row['ratio_to_compiled']:7.2f}")
    write_report(OUT, {"benchmark": "b2_orientation", "repeats": args.repeats, "scene": "benchmarks/b2.toml",
                       "error": f"max |F_n - F_n,ref| over t >= {T_FROM} s, reference: compiled, rtol 1e-12, "
                                "atol 1e-14"}, rows)


if __name__ == "__main__":
    main()
