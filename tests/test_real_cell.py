"""sims/force_loop_real_cell.toml (README, "Your robot's friction, your controller's rate"): the force loop that
settles in continuous time and limit-cycles at 500 Hz with a 2-sample delay, its growth bounded by the motors'
voltage limit. The long runs and the table are benchmarks/real_cell_demo.py's; these are short runs of the same
scene (a few s of CPU each)."""

from __future__ import annotations

import tomllib
import warnings

import numpy as np

from contactdyn import parse_scene, simulate
from contactdyn.model.paths import PIPELINE
from contactdyn.scene.scene_file import sims_dir

SCENE = sims_dir() / "force_loop_real_cell.toml"
F_D = 50.0  #: [N] the scene's set-point


def _run(duration: float, sampled: bool = True):
    doc = tomllib.loads(SCENE.read_text())
    doc["duration"] = duration
    if not sampled:
        for key in ("sample_rate", "delay"):
            doc["controller"].pop(key)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return simulate(parse_scene(doc, {}, SCENE)), doc


def _amplitude(r, t0: float, t1: float) -> float:
    """√2 × the RMS of F_n about its mean over [t0, t1] [N]: a sinusoid's amplitude."""
    window = (r.t >= t0) & (r.t <= t1)
    return float(np.sqrt(2.0) * np.std(r["contact.tip.F_n"][window]))


def test_the_continuous_loop_settles_at_the_set_point():
    r, _ = _run(2.0, sampled=False)
    last = r.t >= 1.5
    f = r["contact.tip.F_n"][last]
    assert abs(f.mean() - F_D) < 0.05 and np.ptp(f) < 0.5  # friction's residual stick-slip: ~0.1 N
    assert not np.any(np.abs(r["u"][last]) >= 24.0 - 1e-9)  # no voltage clips


def test_the_sampled_loop_cycles_with_a_steady_amplitude_bounded_by_the_voltage_limit():
    r, doc = _run(3.0)
    first, second = _amplitude(r, 1.0, 2.0), _amplitude(r, 2.0, 3.0)
    assert first > 5.0 and abs(second / first - 1.0) < 0.1  # neither decaying nor growing (the hunting: < 2 N)
    last = r.t >= 1.0
    f = r["contact.tip.F_n"][last]
    assert abs(f.mean() - F_D) < 0.5 and f.min() > 10.0  # the integral holds the mean; the contact stays pressed
    u_max = doc["robot"]["drive"]["u_max"]
    clipped = np.mean(np.abs(r["u"][last, 0]) >= u_max - 1e-9)
    assert 0.1 < clipped < 0.6  # the shoulder's voltage clips in every cycle, not always
    assert not np.any(r["joint_stuck"][last] > 0.5)  # the joints slide through the cycle
    assert {p["path"] for p in r.stats["paths"].values()} == {PIPELINE}


def test_a_slide_that_stops_and_slips_within_one_held_step_is_seen():
    """The shoulder, sliding, comes to rest at 0.17033 s and slips again 0.8 ms later, both inside one 2 ms step
    between samples: its joint_stick is watched at the step's stages (hybrid.events.StateWatch), so the default
    DOP853C logs the events RK45 logs, at the same instants (before: neither, and the shoulder slid backwards for
    0.8 ms with its friction pushing it on)."""
    fast = simulate("force_loop_real_cell", {"duration": 0.175})
    ref = simulate("force_loop_real_cell", {"duration": 0.175, "solver.method": "RK45"})
    assert [(e["kind"], e["name"]) for e in fast.events] == [(e["kind"], e["name"]) for e in ref.events]
    np.testing.assert_allclose([e["t"] for e in fast.events], [e["t"] for e in ref.events], rtol=0, atol=1e-8)
    assert [e["kind"] for e in fast.events if e["t"] > 0.17] == ["joint_stick", "joint_slip"]
