"""B2 (UR5 press and slide, /work/shared/bench/B2.md) against its hand-written floor: cost at equal force error.

    PYTHONPATH=. python3 benchmarks/b2_floor.py [--repeats 11] [--rtols 3e-4,1e-4,5e-5,...,1e-8]

The floor is B2.md's "hand-written floor", independent of contactdyn (only the URDF's path is looked up through
``contactdyn.robot.catalog``): a right-hand side on Pinocchio's own calls (forwardKinematics with q̈ = 0 and
getFrameClassicalAcceleration for J̇q̇, updateFramePlacement, computeFrameJacobian LOCAL_WORLD_ALIGNED, crba,
nonLinearEffects, computeGeneralizedGravity for the feedforward), B2.md §3's controller (task_pd with the
tool-axis hold) written out in NumPy, and §2's (q̈, F_n) solve (one 7×7 np.linalg.solve) with the table's
equivalent mass as a state: y = (q, z_e, q̇, ż_e), z̈_e = J_z q̈ + (J̇q̇)_z (bonded), F_n = −(ME z̈_e + KS (z_e −
Z_S) + BS ż_e) — contactdyn's layout of a bonded model-(b) mass. Integrated by scipy's ``solve_ivp`` DOP853 with a
dense output; the 1 kHz F_n and x_tool samples are each the state's at t_k (one more solve per sample).

Reference: the floor at rtol = atol = 1e-12 (B2.md §6), checked against the floor at 3e-13 and against
contactdyn at rtol 1e-12, atol 1e-14 (the physics must agree before anything is timed). Error: B2.md §5, max |F_n
− F_n,ref| [N] over the samples with t ∈ [0.05, 1] s (and max |x_tool − x_ref| [m] over all samples).

Cost: per rtol (atol = rtol / 100 on both sides, as b2.toml's 1e-8 / 1e-10), interleaved in this process (every
variant once per repeat after one untimed run; medians of process CPU time [s] and wall [s]): the floor (its model
built once); ``contactdyn.simulate.simulate`` on benchmarks/b2.toml (the scene parsed once per rtol; building the
System — URDF, pipelines — is inside, as a user's call pays it); and ``run_system`` on a System built once. The ratio
contactdyn / floor at max |ΔF_n| = 1e-2 N, read two ways (the errors are not monotone in rtol at loose
tolerances): each side's cost interpolated on log-log axes between the loosest rtol from which every tighter run is
under 1e-2 N and the next looser one; and each side's cheapest run under 1e-2 N. The floor's column "output" is its
1 kHz sampling's share (a solve per sample). Writes benchmarks/out/b2_floor.json.
"""

from __future__ import annotations

import argparse
import math
import sys
import time
import tomllib
from pathlib import Path

import numpy as np
import pinocchio as pin
from scipy.integrate import solve_ivp

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from timing import interleaved, write_report  # noqa: E402

from contactdyn.model.system import System  # noqa: E402
from contactdyn.robot.catalog import example_robots  # noqa: E402
from contactdyn.scene.scene_file import load_scene  # noqa: E402
from contactdyn.simulate import run_system, simulate  # noqa: E402

HERE = Path(__file__).resolve().parent
SCENE = HERE / "b2.toml"
OUT = HERE / "out" / "b2_floor.json"

# ---- B2.md's numbers (SI) -------------------------------------------------------------------------------------
ZS, ME, KS, BS, MU = 0.10, 5.0, 1e5, 100.0, 0.3  #: table: height [m], mass [kg], [N/m], [N·s/m], Coulomb [-]
X0, Y0, V, FD = 0.40, 0.15, 0.10, 40.0  #: start [m], slide speed [m/s], force set-point [N]
KP, KD = 2000.0, 100.0  #: task PD on x and y [N/m], [N·s/m]
DELTA = MU * FD / KP  #: reference lead [m] (0.006)
KO, DO, KDJ = 50.0, 2.0, 1.0  #: tool-axis hold [N·m/rad], [N·m·s/rad]; joint damping [N·m·s/rad]
T_END, N_OUT, T_FROM = 1.0, 1001, 0.05  #: duration [s], 1 kHz samples, error window start [s]
TARGET_N = 1e-2  #: [N] the force error at which issue 29 asks for the cost ratio
_DOC = tomllib.loads(SCENE.read_text())
Q0, V0 = np.array(_DOC["robot"]["q0"]), np.array(_DOC["robot"]["v0"])  #: [rad], [rad/s] B2.md §4, exactly

