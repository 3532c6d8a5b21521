"""The batched output of the one pipeline's modes (PipelineMode.samples: every output sample of a segment in one
compiled call) equals the same call interpreted.

Each scene runs twice on the same integration: once with the pipeline's compiled batched output, once with every
output sample from the interpreted call (``run_agreement.interpreted_samples``). Every channel must agree to 1e-10
(relative to 1 + the channel's largest magnitude).
"""

from __future__ import annotations

import numpy as np
import pytest
from run_agreement import interpreted_samples

from contactdyn import Robot, parse_scene
from contactdyn.hybrid.pipeline_mode import PipelineMode
from contactdyn.model.contact import ContactMode
from contactdyn.model.paths import PIPELINE
from contactdyn.output.channels import _per_sample
from contactdyn.simulate import simulate

#: scene -> a duration [s] that holds its phases' kinds (motor, elastic, force-reading, a carried reference)
SCENES = {"case1_cart": 1.1, "case2_writer_motors": 0.3, "case3_a_force": 0.3, "case3_b_force": 0.3, "b1": 0.3}


_SAMPLES = PipelineMode.samples  #: the method itself, before a test replaces it
_BATCHES: list[int] = []  #: the batches sampled by the interpreted call in place of a compiled mode (their sizes)


def _interpreted(mode, ts, X, modes=None, runs=None):
    """PipelineMode.samples of a compiled mode by the same call interpreted (``runs``: its batches' runs, unused:
    the interpreted call's samples take the whole batch); the interpreted runner's own samples as they are."""
    if mode.interpreted:
        return _SAMPLES(mode, ts, X, modes, runs)
    _BATCHES.append(len(ts))
    return interpreted_samples(mode.system, ts, X, modes if modes is not None else mode.modes, mode.phase)


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
    assert {row["path"] for row in fast.stats["paths"].values()} == {PIPELINE}  # every sample batched
    monkeypatch.setattr(PipelineMode, "samples", _interpreted)
    _BATCHES.clear()
    ref = simulate(scene, overrides)
    assert sum(_BATCHES) == len(ref.channels["t"])  # every sample of the reference on the interpreted call
    assert fast.channels.keys() == ref.channels.keys()
    assert np.array_equal(fast.channels["t"], ref.channels["t"])
    for name, want in ref.channels.items():
        got = fast.channels[name]
        scale = 1.0 + np.nanmax(np.abs(want)) if np.any(np.isfinite(want)) else 1.0
        assert np.array_equal(np.isnan(got), np.isnan(want)), name
        assert np.nanmax(np.abs(got - want), initial=0.0) <= 1e-10 * scale, name
    return fast


@pytest.mark.parametrize("scene", SCENES)
def test_batched_output_equals_the_interpreted_call(scene, monkeypatch):
    _assert_same_channels(scene, {"duration": SCENES[scene], "solver.output_rate": 500.0}, monkeypatch)


@pytest.mark.parametrize("drive", [{"kind": "dc_motor", **CASE3},
                                   {"kind": "elastic", **CASE3, "c": 14000.0, "d": 0.0196}], ids=["rigid", "elastic"])
def test_clipped_voltages_in_the_batched_output(drive, monkeypatch):
    """Samples where a voltage clips take the drive law itself: the same u (at ±u_max), τ and motion channels."""
    result = _assert_same_channels(parse_scene(_clipping_axis(drive)), None, monkeypatch)
    u = result.channels["u"][:, 0]
    assert np.mean(np.abs(u) == CASE3["u_max"]) > 0.1 and np.mean(np.abs(u) < CASE3["u_max"]) > 0.1


