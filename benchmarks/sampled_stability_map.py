"""B1's force loop sampled: the z-domain decay rate over (sample rate, delay) against the simulator's own runs.

The loop is ``sims/b1_force_loop.toml`` (B1's robot, surface, friction and 100 N set-point under the hybrid law:
A7 along x, A10 along the normal with the measured force fed back). The map is σ = ln|z_max|·rate [1/s] of
:class:`contactdyn.analysis.sampled_stability.SampledLoop`, the scene's phase run sampled (``controller.sample_rate``,
``controller.delay``) linearised at B1's start with the reference held there (the contact sliding: the mode B1's
start finds); the boundary is σ = 0 (|z_max| = 1).

At points on both sides of it the simulator runs the sampled scene from that equilibrium, the tip sliding at
``SPEED`` (its joint velocities set for it, the reference moving at it from the same point: a sliding steady state
to first order), with the set-point raised by ``KICK``: a force error of 0.01 N that stays linear over the whole
run. The measured rate is the force error's own mode nearest the dominant pole in frequency (matrix pencil on the
error at the sample instants, which sees z directly) from ``T_FIT`` while |F − F_d| ≤ ``LIMIT`` and the slip keeps
its direction (:func:`~contactdyn.analysis.sampled_stability.linear_window`). Why so small and so slow: the force
loop's oscillation under the hold moves the tip along the surface as well (the table prints how fast, per newton
of force error), so a slide at B1's own speed scale reverses, and the contact sticks, once the error grows past a
few newtons; and the loop's poles move with the pose (σ by ~4 % per cm along x), so the slide must not carry the
tip far in the fit window (``SPEED`` · 2 s = 0.4 mm). Writes benchmarks/out/sampled_stability_map.png and .json,
prints the poles, a table, and the diagnosis of the earlier runs' low readings (:func:`diagnose`) (~15 s).

    PYTHONPATH=$PWD python3 benchmarks/sampled_stability_map.py [--no-runs]
"""

from __future__ import annotations

import json
import sys
import time
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from contactdyn.analysis.sampled_stability import (  # noqa: E402
    SampledLoop,
    linear_window,
    measured_rate,
    run_from,
    with_tip_velocity,
)
from contactdyn.analysis.stability import contact_phase_scene, modal_poles  # noqa: E402

SCENE = str(Path(__file__).resolve().parents[1] / "sims" / "b1_force_loop.toml")
Q0 = [0.337307481430, -1.318116071653]  #: B1's start, tip at (0.45, −0.15)
START = [0.43, -0.15, 0.0]  #: [m] the reference's start (the scene's)
OUT = Path(__file__).resolve().parent / "out"
RATES = np.geomspace(50.0, 2000.0, 41)  #: [Hz]
DELAYS = np.arange(0, 9)  #: [samples]
SPEED = 2e-4  #: [m/s] the runs' sliding speed along −x
KICK = 0.01  #: [N] the set-point's raise over the equilibrium's
T_FIT, LIMIT, DURATION = 0.3, 0.5, 2.0  #: [s] fit from (the 40–80 Hz modes gone), [N] error at most, [s] a run
#: (rate [Hz], delay [samples]) on both sides of the boundary
POINTS = [(200.0, 2), (200.0, 4), (300.0, 3), (150.0, 3), (100.0, 1), (100.0, 2), (500.0, 6), (500.0, 8)]


def moving(speed: float) -> dict:
    """Overrides: the reference from START moving along −x at ``speed`` [m/s] (0: held), the start's slide
    direction −x (B1's)."""
    return {"phase.0.reference.start": START,
            "phase.0.reference.moves": [{"kind": "constant_velocity", "delta": [-4.0 * speed, 0.0, 0.0],
                                         "duration": 4.0}],
            "robot.v0": [0.287298334621 / 15.0, -0.774596669241 / 15.0]}


def linearised() -> tuple[SampledLoop, object]:
    """The sampled loop at B1's start, the reference held there (its pieces hold for every rate and delay)."""
    loop = SampledLoop(contact_phase_scene(SCENE, Q0, moving(0.0)), t_eq=0.0)
    return loop, loop.linearize()