MODEL = pin.buildModelFromUrdf(str(example_robots()["ur5"]))
DATA = MODEL.createData()
FID = MODEL.getFrameId("tool0")
LWA = pin.ReferenceFrame.LOCAL_WORLD_ALIGNED
NV = MODEL.nv
ZERO = np.zeros(NV)


def solve(t: float, y: np.ndarray):
    """(q̈ [rad/s²], z̈_e [m/s²], F_n [N], p_tool [m]) at the state y = (q, z_e, q̇, ż_e) [rad, m, rad/s, m/s]."""
    q, v, z_e, w_e = y[:NV], y[NV + 1:2 * NV + 1], y[NV], y[2 * NV + 1]
    pin.forwardKinematics(MODEL, DATA, q, v, ZERO)
    jdqd = pin.getFrameClassicalAcceleration(MODEL, DATA, FID, LWA).linear  # J̇q̇ of the tool point [m/s²]
    pose = pin.updateFramePlacement(MODEL, DATA, FID)
    p, R = pose.translation.copy(), pose.rotation.copy()
    J6 = pin.computeFrameJacobian(MODEL, DATA, q, FID, LWA)
    J, Jw = J6[:3], J6[3:]
    H = pin.crba(MODEL, DATA, q)  # symmetric as the binding returns it (checked in main)
    n = pin.nonLinearEffects(MODEL, DATA, q, v)
    g = pin.computeGeneralizedGravity(MODEL, DATA, q)
    pd, w = J @ v, Jw @ v  # tool velocity [m/s], angular velocity [rad/s]
    # controller (B2.md §3): task PD on x, y, the force set-point on z, the tool-axis hold, joint damping, g(q)
    f = np.array([KP * (X0 + DELTA + V * t - p[0]) + KD * (V - pd[0]), KP * (Y0 - p[1]) - KD * pd[1], -FD])
    a = R[:, 2]  # tool axis (world)
    w_perp = w - (w @ a) * a
    m = KO * np.array([-a[1], a[0], 0.0]) - DO * w_perp  # a × (0, 0, −1) = (−a_y, a_x, 0)
    tau = J.T @ f + Jw.T @ m - KDJ * v + g
    # (q̈, F_n) of B2.md §2, isotropic Coulomb friction along the slip direction d
    d = pd[:2] / math.hypot(pd[0], pd[1])
    c = J[2] - MU * (d[0] * J[0] + d[1] * J[1])
    A = np.empty((NV + 1, NV + 1))
    A[:NV, :NV], A[:NV, NV], A[NV, :NV], A[NV, NV] = H, -c, ME * J[2], 1.0
    b = np.empty(NV + 1)
    b[:NV], b[NV] = tau - n, -ME * jdqd[2] - KS * (z_e - ZS) - BS * w_e
    x = np.linalg.solve(A, b)
    return x[:NV], J[2] @ x[:NV] + jdqd[2], x[NV], p


def rhs(t: float, y: np.ndarray) -> np.ndarray:
    qdd, zdd, _, _ = solve(t, y)
    return np.concatenate((y[NV + 1:], qdd, (zdd,)))


def initial_state() -> np.ndarray:
    """(q0, z_e0, q̇0, ż_e0): the table mass at rest where the tool is (undeformed: z_e0 = tool z ≈ Z_S)."""
    pin.forwardKinematics(MODEL, DATA, Q0, V0)
    p = pin.updateFramePlacement(MODEL, DATA, FID).translation
    vz = pin.getFrameVelocity(MODEL, DATA, FID, LWA).linear[2]
    return np.concatenate((Q0, (p[2],), V0, (vz,)))


def floor_run(rtol: float, atol: float) -> dict:
    """One run of the floor: integrate 1 s and sample F_n [N], x_tool [m] at 1 kHz (the timed unit)."""
    sol = solve_ivp(rhs, (0.0, T_END), initial_state(), method="DOP853", rtol=rtol, atol=atol, dense_output=True)
    t = np.linspace(0.0, T_END, N_OUT)
    c0 = time.process_time()
    ys = sol.sol(t)
    F, x = np.empty(N_OUT), np.empty(N_OUT)
    for k in range(N_OUT):
        _, _, F[k], p = solve(t[k], ys[:, k])
        x[k] = p[0]
    return {"t": t, "F_n": F, "x": x, "rhs_evals": int(sol.nfev), "steps": len(sol.t) - 1,
            "output_cpu_s": time.process_time() - c0}