def pressing_writer(u_max: float | None = None) -> dict:
    """A7 on the 2-DOF writer pressing a bonded wall under DC motors (``u_max`` [V]: their voltage limit, None:
    none): every sample folded."""
    q0 = [0.3, 1.2]  # [rad] the writer's pose, tip at p0
    p0 = Robot.load("writer2r").frame_position(np.array(q0), "tip")
    drive = {"kind": "dc_motor", "R": 0.272, "C_M": 0.061, "J": 0.000452, "N": 160.0, "N_star": 65.12,
             **({"u_max": u_max} if u_max is not None else {})}
    return {"duration": 0.3, "solver": {"output_rate": 500.0},
            "robot": {"urdf": "writer2r", "q0": q0, "drive": drive},
            "controller": {"kind": "position_dynamic", "kp": 400.0, "kv": 40.0},
            "phase": [{"name": "main", "reference": {"space": "task", "start": (p0 + [0.01, 0.0, -0.03]).tolist(),
                                                     "moves": []}}],
            "contact": {"c": {"point": p0.tolist(), "bonded": True,
                              "normal": {"direction": [-1, 0, 0], "model": "b", "k": 1e4, "b": 10.0, "m": 2.0}}}}


def test_folded_forces_with_clipped_voltages_in_the_batched_output(monkeypatch):
    """A7 pressing a bonded wall with a voltage limit (tests/test_controllers.py's case): the measured force
    folded into the solve and the clip re-checked with it, in the call at every sample."""
    doc = pressing_writer(u_max=4.0)
    result = _assert_same_channels(parse_scene(doc), None, monkeypatch)
    u = result.channels["u"]
    assert np.mean(np.abs(u) == 4.0) > 0.05 and np.mean(np.abs(u) < 4.0) > 0.05


def test_folded_forces_with_coulomb_friction_in_b(monkeypatch):
    """A7 bonded to a wall (a normal row: the measured force folded into the solve) while sliding on a
    compliant model-(a) floor with Coulomb friction: the floor's normal force is its interface stage's, known,
    so −μ max(F_n, 0) d enters the right-hand side before the fold reads it."""
    q0 = [0.3, 1.2]  # [rad] the writer's pose, tip at p0
    p0 = Robot.load("writer2r").frame_position(np.array(q0), "tip")
    drive = {"kind": "dc_motor", "R": 0.272, "C_M": 0.061, "J": 0.000452, "N": 160.0, "N_star": 65.12}
    floor = {"direction": [0, 0, 1], "model": "a", "m": 1.0, "k_ext": 1e4, "b_ext": 5.0, "k_int": 1e4, "b_int": 2.0}
    doc = {"duration": 0.4, "solver": {"output_rate": 500.0},
           "robot": {"urdf": "writer2r", "q0": q0, "drive": drive},
           "controller": {"kind": "position_dynamic", "kp": 400.0, "kv": 40.0},
           "phase": [{"name": "main", "reference": {
               "start": (p0 + [0.0, 0.0, -0.01]).tolist(),
               "moves": [{"kind": "trapezoid", "delta": [0.02, 0.0, 0.0], "duration": 0.4}]}}],
           "contact": {"wall": {"point": p0.tolist(), "bonded": True,
                                "normal": {"direction": [-1, 0, 0], "model": "b", "k": 1e3, "b": 10.0, "m": 2.0}},
                       "floor": {"point": (p0 + [0.0, 0.0, -0.002]).tolist(), "normal": floor,
                                 "tangent": {"model": "friction", "directions": [[1.0, 0.0, 0.0]], "mu": 0.3}}}}
    result = _assert_same_channels(parse_scene(doc), None, monkeypatch)
    sliding = (result["contact.floor.touching"] == 1.0) & (result["contact.floor.stuck"] == 0.0)
    assert sliding.sum() >= 150  # samples with the wall's row folded and the floor sliding
    F_n, F_f = result.channels["contact.floor.F_n"], result.channels["contact.floor.F_f"][:, 0]
    assert F_n.max() > 30.0 and np.abs(F_f).max() > 9.0  # μ F_n of ~12 N in b


def test_mode_flags_per_run_of_samples():
    """A channel read off the modes (touching, stuck) is the same evaluated once per run of samples
    sharing one modes list as per sample, runs of one and a list coming back included."""
    free, slide, stick = [ContactMode()], [ContactMode(True, False, (1.0,))], [ContactMode(True, True)]
    modes_of = [free] * 3 + [slide] + [stick] * 4 + [slide] * 2 + [free]
    for value in (lambda m: m[0].touching, lambda m: m[0].stuck):
        assert np.array_equal(_per_sample(modes_of, value), [float(value(m)) for m in modes_of])
    assert _per_sample([], lambda m: m[0].stuck).shape == (0,)
