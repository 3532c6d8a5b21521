"""Motors and force-reading laws on the compiled path agree with the readable model."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from contactdyn.compiled.rhsplan import ModePlan
from contactdyn.model.paths import Gap
from contactdyn.model.phases import start_phase
from contactdyn.model.system import System
from contactdyn.scene.scene_file import load_scene
from contactdyn.simulate import prepare, run_system

READABLE = Gap("test", "readable model forced by the test", "always", lambda modes, phase: True)


TIGHT = {"solver.rtol": 1e-11, "solver.atol": 1e-13}  # the paths differ by round-off; at the scenes' own
# tolerances a clip or a touch without an event shifts the step sequence, and the runs then differ by ~rtol


def _both(scene: str, overrides: dict):
    overrides = {**TIGHT, **overrides}
    compiled = run_system(System(load_scene(scene, overrides)))
    readable_system = System(load_scene(scene, overrides))
    readable_system.fast_path_gaps = [READABLE]  # every plan declines: System.evaluate integrates
    return compiled, run_system(readable_system)


def _close(a: np.ndarray, b: np.ndarray, rtol: float) -> None:
    np.testing.assert_allclose(a, b, rtol=0, atol=rtol * max(float(np.abs(b).max()), 1e-300))


@pytest.mark.parametrize("u_max", [None, 4.0])  # None: the scene's own; 4 V: clips while the writer accelerates
def test_dc_motors_through_rigid_gears_are_compiled_and_agree_with_the_readable_model(u_max):
    overrides = {"duration": 0.3} if u_max is None else {"duration": 0.3, "robot.drive.u_max": u_max}
    compiled, readable = _both("case2_writer_motors", overrides)
    assert compiled.stats["compiled_modes"] >= 1 and not compiled.stats["fallback_modes"]
    assert readable.stats["compiled_modes"] == 0
    if u_max is not None:
        assert np.any(np.abs(readable["u"]) >= u_max)  # the clipping branch ran
    for key in ("q", "v", "tau", "u"):
        _close(compiled[key], readable[key], 1e-8)


def test_an_elastic_transmission_is_compiled_and_agrees_with_the_readable_model():
    compiled, readable = _both("case3_a_position", {"duration": 0.4})  # the approach, in free flight
    assert compiled.stats["compiled_modes"] == 1 and not compiled.stats["fallback_modes"]
    theta = next(k for k in compiled.channels if k.endswith(".theta"))
    for key in ("q", "v", "tau", "u", theta):
        _close(compiled[key], readable[key], 1e-8)


@pytest.mark.parametrize("scene", ["case3_a_position", "case3_b_force"])  # position_dynamic; force_dynamic, a row
def test_a_force_reading_law_is_folded_into_the_plan_as_in_the_readable_model(scene):
    system, modes, phase, x0 = prepare(load_scene(scene))
    press = start_phase(system, 1, 0.0, x0, phase)
    assert press.controller.uses_forces
    touching = [replace(m, touching=True) for m in modes]
    plan = ModePlan(system, touching, press)
    assert plan.ok, plan.reason
    rng = np.random.default_rng(5)
    for k in range(3):
        t, x = 0.02 * k, x0 + 1e-3 * rng.normal(size=system.n)
        ref = system.evaluate(t, x, touching, press).xdot
        assert np.abs(plan.rhs(t, x) - ref).max() <= 1e-12 * (1.0 + np.abs(ref).max())


def test_a_force_phase_runs_compiled_and_agrees_with_the_readable_model():
    compiled, readable = _both("case3_b_force", {"duration": 1.5})  # touch and press at 1.407 s
    assert compiled.stats["compiled_modes"] >= 2 and not compiled.stats["fallback_modes"]
    assert [e["kind"] for e in compiled.events] == [e["kind"] for e in readable.events]
    for key in ("q", "tau", "u", "contact.tip.F_n"):
        _close(compiled[key], readable[key], 1e-8)


def test_a_reference_carried_by_a_body_runs_compiled_and_agrees_with_the_readable_model():
    compiled, readable = _both("case1_cart", {"duration": 1.1})  # the push phase rides on the cart from 1.0 s
    assert compiled.stats["compiled_modes"] >= 3 and not compiled.stats["fallback_modes"]
    assert [e["kind"] for e in compiled.events] == [e["kind"] for e in readable.events]
    for key in ("q", "tau", "u", "body.cart.x", "contact.tip.F_n"):
        _close(compiled[key], readable[key], 1e-8)
