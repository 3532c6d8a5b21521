"""The compiled call run interpreted (contactdyn.numerics.twins, a scene kind's first run): its outputs are the
compiled run's bit for bit, for B1 and for scenes with a user's stage law, controller and force-reading law;
it compiles nothing but its leaves (numba's compile events), and there is no readable model left to call
(``contactdyn.model.evaluation`` has no ``evaluate``)."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest
from numba.core import event

from contactdyn.model import evaluation
from contactdyn.model.paths import INTERPRETED, PIPELINE
from contactdyn.numerics.twins import LEAVES, Twins
from contactdyn.simulate import simulate

EXAMPLES = Path(__file__).resolve().parent.parent / "examples"
#: modules whose functions may compile in an interpreted run: the leaves' (and their callees'), and a law's cfunc at
#: bind (the model's numba functions the loop and the checks call outside the pipeline run as twins: a turning
#: surface's kinematics, an impact's chains)
OUTSIDE = ("contactdyn.robot.rigid_body", "contactdyn.numerics.linalg", "contactdyn.numerics.dop853",
           "contactdyn.numerics.dense_output", "contactdyn.hybrid.steps", "contactdyn.laws.")


class _Compiles(event.Listener):
    def __init__(self) -> None:
        self.modules: list[str] = []

    def on_start(self, e) -> None:
        function = getattr((e.data or {}).get("dispatcher"), "py_func", None)
        self.modules.append(getattr(function, "__module__", "") or "")

    def on_end(self, e) -> None:
        pass


@pytest.fixture(autouse=True)
def user_laws(fresh_user_imports):
    """The examples' law modules imported afresh, the registries (stage laws, drive kinds, controllers) left as they
    were (conftest's fresh_user_imports)."""
    from contactdyn.laws.controllers import CONTROLLERS

    controllers = dict(CONTROLLERS)
    yield
    for module in ("cubic_stage", "my_laws", "force_law"):
        sys.modules.pop(module, None)
    CONTROLLERS.clear()
    CONTROLLERS.update(controllers)


def _same(interpreted, compiled) -> None:
    assert {row["path"] for row in interpreted.stats["paths"].values()} == {INTERPRETED}
    assert {row["path"] for row in compiled.stats["paths"].values()} == {PIPELINE}
    assert interpreted.channels.keys() == compiled.channels.keys()
    for name, values in compiled.channels.items():
        assert np.array_equal(np.asarray(interpreted.channels[name]), np.asarray(values), equal_nan=True), name
    assert [(e["kind"], e["t"]) for e in interpreted.events] == [(e["kind"], e["t"]) for e in compiled.events]
    assert interpreted.stats["rhs_evals"] == compiled.stats["rhs_evals"]


@pytest.mark.parametrize("scene, overrides", [
    ("b1", {"duration": 0.3}),
    ("lever", {"duration": 0.1}),  # a surface turning with a body's frame, touched (an impact) at 68 ms, then a slip
    (EXAMPLES / "cubic_press.toml", {"duration": 0.1}),  # a user's stage law (examples/cubic_stage.py)
    (EXAMPLES / "impedance_press.toml", {"duration": 0.2}),  # a user's controller (examples/my_laws.py)
    (EXAMPLES / "force_pi_press.toml", {"duration": 0.2}),  # a user's force-reading law (examples/force_law.py)
])
def test_the_interpreted_run_is_the_compiled_run(scene, overrides):
    compiled = simulate(scene, overrides)
    seen = _Compiles()
    event.register("numba:compile", seen)

    try:
        interpreted = simulate(scene, overrides, interpreted=True)
    finally:
        event.unregister("numba:compile", seen)
    assert not hasattr(evaluation, "evaluate"), "the readable model (evaluate) is back"
    assert all(module.startswith(OUTSIDE) for module in seen.modules), seen.modules
    _same(interpreted, compiled)


def test_the_twins_are_the_package_functions_with_their_own_namespaces():
    from contactdyn.model.pipeline import pipeline, robot_terms
    from contactdyn.robot import rigid_body

    twins = Twins()
    twin = twins.of(pipeline.call)
    assert twin.__code__ is pipeline.call.py_func.__code__ and twin.__globals__ is not vars(pipeline)
    assert twin.__globals__["robot_terms"].__globals__ is twins.shadows["contactdyn.model.pipeline.robot_terms"]
    assert twins.of(robot_terms.robot_terms).__globals__["_kinematics"] is rigid_body._kinematics  # a leaf
    assert "contactdyn.robot.rigid_body._kinematics" in LEAVES
    assert vars(pipeline)["robot_terms"] is robot_terms.robot_terms  # the module itself untouched
    assert twins.of(np.zeros) is np.zeros and twins.of(3) == 3


def test_a_sampled_laws_command_runs_as_twins_in_an_interpreted_run(monkeypatch):
    """The sampled real cell's law (hybrid: dynamic_law.force_targets, computed_torque.torque) computes its command in
    Python at each sample: in an interpreted run it calls their twins (numerics.twins.current), so a first run does
    not compile them; the outputs stay the compiled run's bit for bit. (Each is replaced by a fresh, never compiled
    dispatcher of the same function: a call of it from Python would compile it, and give it a signature.)"""
    import numba

    from contactdyn.laws.controllers import computed_torque, dynamic_law

    overrides = {"duration": 0.05}
    compiled = simulate("force_loop_real_cell", overrides)
    fresh = {}
    for module, name in ((computed_torque, "torque"), (dynamic_law, "force_targets")):
        fresh[name] = numba.njit(getattr(module, name).py_func)
        monkeypatch.setattr(module, name, fresh[name])
    interpreted = simulate("force_loop_real_cell", overrides, interpreted=True)
    assert interpreted.stats["samples"] == compiled.stats["samples"] > 20
    assert {name: f.signatures for name, f in fresh.items()} == {"torque": [], "force_targets": []}
    _same(interpreted, compiled)


def test_a_turning_surfaces_kinematics_and_an_impacts_chain_run_as_twins_in_an_interpreted_run(monkeypatch):
    """The lever's surface turns with the bar's frame: the start's kinematics and the scene's checks (before the run)
    call contact.turning_surface from Python, its touch's impact orients the chains (chain_forces.orient). In an
    interpreted run each is its twin (numerics.twins.current), so a first run compiles neither (turning_surface
    alone took a cold first run 2.5–3.5 s, in the run and in its helper). Each is replaced by a fresh, never compiled
    dispatcher of the same function: a call of it from Python would compile it and give it a signature."""
    import numba

    from contactdyn.model import chain_forces, system

    overrides = {"duration": 0.1}
    compiled = simulate("lever", overrides)
    fresh = {"turning_surface": numba.njit(system.turning_surface.py_func),
             "orient": numba.njit(chain_forces.orient.py_func)}
    monkeypatch.setattr(system, "turning_surface", fresh["turning_surface"])
    monkeypatch.setattr(chain_forces, "orient", fresh["orient"])
    interpreted = simulate("lever", overrides, interpreted=True)
    assert [e["kind"] for e in interpreted.events] == ["touch", "slip"]
    assert {name: f.signatures for name, f in fresh.items()} == {"turning_surface": [], "orient": []}
    _same(interpreted, compiled)


def test_a_late_leaf_runs_as_its_twin_until_it_arrives_then_compiled_with_the_same_outputs(monkeypatch):
    """The operational law's torque is a late leaf (so are the robot's terms and its frames'): without somewhere it
    arrives from, a plain twin; with one (``late_leaves``: a first run's helper), the run looks at each call here
    (LOOK 0), is told no three times per leaf, then loads it and looks no more: every later call runs it compiled.
    The outputs are the compiled run's bit for bit."""
    import types

    from contactdyn.laws.controllers import operational_law
    from contactdyn.numerics import twins as twins_module
    from contactdyn.numerics.twins import LATE_LEAVES, late_leaves, name_of

    leaf = operational_law.torque
    assert name_of(leaf) in LATE_LEAVES
    plain = Twins().of(leaf)
    assert isinstance(plain, types.FunctionType) and plain.__code__ is leaf.py_func.__code__
    monkeypatch.setattr(twins_module, "LOOK", 0.0)
    overrides = {"duration": 0.02}
    compiled = simulate("case2_writer5dof", overrides)
    looks: dict[str, list] = {}

    def arrived(function, types_):
        looks.setdefault(name_of(function), []).append(types_)
        return len(looks[name_of(function)]) > 3

    with late_leaves(arrived):
        interpreted = simulate("case2_writer5dof", overrides, interpreted=True)
    assert {name_of(leaf), "contactdyn.model.pipeline.robot_terms.robot_terms"} <= set(looks) <= set(LATE_LEAVES)
    assert all(len(seen) == 4 for seen in looks.values()), {name: len(seen) for name, seen in looks.items()}
    assert looks[name_of(leaf)][-1] in [tuple(s) for s in leaf.signatures]  # (loaded: the compiled run's signature)
    assert interpreted.stats["rhs_evals"] > 20  # (most calls after the arrival)
    _same(interpreted, compiled)


def test_every_late_leaf_is_a_numba_function_of_the_package():
    import importlib

    from numba.core.dispatcher import Dispatcher

    from contactdyn.numerics.twins import LATE_LEAVES

    for name in LATE_LEAVES:
        module, _, function = name.rpartition(".")
        assert isinstance(getattr(importlib.import_module(module), function), Dispatcher), name
