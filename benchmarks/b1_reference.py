"""Benchmark B1 written out by hand: a closed-form model of this one scene.

Independent of contactdyn (no Pinocchio, no scene file): the 2R inertia matrix, Coriolis
terms, tip kinematics and the bonded model-(b) surface with sliding Coulomb friction are
typed in from /work/shared/bench/B1.md. Two uses:

- the *hand-written model* of the performance budget (how fast one scene can go when
  every line is written for it): ``python benchmarks/b1_reference.py --time``;
- a cross-check of contactdyn's own reference runs: ``reference()`` integrates it at a
  very tight tolerance and samples t, x_tip, F_n at 1 kHz.

Unknowns at each instant: q̈ (2) and F_n. Equations (B1.md):
  H q̈ + h = Jᵀ f_ctrl + J_yᵀ F_n − μ sgn(ẋ) J_xᵀ F_n   (joint torques)
  m_e (J_y q̈ + J̇_y q̇) = −F_n − k (y − y_s) − b ẏ       (the surface mass rides with the tip)
Eliminating F_n leaves a 2×2 system, solved in closed form (Cramer).
"""

from __future__ import annotations

import argparse
import json
import math
import statistics
import time

import numpy as np
from scipy.integrate import solve_ivp

# ---- B1 parameters (B1.md) --------------------------------------------------------------
L1 = L2 = 0.3  #: link lengths [m]
M1 = M2 = 3.0  #: link masses [kg]
LC = 0.15  #: joint-to-COM distance [m]
I1 = I2 = 0.025  #: rotational inertia about the COM [kg·m²]
ME, K, B = 10.0, 1e5, 1.0  #: surface mass [kg], stiffness [N/m], damping [N·s/m]
MU = 0.4  #: Coulomb coefficient [-]
KP, KD, FD, V = 2000.0, 100.0, 100.0, 0.15  #: [N/m], [N·s/m], [N], [m/s]
X0, YS = 0.45, -0.15  #: initial tip x [m], surface height [m]
DELTA = MU * FD / KP  #: reference lead [m]
Q0 = (0.337307481430, -1.318116071653)  #: [rad]
QD0 = (0.287298334621, -0.774596669241)  #: [rad/s]
T_END = 2.0  #: [s]
N_OUT = 2001  #: 1 kHz including t = 0

# constant parts of H (eq. 3 of the paper with the B1 numbers)
_A = M1 * LC**2 + M2 * (L1**2 + LC**2) + I1 + I2  # H11 without the cos q2 term
_C = M2 * L1 * LC  # coefficient of cos q2 (×2 in H11, ×1 in H12) and of the Coriolis terms
_H12 = M2 * LC**2 + I2  # H12 without the cos q2 term
_H22 = M2 * LC**2 + I2


def accelerations(t: float, q1: float, q2: float, w1: float, w2: float) -> tuple[float, float, float, float, float]:
    """(q̈1, q̈2, F_n [N], x_tip [m], y_tip [m]) at one state."""
    c2, s2 = math.cos(q2), math.sin(q2)
    c1, s1 = math.cos(q1), math.sin(q1)
    c12, s12 = math.cos(q1 + q2), math.sin(q1 + q2)
    h11 = _A + 2.0 * _C * c2
    h12 = _H12 + _C * c2
    g1 = -_C * s2 * (2.0 * w1 * w2 + w2 * w2)  # Coriolis/centrifugal [N·m]
    g2 = _C * s2 * w1 * w1
    x = L1 * c1 + L2 * c12
    y = L1 * s1 + L2 * s12
    jx1, jx2 = -L1 * s1 - L2 * s12, -L2 * s12
    jy1, jy2 = L1 * c1 + L2 * c12, L2 * c12
    w12 = w1 + w2
    xd = jx1 * w1 + jx2 * w2
    yd = jy1 * w1 + jy2 * w2
    dy = -L1 * s1 * w1 * w1 - L2 * s12 * w12 * w12  # J̇_y q̇ [m/s²]
    fx = KP * (X0 - DELTA - V * t - x) + KD * (-V - xd)
    fy = -FD
    # F_n's generalized column: J_y − μ sgn(ẋ) J_x
    sg = MU if xd > 0.0 else (-MU if xd < 0.0 else 0.0)
    c_1, c_2 = jy1 - sg * jx1, jy2 - sg * jx2
    # F_n = −m_e (J_y q̈ + J̇_y q̇) − k (y − y_s) − b ẏ  substituted into the joint equations
    r = -ME * dy - K * (y - YS) - B * yd
    a11, a12 = h11 + ME * c_1 * jy1, h12 + ME * c_1 * jy2
    a21, a22 = h12 + ME * c_2 * jy1, _H22 + ME * c_2 * jy2
    b1 = jx1 * fx + jy1 * fy - g1 + c_1 * r
    b2 = jx2 * fx + jy2 * fy - g2 + c_2 * r
    det = a11 * a22 - a12 * a21
    qdd1 = (b1 * a22 - a12 * b2) / det
    qdd2 = (a11 * b2 - a21 * b1) / det
    fn = r - ME * (jy1 * qdd1 + jy2 * qdd2)
    return qdd1, qdd2, fn, x, y