def simulator_run(loop: SampledLoop, lin, rate: float, delay: int, speed: float = SPEED, kick: float = KICK,
                  duration: float = DURATION):
    """The simulator's own sampled run from the equilibrium, sliding at ``speed``, the set-point raised by
    ``kick`` [N]: (its Result, its CPU time [s])."""
    over = {**moving(speed), "controller.sample_rate": rate, "controller.delay": delay, "duration": duration,
            "solver.output_rate": rate, "solver.rtol": 1e-10, "solver.atol": 1e-12,
            "phase.0.force.0.value": 100.0 + kick}
    x0 = with_tip_velocity(loop.loop, lin.x, [-speed, 0.0, 0.0])
    cpu = time.process_time()
    r = run_from(contact_phase_scene(SCENE, Q0, over), x0)
    return r, time.process_time() - cpu


def measure(loop: SampledLoop, lin, points: list) -> list[dict]:
    rows = []
    for rate, delay in points:
        z = lin.poles(rate, delay)
        r, cpu = simulator_run(loop, lin, rate, delay)
        t, err = linear_window(r, T_FIT, LIMIT)
        sigma, freq = measured_rate(t, err, z[0], 1.0 / rate)
        slip = r["contact.tip.v_slip"].reshape(len(r.t), -1)[:, 0] + SPEED
        sel = r.t >= T_FIT
        coupling = float(np.ptp(slip[sel]) / max(np.ptp(err[t >= T_FIT]), 1e-30))
        row = {"rate": rate, "delay": delay, "window": [float(t[0]), float(t[-1])], "cpu": cpu,
               "predicted": lin.sigma(rate, delay), "f_predicted": abs(float(np.angle(z[0]))) * rate / (2 * np.pi),
               "measured": sigma, "f_measured": freq, "max_error": float(np.max(np.abs(err))),
               "slip_per_newton": coupling, "poles": [[abs(complex(p)), float(np.angle(p))] for p in z[:5]]}
        rows.append(row)
        gap = (sigma - row["predicted"]) / abs(row["predicted"])
        print(f"{rate:6.0f} Hz  d = {delay}  σ predicted {row['predicted']:+8.4f}  measured {sigma:+8.4f} 1/s "
              f"({100 * gap:+5.2f} %)  f {row['f_predicted']:7.3f} / {freq:7.3f} Hz  window {t[0]:.2f}–{t[-1]:.2f} s "
              f"max|err| {row['max_error']:.3f} N  slip swing {1e3 * coupling:.1f} (mm/s)/N  cpu {cpu:.2f} s")
        print("          leading z: " + "  ".join(
            f"|z| {abs(p):.5f} σ {np.log(abs(p)) * rate:+8.3f} f {abs(np.angle(p)) * rate / (2 * np.pi):6.2f} Hz"
            for p in z[:5:2]))
    return rows


#: (rate, delay, speed [m/s], kick [N], error limit [N]): the earlier runs' conditions, one at a time
DIAGNOSIS = [(100.0, 2, 0.01, KICK, 30.0), (200.0, 4, 0.01, KICK, 30.0), (200.0, 4, 0.001, 1.0, 30.0)]


