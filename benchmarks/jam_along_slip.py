"""Case 2's impulse ratio: where the paper's impact procedure (eqs 27-31) gives |F_fΔt| / FΔt > μ.

The paper first assumes sliding (eqs 27-29: friction impulse −μ FΔt d, d the pre-impact slip
direction); if the tangential velocity after it points against d, the impact is taken as jammed
(eqs 30-31: zero tangential velocity, F_fΔt an unknown) — without testing the friction cone.
A jam can then need a friction impulse larger than μ FΔt, and one that pushes the tip *along* its
pre-impact slip (F_fΔt · d > 0). This script runs that procedure, in closed form, for the writer
(``urdf/writer2r.urdf``, links only: the case 2 scenes' ideal drives) striking its model (b)
surface (m_e = 10 kg) at z = −0.1 m, over touch points x and approach directions, and lists
where the ratio exceeds μ. The ratio does not depend on the touch speed (the law is linear in q̇⁻).

    PYTHONPATH=$PWD python3 benchmarks/jam_along_slip.py   # table + benchmarks/out/jam_along_slip.csv
"""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np

from contactdyn.robot.posture import PostureTask, solve_posture
from contactdyn.robot.robot import Robot

MU = 0.4  # sec. 5.2
M_E = 10.0  # [kg] sec. 5.2
Z_S = -0.1  # [m] the scenes' surface height
SEED = np.array([0.43, 2.28])  # elbow up, as sims/case2_writer_b.toml
XS = np.round(np.arange(0.15, 0.5501, 0.01), 3)  # [m] touch points along the surface
#: [deg] approach direction from the downward vertical, + towards +x; 1° steps near the vertical
ANGLES = np.unique(np.concatenate([np.arange(-60.0, 60.01, 5.0), np.arange(-4.0, 4.01, 1.0)]))
SCENE_DIRECTION = np.array([5.8, -11.7])  # [mm/s] case2_writer_b's touch velocity (x, z)
OUT = Path(__file__).resolve().parent / "out" / "jam_along_slip.csv"


def paper_impact(H: np.ndarray, Jx: np.ndarray, Jz: np.ndarray, qd: np.ndarray) -> dict:
    """Eqs 27-31 on a model (b) surface: sliding first; jammed (no cone test) if the slip would reverse."""
    d = float(np.sign(Jx @ qd))

    def solve(jam: bool):
        n = 4 if not jam else 5
        A, b = np.zeros((n, n)), np.zeros(n)
        A[:2, :2] = H
        A[:2, 3] = -(Jz if jam else Jz - MU * d * Jx)  # unknowns: q̇⁺ (2), ż⁺, FΔt [, F_fΔt]
        A[2, 2], A[2, 3] = M_E, 1.0  # m_e ż⁺ = −FΔt
        A[3, :2], A[3, 2] = Jz, -1.0  # J_z q̇⁺ = ż⁺
        if jam:
            A[:2, 4] = -Jx
            A[4, :2] = Jx  # J_x q̇⁺ = 0
        b[:2] = H @ qd
        return np.linalg.solve(A, b)

    z = solve(False)
    P_n, P_t, jammed = z[3], -MU * d * z[3], False
    if float(Jx @ z[:2]) * d < 0.0:
        z = solve(True)
        P_n, P_t, jammed = z[3], z[4], True
    return {"FΔt": P_n, "F_fΔt": P_t, "ratio": abs(P_t) / P_n, "jammed": jammed, "along_slip": P_t * d > 0.0}


def scan() -> list[dict]:
    robot = Robot.load("writer2r")
    rows = []
    for x in XS:
        posture = solve_posture(robot, PostureTask("tip", np.array([x, 0.0, Z_S])), SEED)
        if not posture.from_seed:
            raise RuntimeError(f"x = {x} m: the elbow-up posture from SEED is not the one found")
        q = posture.q
        H = robot.mass_matrix(q)
        J = robot.frame_jacobian(q, "tip")[:3]
        Jx, Jz = J[0], J[2]
        Jp = np.linalg.inv(J[[0, 2]])
        dirs = [(f"{a:+.0f}°", np.array([np.sin(np.radians(a)), -np.cos(np.radians(a))])) for a in ANGLES]
        dirs.append(("scene", SCENE_DIRECTION / np.linalg.norm(SCENE_DIRECTION)))
        for name, v in dirs:
            if abs(v[0]) < 1e-12:
                continue  # no pre-impact slip: no direction d for eq. 27
            rec = paper_impact(H, Jx, Jz, Jp @ v)
            rows.append({"x": float(x), "direction": name, **rec})
    return rows


def main() -> None:
    rows = scan()
    OUT.parent.mkdir(parents=True, exist_ok=True)
    with OUT.open("w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    over = [r for r in rows if r["ratio"] > MU * (1 + 1e-9)]
    along = [r for r in over if r["along_slip"]]
    print(f"{len(rows)} (x, direction) cases; ratio > μ at {len(over)}, all jammed: {all(r['jammed'] for r in over)};"
          f" friction impulse along the pre-impact slip at {len(along)}")
    for r in along:
        print(f"  x = {r['x']:.2f} m  {r['direction']:>6s}  FΔt per unit speed {r['FΔt']:.4f} N·s/(m/s)"
              f"  ratio {r['ratio']:.3f}")
    if along:
        print(f"along-slip jams: x from {min(r['x'] for r in along):.2f} m, ratio up to "
              f"{max(r['ratio'] for r in along):.3f}; ratio 0.42-0.44 (the paper's 0.427) at",
              [(r["x"], r["direction"]) for r in along if 0.42 <= r["ratio"] <= 0.44])
    at_b = next(r for r in rows if r["direction"] == "scene" and abs(r["x"] - 0.30) < 1e-9)
    print(f"the scene's touch (x = 0.30 m, its touch direction): ratio {at_b['ratio']:.4f}, jammed {at_b['jammed']},"
          f" along the slip {at_b['along_slip']}")


if __name__ == "__main__":
    main()
