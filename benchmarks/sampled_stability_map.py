"""B1's force loop sampled: the z-domain decay rate over (sample rate, delay) against runs.

The loop is ``sims/b1_force_loop.toml`` (B1's robot, surface, friction, reference and 100 N set-point under
the hybrid law: A7 along x, A10 along the normal with the measured force fed back). The map is σ = ln|z_max|·rate
[1/s] of :class:`contactdyn.analysis.sampled_stability.SampledLoop` linearised at B1's start pose; the boundary is
σ = 0 (|z_max| = 1). At a few points on both sides of it the loop is run and the force error's own mode nearest
the dominant pole in frequency (matrix pencil on the error at the sample instants) gives the measured rate:

- ``simulator``: the simulator's sampled control (``controller.sample_rate``, ``controller.delay``), when the
  scene reader knows those keys;
- ``held loop``: a zero-order hold written here on the simulator's own right-hand side (``System.evaluate`` with
  the command held between samples, scipy's DOP853 at rtol 1e-10 per period; the law's ``command`` at each sample
  on the input measured ``delay`` samples before, its states advanced by forward Euler), the reference until the
  simulator has sampled control.

The z-domain poles are those of an equilibrium; B1 slides at 0.15 m/s, so its pose (and the loop's poles: the
robot's mass along the normal changes) moves 0.3 m in 2 s. The runs therefore slide at 0.01 m/s from B1's start
(``SLOW``, 2 cm in 2 s): the prediction is the frozen-pose linearisation at the fit window's middle (and, for
comparison, at the start pose). Writes
benchmarks/out/sampled_stability_map.png and .json, prints a table.

    PYTHONPATH=$PWD python3 benchmarks/sampled_stability_map.py [--no-runs]
"""

from __future__ import annotations

import json
import sys
from collections import deque
from dataclasses import replace
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from scipy.integrate import solve_ivp  # noqa: E402

from contactdyn.analysis.sampled_stability import HeldCommand, SampledLoop, measured_input, measured_rate  # noqa: E402
from contactdyn.analysis.stability import ContactLoop, contact_force_error, contact_phase_scene  # noqa: E402
from contactdyn.errors import SceneError  # noqa: E402

SCENE = str(Path(__file__).resolve().parents[1] / "sims" / "b1_force_loop.toml")
Q0 = [0.337307481430, -1.318116071653]  #: B1's start, tip at (0.45, −0.15)
OUT = Path(__file__).resolve().parent / "out"
RATES = np.geomspace(50.0, 2000.0, 41)  #: [Hz]
DELAYS = np.arange(0, 9)  #: [samples]
#: (rate [Hz], delay [samples], duration [s], fit from [s]): both sides of the boundary
LINEAR = 30.0  #: [N] the fit stops where |F_n − F_d| first exceeds this (beyond, the harmonics 2ω, 3ω of the
#: force's nonlinearity grow at 2σ, 3σ and the fundamental saturates: at 90 N it reads 20–30 % low)
#: the runs' reference: B1's start, sliding at 0.01 m/s (tip velocity (−0.01, 0) at the start)
SLOW = {"phase.0.reference.moves": [{"kind": "constant_velocity", "delta": [-0.04, 0.0, 0.0], "duration": 4.0}],
        "robot.v0": [0.287298334621 / 15.0, -0.774596669241 / 15.0]}
POINTS = [(200.0, 2, 2.0, 0.1), (200.0, 4, 2.0, 0.1), (300.0, 3, 2.0, 0.1), (150.0, 3, 2.0, 0.1),
          (100.0, 1, 2.0, 0.1), (100.0, 2, 2.0, 0.1)]


def linearised(t_eq: float = 0.0, over: dict | None = None):
    """The sampled loop linearised at the frozen pose of time t_eq [s] (Newton continued from the start pose in
    steps of 0.1 s of the reference: the pose moves 15 mm per step)."""
    x = None
    for t in [*np.arange(0.0, t_eq, 0.1)[1:], t_eq]:
        x = ContactLoop(contact_phase_scene(SCENE, Q0, over), t_eq=float(t)).linearize(x).x
    return SampledLoop(ContactLoop(contact_phase_scene(SCENE, Q0, over), t_eq=t_eq)).linearize(x)


def held_loop_run(rate: float, delay: int, duration: float) -> tuple[np.ndarray, np.ndarray]:
    """(t_k [s], F_n − F_d at t_k [N]) of the sampled loop on the simulator's right-hand side (see the module
    docstring); the force is the one measured at t_k, under the command held from the previous sample."""
    loop = ContactLoop(contact_phase_scene(SCENE, Q0, SLOW))
    system, phase, modes, ctl = loop.system, loop.phase, loop.modes, loop.phase.controller
    h = 1.0 / rate
    z_slots = slice(2 * system.nQ + phase.z_slice.start, 2 * system.nQ + phase.z_slice.stop)
    x = loop.x0.copy()
    held = ctl.command(measured_input(loop, 0.0, x, np.zeros(system.nv)))[0]  # a first command to measure under
    line: deque = deque(maxlen=delay + 1)
    ts, errs = [], []
    for k in range(int(round(duration * rate)) + 1):
        t = k * h
        inp = measured_input(loop, t, x, held)
        errs.append(inp.forces["tip"] - inp.force_d["tip"][0])
        ts.append(t)
        if not line:
            line.extend([inp] * (delay + 1))  # the delay line starts full of the first measurement
        line.append(inp)
        tau, zdot = ctl.command(line[0].replaced(z=x[z_slots].copy()))
        if zdot is not None and len(zdot):
            x[z_slots] += h * np.asarray(zdot)
        held = np.asarray(tau, float)
        held_phase = replace(phase, controller=HeldCommand(held, ctl.n_states, ctl.outputs))
        sol = solve_ivp(lambda s, y, p=held_phase: system.evaluate(s, y, modes, p).xdot, (t, t + h), x,
                        method="DOP853", rtol=1e-10, atol=1e-12)
        x = sol.y[:, -1].copy()
        if abs(errs[-1]) > 95.0:
            break
    return np.array(ts), np.array(errs)