def diagnose(loop: SampledLoop, lin) -> list[dict]:
    """Why runs at 0.01 m/s with up to 30 N of error read the unstable side low: the run's pencil modes near the
    force mode (a pose that drifts makes the mode a chirp, which the pencil splits into two) and whether the slip
    turned (the window then stops there: fitted on the whole run instead, to show what it gives)."""
    rows = []
    for shift in (0.01, 0.02):  # the pose's part: the loop linearised 1 and 2 cm further along the slide
        over = {**moving(0.0), "phase.0.reference.start": [START[0] - shift, START[1], START[2]]}
        there = SampledLoop(contact_phase_scene(SCENE, Q0, over), t_eq=0.0).linearize()
        print(f"σ predicted {100 * shift:.0f} cm further along: " + ", ".join(
            f"{f:.0f} Hz d = {d}: {there.sigma(f, d):+.3f} ({100 * (there.sigma(f, d) / lin.sigma(f, d) - 1):+.1f} %)"
            for f, d in ((100.0, 2), (200.0, 4))))
    for rate, delay, speed, kick, limit in DIAGNOSIS:
        z = lin.poles(rate, delay)[0]
        r, _ = simulator_run(loop, lin, rate, delay, speed, kick, duration=3.0)
        err = r["contact.tip.F_n"] - r["contact.tip.F_d"]
        sel = (r.t >= T_FIT) & (np.cumsum(np.abs(err) > limit) == 0)
        t, e = r.t[sel], err[sel]
        found = modal_poles(t, e)
        near = sorted((p for p in found if p.imag > 0 and abs(p.imag / (2 * np.pi) - 15.5) < 1.0),
                      key=lambda p: -p.real)
        sigma, _ = measured_rate(t, e, z, 1.0 / rate)
        stuck = float(np.max(r["contact.tip.stuck"][sel]))
        drift = float(r["tip"][sel][-1, 0] - r["tip"][sel][0, 0])
        rows.append({"rate": rate, "delay": delay, "speed": speed, "kick": kick, "predicted": lin.sigma(rate, delay),
                     "measured": sigma, "near": [[p.real, p.imag / (2 * np.pi)] for p in near], "stuck": stuck,
                     "drift": drift})
        print(f"{rate:6.0f} Hz  d = {delay}  slide {speed:.3f} m/s  kick {kick:4.2f} N  window {t[0]:.2f}–{t[-1]:.2f} s"
              f"  tip moved {1e3 * drift:+6.1f} mm  stuck {'yes' if stuck else 'no'}: σ predicted "
              f"{lin.sigma(rate, delay):+.3f}, measured {sigma:+.3f} 1/s; pencil modes at 14.5–16.5 Hz: "
              + ", ".join(f"{p.real:+.3f}/{p.imag / (2 * np.pi):.2f} Hz" for p in near))
    return rows


def draw(sigma: np.ndarray, rows: list[dict], path: Path) -> None:
    fig, ax = plt.subplots(figsize=(8.0, 4.8))
    lim = float(np.max(np.abs(sigma)))
    mesh = ax.pcolormesh(RATES, DELAYS, sigma, cmap="RdBu_r", vmin=-lim, vmax=lim, shading="nearest")
    ax.contour(RATES, DELAYS, sigma, levels=[0.0], colors="k", linewidths=1.6)
    for r in rows:
        ax.plot(r["rate"], r["delay"], "o", ms=9, mfc="none", mec="k")
        ax.annotate(f"{r['predicted']:+.3f}\n{r['measured']:+.3f}", (r["rate"], r["delay"]),
                    textcoords="offset points", xytext=(7, -4), fontsize=7)
    ax.set_xscale("log")
    ax.set_xlabel("sample rate [Hz]")
    ax.set_ylabel("delay [samples]")
    ax.set_title("B1 force loop (hybrid, K_F = 50/s): decay rate σ = ln|z_max|·rate [1/s]\n"
                 "black: |z_max| = 1; circles: z-domain prediction (top) / simulator's sampled run (bottom)",
                 fontsize=10)
    fig.colorbar(mesh, ax=ax, label="σ [1/s] (> 0: grows)")
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


def main() -> None:
    loop, lin = linearised()
    sigma = lin.map(RATES, DELAYS)
    print("continuous poles [1/s]:", np.round(np.sort_complex(lin.continuous), 3))
    print("σ [1/s] at B1's start; rows: delay [samples], columns: rate [Hz]")
    cols = [0, 5, 10, 15, 20, 25, 30, 35, 40]
    print("     " + "".join(f"{RATES[j]:9.0f}" for j in cols))
    for i, d in enumerate(DELAYS):
        print(f"{d:4d} " + "".join(f"{sigma[i, j]:9.2f}" for j in cols))
    rows = [] if "--no-runs" in sys.argv else measure(loop, lin, POINTS)
    diagnosis = [] if "--no-runs" in sys.argv else diagnose(loop, lin)
    OUT.mkdir(parents=True, exist_ok=True)
    draw(sigma, rows, OUT / "sampled_stability_map.png")
    (OUT / "sampled_stability_map.json").write_text(json.dumps(
        {"rates": RATES.tolist(), "delays": DELAYS.tolist(), "sigma": sigma.tolist(), "speed": SPEED, "kick": KICK,
         "points": rows, "diagnosis": diagnosis}, indent=1))


if __name__ == "__main__":
    main()