def channels(result) -> dict:
    """contactdyn's Result as the floor's dict (t [s], F_n [N], x_tool [m], counts)."""
    return {"t": np.asarray(result.t), "F_n": np.asarray(result["contact.tool.F_n"]),
            "x": np.asarray(result["tip"])[:, 0], "rhs_evals": int(result.stats["rhs_evals"]),
            "steps": int(result.stats["steps"])}


def errors(run: dict, ref: dict) -> tuple[float, float]:
    """B2.md §5: max |ΔF_n| [N] over t ∈ [0.05, 1] s, max |Δx_tool| [m] over all samples."""
    assert run["t"].shape == ref["t"].shape and np.allclose(run["t"], ref["t"], rtol=0, atol=1e-12)
    keep = ref["t"] >= T_FROM - 1e-12
    return (float(np.max(np.abs(run["F_n"][keep] - ref["F_n"][keep]))),
            float(np.max(np.abs(run["x"] - ref["x"]))))



def check_physics() -> tuple[dict, dict]:
    """The floor's reference and its checks [N, m]: against the floor at 3e-13 and contactdyn at 1e-12 / 1e-14."""
    H = pin.crba(MODEL, DATA, Q0)
    assert np.array_equal(H, H.T), "crba's matrix is not symmetric: symmetrise it in solve()"
    ref = floor_run(1e-12, 1e-12)
    own = errors(floor_run(3e-13, 3e-13), ref)
    tight = load_scene(SCENE, {"solver.rtol": 1e-12, "solver.atol": 1e-14})
    cd = errors(channels(simulate(tight)), ref)
    print(f"reference: the floor, DOP853 rtol = atol = 1e-12, {ref['rhs_evals']} rhs calls; F_n in "
          f"[{ref['F_n'].min():.2f}, {ref['F_n'].max():.2f}] N, x_tool {ref['x'][0]:.4f} -> {ref['x'][-1]:.4f} m")
    print(f"  against the floor at 3e-13:            max|dF_n| = {own[0]:.1e} N, max|dx| = {own[1]:.1e} m")
    print(f"  against contactdyn at 1e-12 / 1e-14:   max|dF_n| = {cd[0]:.1e} N, max|dx| = {cd[1]:.1e} m")
    if cd[0] > 1e-6:
        raise SystemExit("the floor's physics and contactdyn's disagree: nothing timed")
    return ref, {"floor_3e-13": own, "contactdyn_1e-12": cd}


def measure(rtols: list[float], repeats: int, ref: dict) -> list[dict]:
    """Per rtol and variant: median CPU and wall [s] of interleaved repeats, counts, errors against ``ref``."""
    rows = []
    for rtol in rtols:
        atol = rtol * 1e-2
        scene = load_scene(SCENE, {"solver.rtol": rtol, "solver.atol": atol})
        system = System(scene)
        variants = {"floor": lambda r=rtol, a=atol: floor_run(r, a),
                    "contactdyn simulate": lambda s=scene: channels(simulate(s)),
                    "contactdyn run_system": lambda s=system: channels(run_system(s))}
        for call in variants.values():  # untimed: compiled code loaded, pipelines packed
            call()
        times = interleaved(variants, repeats)
        for name, tm in times.items():
            e_f, e_x = errors(tm.last, ref)
            rows.append({"variant": name, "rtol": rtol, "atol": atol, "cpu_ms": 1e3 * tm.cpu, "wall_ms": 1e3 * tm.wall,
                         "cpu_ms_all": [1e3 * c for c in tm.cpu_s], "wall_ms_all": [1e3 * w for w in tm.wall_s],
                         "rhs_evals": tm.last["rhs_evals"], "steps": tm.last["steps"],
                         "output_cpu_ms": 1e3 * tm.last.get("output_cpu_s", math.nan),
                         "max_dF_n_N": e_f, "max_dx_m": e_x})
            r = rows[-1]
            spread = (max(r["cpu_ms_all"]) - min(r["cpu_ms_all"])) / r["cpu_ms"]
            print(f"{rtol:8.0e} {name:>22} {r['cpu_ms']:8.1f} {100 * spread:6.0f}% {r['wall_ms']:8.1f} "
                  f"{r['output_cpu_ms']:7.1f} {r['rhs_evals']:6d} {r['steps']:6d} {e_f:10.2e} {e_x:10.2e}")
    return rows