def simulator_run(rate: float, delay: int, duration: float, t_fit: float):
    """(t_k, F_n − F_d) of the simulator's own sampled run, or None if it has no sampled control."""
    over = {**SLOW, "controller.sample_rate": rate, "controller.delay": delay, "solver.output_rate": rate,
            "duration": duration, "solver.rtol": 1e-10, "solver.atol": 1e-12}
    try:
        scene = contact_phase_scene(SCENE, Q0, over)
    except SceneError:
        return None
    return contact_force_error(scene, t_fit)


def linear_window(t: np.ndarray, err: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The samples from the first with |err| ≤ LINEAR up to the next one beyond it."""
    small = np.abs(err) <= LINEAR
    start = int(np.argmax(small))
    over = np.flatnonzero(~small[start:])
    end = start + int(over[0]) if len(over) else len(err)
    return t[start:end], err[start:end]


def measure(points: list) -> list[dict]:
    rows = []
    for rate, delay, duration, t_fit in points:
        t, err = held_loop_run(rate, delay, duration)
        keep = t > t_fit
        t, err = t[keep], err[keep]
        t, err = linear_window(t, err)
        mid = 0.5 * (t[0] + t[-1])
        at_mid, at_start = linearised(mid, SLOW), linearised(0.0, SLOW)
        z = at_mid.dominant(rate, delay)
        row = {"rate": rate, "delay": delay, "window": [float(t[0]), float(t[-1])],
               "sigma_mid": at_mid.sigma(rate, delay), "sigma_start": at_start.sigma(rate, delay),
               "frequency": abs(float(np.angle(z))) * rate / (2 * np.pi),
               "held_loop": measured_rate(t, err, z, 1.0 / rate)}
        sim = simulator_run(rate, delay, duration, t_fit)
        if sim is not None:
            sim = linear_window(*sim)
        row["simulator"] = None if sim is None else measured_rate(*sim, z, 1.0 / rate)
        rows.append(row)
        print(f"{rate:6.0f} Hz  d = {delay}  window {row['window'][0]:.2f}–{row['window'][1]:.2f} s  "
              f"σ(mid pose) {row['sigma_mid']:+7.3f}  σ(start pose) {row['sigma_start']:+7.3f} 1/s  "
              f"f {row['frequency']:5.1f} Hz  held loop {row['held_loop']:+7.3f}  simulator "
              + ("—" if row["simulator"] is None else f"{row['simulator']:+7.3f}"))
    return rows


def draw(sigma: np.ndarray, rows: list[dict], path: Path) -> None:
    fig, ax = plt.subplots(figsize=(8.0, 4.8))
    lim = float(np.max(np.abs(sigma)))
    mesh = ax.pcolormesh(RATES, DELAYS, sigma, cmap="RdBu_r", vmin=-lim, vmax=lim, shading="nearest")
    ax.contour(RATES, DELAYS, sigma, levels=[0.0], colors="k", linewidths=1.6)
    for r in rows:
        measured = r["simulator"] if r["simulator"] is not None else r["held_loop"]
        ax.plot(r["rate"], r["delay"], "o", ms=9, mfc="none", mec="k")
        ax.annotate(f"{r['sigma_mid']:+.2f} / {measured:+.2f}", (r["rate"], r["delay"]), textcoords="offset points",
                    xytext=(7, 5), fontsize=8)
    ax.set_xscale("log")
    ax.set_xlabel("sample rate [Hz]")
    ax.set_ylabel("delay [samples]")
    which = "simulator" if rows and rows[0]["simulator"] is not None else "held loop on System.evaluate"
    ax.set_title("B1 force loop (hybrid, K_F = 50/s): decay rate σ = ln|z_max|·rate [1/s]\n"
                 f"black: |z_max| = 1; circles: predicted / measured ({which})", fontsize=10)
    fig.colorbar(mesh, ax=ax, label="σ [1/s] (> 0: grows)")
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


def main() -> None:
    lin = linearised(0.0)
    sigma = lin.map(RATES, DELAYS)
    print("continuous poles [1/s]:", np.round(np.sort_complex(lin.continuous), 3))
    print("σ [1/s] at B1's start pose; rows: delay [samples], columns: rate [Hz]")
    cols = [0, 5, 10, 15, 20, 25, 30, 35, 40]
    print("     " + "".join(f"{RATES[j]:9.0f}" for j in cols))
    for i, d in enumerate(DELAYS):
        print(f"{d:4d} " + "".join(f"{sigma[i, j]:9.2f}" for j in cols))
    rows = [] if "--no-runs" in sys.argv else measure(POINTS)
    OUT.mkdir(parents=True, exist_ok=True)
    draw(sigma, rows, OUT / "sampled_stability_map.png")
    (OUT / "sampled_stability_map.json").write_text(json.dumps(
        {"rates": RATES.tolist(), "delays": DELAYS.tolist(), "sigma": sigma.tolist(), "points": rows}, indent=1))


if __name__ == "__main__":
    main()
