"""The fold of a force-reading law into the plan's solve (contactdyn.compiled.plan_fold): the law's matrix at the plan's
own slots gives what the ControlInput path gives."""

from __future__ import annotations

import numpy as np
import pytest
from test_plan_law import _plan_states

import contactdyn.compiled.plan_fold as plan_fold
from contactdyn.compiled.plan_law import compiled_law
from contactdyn.scene.scene_file import load_scene


def _folded(plan, states):
    """(z, ż, τ) of the plan's folded call at each state."""
    m = plan.m
    out = []
    for t, x, Js, phi, _, _ in states:
        y = plan.P.dot(phi)
        if plan.friction_terms is not None:
            plan.friction_terms(y, Js, plan.modes)
        out.append(plan.folded_detail(t, x, Js, phi, y[m * m + m:], y[:m * m].reshape(m, m), y[m * m:m * m + m]))
    return out


def _no_control_input(*args):
    raise AssertionError("the fold took the ControlInput path")


@pytest.mark.parametrize(("name", "rows", "carried"), [("case3_b_force", 1, False), ("case1_cart", 0, True)])
def test_the_fold_from_the_plans_slots_equals_the_fold_from_a_control_input(name, rows, carried, monkeypatch):
    """case3_b_force: a bonded row reaching the surface's mass; case1_cart: a reference carried by the cart."""
    plan, states = _plan_states(load_scene(name))
    assert plan.nr == rows and (plan.phase.carrier is not None) == carried and compiled_law(plan).M is not None
    with monkeypatch.context() as patch:  # the fast path builds no ControlInput (else this compares it with itself)
        patch.setattr(plan_fold, "command_of", _no_control_input)
        fast = _folded(plan, states)
    monkeypatch.setattr(plan_fold, "plan_command", lambda plan: None)  # the ControlInput path
    readable_plan, _ = _plan_states(load_scene(name))
    readable = _folded(readable_plan, states)
    for (z, zdot, tau), (z_r, zdot_r, tau_r) in zip(fast, readable, strict=True):
        assert np.array_equal(z, z_r) and np.array_equal(tau, tau_r)
        assert (zdot is None and zdot_r is None) or np.array_equal(zdot, zdot_r)