def at_target(rows: list[dict], variant: str, key: str = "cpu_ms") -> dict:
    """A variant's cost [ms] at max|ΔF_n| = TARGET_N.

    ``interpolated``: log cost linear in log error between the loosest rtol from which every tighter run is under
    the target and the next looser one (None when no run or every run is under it); ``cheapest``: the cheapest single
    run under the target."""
    runs = sorted((r for r in rows if r["variant"] == variant), key=lambda r: -r["rtol"])
    under = [r for r in runs if r["max_dF_n_N"] <= TARGET_N]
    cheapest = min(under, key=lambda r: r[key]) if under else None
    i = len(runs)
    while i > 0 and runs[i - 1]["max_dF_n_N"] <= TARGET_N:
        i -= 1
    interp = None
    if 0 < i < len(runs):
        a, b = runs[i - 1], runs[i]
        s = math.log(TARGET_N / a["max_dF_n_N"]) / math.log(b["max_dF_n_N"] / a["max_dF_n_N"])
        interp = math.exp(math.log(a[key]) + s * (math.log(b[key]) - math.log(a[key])))
        interp = {"cost_ms": interp, "between_rtols": [a["rtol"], b["rtol"]]}
    return {"interpolated": interp,
            "cheapest": cheapest and {"cost_ms": cheapest[key], "rtol": cheapest["rtol"],
                                      "max_dF_n_N": cheapest["max_dF_n_N"]}}


def ratios(rows: list[dict]) -> list[dict]:
    """contactdyn / floor at TARGET_N, per contactdyn variant and clock, both ways of reading the cost."""
    out = []
    for key in ("cpu_ms", "wall_ms"):
        floor = at_target(rows, "floor", key)
        for name in ("contactdyn simulate", "contactdyn run_system"):
            ours = at_target(rows, name, key)
            row = {"variant": name, "clock": key, "floor": floor, "contactdyn": ours}
            for how in ("interpolated", "cheapest"):
                ok = floor[how] and ours[how]
                row[f"ratio_{how}"] = ours[how]["cost_ms"] / floor[how]["cost_ms"] if ok else None
            out.append(row)
            print(f"{name:>22} {key:>7}: interpolated {_fmt(ours['interpolated'])} / {_fmt(floor['interpolated'])} "
                  f"= {_num(row['ratio_interpolated'])};  cheapest under {TARGET_N:g} N {_fmt(ours['cheapest'])} / "
                  f"{_fmt(floor['cheapest'])} = {_num(row['ratio_cheapest'])}")
    return out


def _fmt(x: dict | None) -> str:
    if not x:
        return "-"
    where = f"rtol {x['rtol']:.0e}, {x['max_dF_n_N']:.1e} N" if "rtol" in x else \
        "rtols " + "/".join(f"{r:.0e}" for r in x["between_rtols"])
    return f"{x['cost_ms']:.1f} ms ({where})"


def _num(x: float | None) -> str:
    return "-" if x is None else f"{x:.2f}"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--repeats", type=int, default=11)
    ap.add_argument("--rtols", default="3e-4,1e-4,5e-5,3e-5,2e-5,1e-5,5e-6,3e-6,1e-6,1e-7,1e-8")
    args = ap.parse_args()
    rtols = [float(r) for r in args.rtols.split(",")]
    ref, checks = check_physics()
    print(f"\n{'rtol':>8} {'variant':>22} {'CPU [ms]':>8} {'spread':>7} {'wall [ms]':>8} {'output':>7} {'rhs':>6} "
          f"{'steps':>6} {'max|dF_n| [N]':>10} {'max|dx| [m]':>10}")
    print("(CPU, wall: medians of the repeats; spread: (max − min) / median of CPU; output: the floor's sampling's CPU"
          " [ms], inside its CPU)")
    rows = measure(rtols, args.repeats, ref)
    print(f"\ncost ratio contactdyn / floor at max|dF_n| = {TARGET_N:g} N (issue 29 item 3: <= 0.3):")
    summary = ratios(rows)
    write_report(OUT, {"benchmark": "b2_floor", "repeats": args.repeats, "scene": "benchmarks/b2.toml",
                       "error": f"max |F_n - F_n,ref| over t >= {T_FROM} s; reference: the floor, DOP853 rtol = "
                                "atol = 1e-12", "reference_checks": checks, "target_N": TARGET_N,
                       "at_target": summary}, rows)


if __name__ == "__main__":
    main()
