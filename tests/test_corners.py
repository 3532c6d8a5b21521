"""Segments end at the set-points' corners: a trapezoid reference's kinks do not fall inside a step.

The writer's joints follow a trapezoid through the dynamic position law A7, whose error obeys
η̈ = −K_p η − K_v η̇ exactly (tests/test_controllers.py): q = q_ref(t) + η(t) in closed form,
with q̈ jumping at each of the trapezoid's four corners.
"""

from __future__ import annotations

import numpy as np
import pytest
from test_contact_layer import axis_scene
from test_controllers import KP, KV, Q0, critically_damped, writer_doc

from contactdyn import parse_scene, simulate
from contactdyn.hybrid.loop import HybridRun
from contactdyn.laws.trajectory import Move, Reference
from contactdyn.model.system import System

START, DELTA = np.array([0.35, 1.1]), np.array([0.2, -0.3])
TRAPEZOID = Move(DELTA, 0.05, 0.4, "trapezoid", 0.15)  # corners at 0.05, 0.11, 0.39, 0.45 s
CORNERS = (0.05, 0.11, 0.39, 0.45)  # [s]
RTOL = 1e-8


def _run(max_step: float, output_rate: float):
    ref = {"space": "joint", "start": START.tolist(), "moves": [
        {"kind": "trapezoid", "delta": DELTA.tolist(), "duration": 0.4, "start": 0.05, "accel_fraction": 0.15}]}
    doc = writer_doc({"kind": "position_dynamic", "space": "joint", "kp": KP, "kv": KV}, {"reference": ref},
                     rtol=RTOL)
    doc["solver"].update(max_step=max_step, output_rate=output_rate)
    run = HybridRun(System(parse_scene(doc)))
    return run, run.run(0.0)


@pytest.mark.parametrize("max_step, output_rate", [(np.inf, 500.0), (0.0173, 700.0)])
def test_a_trapezoid_reference_is_integrated_piece_by_piece(max_step, output_rate):
    run, r = _run(max_step, output_rate)
    # a segment boundary at each corner: the one before ends there, the next starts one float later
    ends = np.array([seg.t1 for seg in run.segments[:-1]])
    starts = np.array([seg.t0 for seg in run.segments[1:]])
    np.testing.assert_allclose(ends, CORNERS, rtol=0, atol=1e-15)
    np.testing.assert_array_equal(starts, np.nextafter(ends, np.inf))
    assert r.stats["corners"] == 4 and r.events == []  # no event, no mode change
    # every piece is smooth, so the run is as accurate as the tolerance asks: q 1e-10–3e-10 rad, v 2e-9–2.5e-8
    # rad/s off (without the corners the steps straddling them leave 1.4e-9–2.5e-9 rad and 8e-8–2e-7 rad/s,
    # and take 89–103 steps instead of 26–36)
    reference = Reference(START, (TRAPEZOID,))
    q_ref, v_ref = (np.array([reference.at(t)[k] for t in r.t]) for k in (0, 1))
    eta0 = Q0 - START
    assert np.abs(r["q"] - (q_ref + critically_damped(eta0, r.t))).max() <= 0.1 * RTOL
    v_exact = v_ref + np.outer(-KP * r.t * np.exp(-0.5 * KV * r.t), eta0)  # η̇ of (1 + 20 t) e^(−20 t) η0
    assert np.abs(r["v"] - v_exact).max() <= 2 * RTOL * np.abs(v_exact).max()
    assert r.stats["steps"] <= 50


def test_the_step_placement_does_not_change_the_result():
    (_, a), (_, b) = _run(np.inf, 500.0), _run(0.0173, 500.0)
    assert a.stats["steps"] != b.stats["steps"]  # other steps, the same corners
    np.testing.assert_allclose(a["q"], b["q"], rtol=0, atol=0.1 * RTOL)
    np.testing.assert_allclose(a["v"], b["v"], rtol=0, atol=3 * RTOL * np.abs(b["v"]).max())


def test_a_force_jumping_through_zero_at_a_corner_is_the_event_a_straddling_step_would_find():
    """A rigid contact held by a 10 N push whose set-point steps to a 5 N pull at 0.3 s: the normal force
    jumps through zero between the segments either side of the corner (no step sees the sign change),
    and the contact separates there (events.fired_across)."""
    scene = axis_scene({"model": "rigid"}, q0=1.0, v0=0.0, duration=0.4, solver={"rtol": 1e-8, "atol": 1e-10})
    doc = {**scene.document, "controller": {"kind": "task_pd", "kp": 0.0, "kd": 0.0, "axes": [[1.0, 0.0, 0.0]]},
           "phase": [{"name": "pull", "force": [{"contact": "tip", "value": -5.0, "kind": "step", "start": 0.3,
                                                 "initial": 10.0}]}]}
    r = simulate(parse_scene(doc))
    assert r.stats["corners"] == 1
    assert [(e["kind"], e["t"]) for e in r.events] == [("separate", 0.3)]
    before, after = r.t < 0.3, r.t > 0.3
    np.testing.assert_allclose(r["contact.tip.F_n"][before], 10.0, rtol=1e-6)
    assert np.all(r["contact.tip.touching"][after] == 0) and np.all(r["contact.tip.F_n"][after] == 0.0)
