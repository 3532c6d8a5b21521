"""The batched output of motor, elastic and force-reading phases equals the readable model per sample.

Each scene runs twice on the same integration: once with the plans' batched output
(:func:`~contactdyn.samples.plan_samples`), once with every output sample from
``System.evaluate(full=True)``. Every channel must agree to 1e-10 (relative to the channel's scale).
"""

from __future__ import annotations

import numpy as np
import pytest

import contactdyn.rhsplan as rhsplan
from contactdyn.samples import evaluated_samples
from contactdyn.simulate import simulate

#: scene -> a duration [s] that holds its phases' kinds (motor, elastic, force-reading, clipping)
SCENES = {"case1_cart": 0.6, "case2_writer_motors": 0.3, "case3_a_force": 0.3, "case3_b_force": 0.3}


def _readable(plan, ts, X):
    return evaluated_samples(plan.system, ts, X, plan.modes, plan.phase)[0]


@pytest.mark.parametrize("scene", SCENES)
def test_batched_output_equals_evaluate(scene, monkeypatch):
    overrides = {"duration": SCENES[scene], "solver.output_rate": 500.0}
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


def test_clipped_voltages_reach_the_output():
    """case1's cart clips its motor voltage: the batched output gives the law's clipped u there, |u| = u_max."""
    result = simulate("case1_cart", {"duration": 0.6, "solver.output_rate": 500.0})
    u = result.channels["body.cart.u"] if "body.cart.u" in result.channels else result.channels["u"]
    assert np.isclose(np.abs(u).max(), np.nanmax(np.abs(u))) and np.any(np.isclose(np.abs(u), np.abs(u).max()))