def rhs(t: float, s) -> list[float]:
    """ṡ for s = (q1, q2, q̇1, q̇2)."""
    qdd1, qdd2, _, _, _ = accelerations(t, s[0], s[1], s[2], s[3])
    return [s[2], s[3], qdd1, qdd2]


def run(rtol: float = 1e-8, atol: float = 1e-10, method: str = "DOP853") -> dict:
    """Integrate B1 and sample the 1 kHz channels; wall time covers the whole simulation."""
    t0 = time.perf_counter()
    sol = solve_ivp(rhs, (0.0, T_END), [*Q0, *QD0], method=method, rtol=rtol, atol=atol, dense_output=True)
    t = np.linspace(0.0, T_END, N_OUT)
    states = sol.sol(t)
    fn = np.empty(N_OUT)
    xt = np.empty(N_OUT)
    for i in range(N_OUT):
        _, _, fn[i], xt[i], _ = accelerations(t[i], *states[:, i])
    wall = time.perf_counter() - t0
    return {"t": t, "x_tip": xt, "F_n": fn, "wall_s": wall, "rhs_evals": int(sol.nfev), "steps": len(sol.t) - 1}


def reference(rtol: float = 1e-13, atol: float = 1e-14) -> dict:
    """A tight-tolerance run (its own error is estimated by :func:`self_check`)."""
    return run(rtol, atol)


def errors(run_out: dict, ref: dict) -> tuple[float, float]:
    """B1.md's metrics: max |ΔF_n| over t ∈ [0.05, 2] s [N], max |Δx_tip| over all samples [m]."""
    mask = ref["t"] >= 0.05 - 1e-12
    return (float(np.max(np.abs(run_out["F_n"][mask] - ref["F_n"][mask]))),
            float(np.max(np.abs(run_out["x_tip"] - ref["x_tip"]))))


def self_check() -> tuple[float, float]:
    """Errors of the reference against a run at half its tolerances."""
    return errors(reference(), reference(0.5e-13, 0.5e-14))


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--time", action="store_true", help="time the hand-written model at rtol=1e-8 (median of 5)")
    p.add_argument("--out", help="write the reference channels to this JSON file")
    args = p.parse_args(argv)
    ref = reference()
    if args.time:
        for rtol, atol in ((1e-6, 1e-8), (1e-7, 1e-9), (1e-8, 1e-10), (1e-9, 1e-11), (1e-10, 1e-12)):
            runs = [run(rtol, atol) for _ in range(5)]
            e_f, e_x = errors(runs[0], ref)
            wall = statistics.median(r["wall_s"] for r in runs)
            print(f"hand-written B1, DOP853 rtol={rtol:g}: wall {wall * 1e3:.1f} ms (median of 5), "
                  f"{runs[0]['rhs_evals']} rhs evals, F_n error {e_f:.2e} N, x_tip error {e_x:.2e} m")
    e_f, e_x = self_check()
    print(f"reference self-check (rtol 1e-13 vs 5e-14): F_n {e_f:.2e} N, x_tip {e_x:.2e} m")
    if args.out:
        with open(args.out, "w") as f:
            json.dump({k: ref[k].tolist() for k in ("t", "x_tip", "F_n")}, f)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
