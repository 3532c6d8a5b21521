"""The batched output of motor, elastic and force-reading phases equals the readable model per sample.

Each scene runs twice on the same integration: once with the plans' batched output
(:func:`~contactdyn.samples.plan_samples`), once with every output sample from
``System.evaluate(full=True)``. Every channel must agree to 1e-10 (relative to the channel's scale).
"""

from __future__ import annotations

import numpy as np
import pytest

import contactdyn.rhsplan as rhsplan
from contactdyn import Robot, parse_scene
from contactdyn.samples import evaluated_samples
from contactdyn.simulate import simulate

#: scene -> a duration [s] that holds its phases' kinds (motor, elastic, force-reading, a carried reference)
SCENES = {"case1_cart": 1.1, "case2_writer_motors": 0.3, "case3_a_force": 0.3, "case3_b_force": 0.3}


def _readable(plan, ts, X):
    return evaluated_samples(plan.system, ts, X, plan.modes, plan.phase)


#: a prismatic axis under a joint PD asking far more than its voltage limit gives: it clips, then settles
CASE3 = {"R": 0.175, "C_M": 0.0575, "J": 7.9e-4, "N": 50.0, "wheel_radius": 0.15, "u_max": 6.0}


def _clipping_axis(drive: dict) -> dict:
    return {"duration": 0.3, "solver": {"output_rate": 1000.0},
            "robot": {"urdf": "cylindrical3", "active_joints": ["q3"], "gravity": [0.0, 0.0, 0.0], "q0": [0.0],
                      "drive": drive},
            "controller": {"kind": "joint_pd", "kp": 2e5, "kd": 0.0},
            "phase": [{"name": "go", "reference": {"space": "joint", "start": [0.02], "moves": []}}]}


def _assert_same_channels(scene, overrides, monkeypatch):
    fast = simulate(scene, overrides)
    monkeypatch.setattr(rhsplan, "plan_samples", _readable)
    ref = simulate(scene, overrides)
    assert fast.channels.keys() == ref.channels.keys()
    assert np.array_equal(fast.channels["t"], ref.channels["t"])
    for name, want in ref.channels.items():
        got = fast.channels[name]
        scale = 1.0 + np.nanmax(np.abs(want)) if np.any(np.isfinite(want)) else 1.0
        assert np.array_equal(np.isnan(got), np.isnan(want)), name
        assert np.nanmax(np.abs(got - want), initial=0.0) <= 1e-10 * scale, name
    return fast


@pytest.mark.parametrize("scene", SCENES)
def test_batched_output_equals_evaluate(scene, monkeypatch):
    _assert_same_channels(scene, {"duration": SCENES[scene], "solver.output_rate": 500.0}, monkeypatch)


@pytest.mark.parametrize("drive", [{"kind": "dc_motor", **CASE3},
                                   {"kind": "elastic", **CASE3, "c": 14000.0, "d": 0.0196}], ids=["rigid", "elastic"])
def test_clipped_voltages_in_the_batched_output(drive, monkeypatch):
    """Samples where a voltage clips take the drive law itself: the same u (at ±u_max), τ and motion channels."""
    result = _assert_same_channels(parse_scene(_clipping_axis(drive)), None, monkeypatch)
    u = result.channels["u"][:, 0]
    assert np.mean(np.abs(u) == CASE3["u_max"]) > 0.1 and np.mean(np.abs(u) < CASE3["u_max"]) > 0.1


def test_folded_forces_with_clipped_voltages_in_the_batched_output(monkeypatch):
    """A7 pressing a bonded wall with a voltage limit (tests/test_controllers.py's case): the measured force
    folded into the solve and the clip re-checked with it, through the plan's fold at every sample."""
    q0 = [0.3, 1.2]  # [rad] the writer's pose, tip at p0
    p0 = Robot.load("writer2r").frame_position(np.array(q0), "tip")
    drive = {"kind": "dc_motor", "R": 0.272, "C_M": 0.061, "J": 0.000452, "N": 160.0, "N_star": 65.12, "u_max": 4.0}
    doc = {"duration": 0.3, "solver": {"output_rate": 500.0},
           "robot": {"urdf": "writer2r", "q0": q0, "drive": drive},
           "controller": {"kind": "position_dynamic", "kp": 400.0, "kv": 40.0},
           "phase": [{"name": "main", "reference": {"space": "task", "start": (p0 + [0.01, 0.0, -0.03]).tolist(),
                                                    "moves": []}}],
           "contact": {"c": {"point": p0.tolist(), "bonded": True,
                             "normal": {"direction": [-1, 0, 0], "model": "b", "k": 1e4, "b": 10.0, "m": 2.0}}}}
    result = _assert_same_channels(parse_scene(doc), None, monkeypatch)
    u = result.channels["u"]
    assert np.mean(np.abs(u) == 4.0) > 0.05 and np.mean(np.abs(u) < 4.0) > 0.05
