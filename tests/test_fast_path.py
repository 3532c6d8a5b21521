"""The compiled right-hand side runs every mode unless a part declared at load that it cannot (model.paths)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from contactdyn import load_scene, parse_scene, simulate
from contactdyn.compiled.rhsplan import _PLANS
from contactdyn.model.chain import ChainStage
from contactdyn.model.paths import ENERGY, UNDECLARED, Gap
from contactdyn.model.system import System
from contactdyn.scene.scene_file import sims_dir
from contactdyn.simulate import run_system

HARD = Path(__file__).resolve().parent.parent / "benchmarks" / "hard"
READABLE = Gap("test", "readable model forced by the test", "always", lambda modes, phase: True)
HUNT_CROSSLEY = {"model": "chain", "environment": [{"k": 1e7, "b": 1e9, "law": "hunt_crossley", "exponent": 1.5}]}


def axis_scene(normal: dict, duration: float):
    """The cylindrical robot's vertical axis (1 DOF) falling at 0.5 m/s onto a surface 1 mm below its tip."""
    return parse_scene({
        "duration": duration, "solver": {"rtol": 1e-10, "atol": 1e-13},
        "robot": {"urdf": "cylindrical3", "active_joints": ["q3"], "gravity": [0.0, 0.0, 0.0], "q0": [0.999],
                  "v0": [0.5]},
        "contact": {"tip": {"point": [1.0, 0.0, 0.2], "normal": {"direction": [0, 0, 1], **normal}}},
        "controller": {"kind": "task_pd", "kp": 0.0, "kd": 0.0},
    })


def _declared(result) -> set[str]:
    return {gap["reason"] for gap in result.stats["fast_path_gaps"]}


def _assert_only_declared_fallbacks(result) -> None:
    fallbacks = set(result.stats["fallback_modes"])
    assert not any(reason.startswith(UNDECLARED) for reason in fallbacks), fallbacks
    assert fallbacks <= _declared(result)


def test_a_hunt_crossley_stage_declares_its_gap_at_load_and_only_its_touching_modes_fall_back():
    scene = axis_scene(HUNT_CROSSLEY, duration=0.05)  # free flight, then touch
    gaps = System(scene).fast_path_gaps
    assert [g.part for g in gaps] == ["contact.tip.n.env1"]
    r = simulate(scene)
    assert r.events[0]["kind"] == "touch"
    assert r.stats["compiled_modes"] >= 1  # the free flight: the stage carries no force
    assert set(r.stats["fallback_modes"]) == {gaps[0].reason}
    _assert_only_declared_fallbacks(r)


def test_the_energy_audit_is_a_declared_gap_and_motors_and_force_reading_laws_are_not():
    r = simulate("b1", {"solver.record_energy": True, "duration": 0.05})
    assert set(r.stats["fallback_modes"]) == {ENERGY} == _declared(r)
    system = System(load_scene("case3_b_force"))  # DC motor, elastic drive, force_dynamic reading the force
    assert system.fast_path_gaps == []  # all compiled (tests/test_fast_path_drives.py)


def test_a_part_that_claims_to_compile_but_does_not_is_reported_as_undeclared(monkeypatch):
    scene = axis_scene(HUNT_CROSSLEY, duration=0.05)
    honest = simulate(scene)
    monkeypatch.setattr(ChainStage, "fast_path_gap", property(lambda self: ""))
    assert System(scene).fast_path_gaps == []
    r = simulate(scene)
    assert r.stats["fallback_modes"] and all(k.startswith(UNDECLARED) for k in r.stats["fallback_modes"])
    # the readable model still runs those modes (the honest run: on the one pipeline's compiled steps, ~1 ulp apart)
    np.testing.assert_allclose(r["q"], honest["q"], rtol=0, atol=1e-12 * np.abs(honest["q"]).max())
    with pytest.raises(AssertionError):
        _assert_only_declared_fallbacks(r)


def test_a_new_affine_stage_law_is_compiled_by_construction(doubled_law):
    k, b = 5e4, 1500.0  # [N/m], [N·s/m]
    doubled = simulate(axis_scene({"model": "chain", "environment": [{"k": k, "b": b, "law": doubled_law}]}, 0.05))
    linear = simulate(axis_scene({"model": "chain", "environment": [{"k": 2 * k, "b": 2 * b}]}, 0.05))
    assert doubled.stats["fast_path_gaps"] == [] and not doubled.stats["fallback_modes"]
    assert doubled.stats["compiled_modes"] == linear.stats["compiled_modes"] >= 2  # approach, then touching
    np.testing.assert_allclose(doubled["contact.tip.F_n"], linear["contact.tip.F_n"], rtol=0,
                               atol=1e-9 * np.abs(linear["contact.tip.F_n"]).max())


@pytest.mark.parametrize("scene", ["case2_writer5dof", "case2_writer_ur5"])
def test_the_writers_2d_slip_launching_from_rest_runs_on_the_compiled_path(scene):
    """Both writers stick at the start, then break away (a 2-D slide from rest, its direction solved per
    call): up to 0.85 s every mode, the launch included, is compiled."""
    r = simulate(scene, {"duration": 0.85})
    assert [e["kind"] for e in r.events if e["kind"] != "phase"] == ["stick", "slip"]
    assert r.events[-1]["t"] < 0.8  # the launch segment ran for more than 50 ms
    assert r.stats["fallback_modes"] == {} and r.stats["fast_path_gaps"] == []
    assert r.stats["segments_by_method"].get("LSODA") == 1  # the launch segment (contactdyn.hybrid.loop)


def test_a_compiled_launch_from_rest_agrees_with_the_readable_model():
    """cylindrical3 pushed at 45° on a table until it breaks away (test_friction's anisotropic arm): the
    launch direction solved on the plan's KKT system = the readable Newton on System.evaluate."""
    doc = {"name": "cyl", "duration": 0.6, "solver": {"rtol": 1e-10, "atol": 1e-12, "output_rate": 1000.0},
           "robot": {"urdf": "cylindrical3", "q0": [0.0, 0.0, 1.0]},
           "contact": {"table": {"point": [0.0, 0.0, 0.2], "normal": {"direction": [0.0, 0.0, 1.0]},
                                 "tangent": {"model": "friction", "directions": [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]],
                                             "mu_s": 0.5, "mu_k": 0.3}}},
           "controller": {"kind": "task_force", "rate": [500.0 / np.sqrt(2), 500.0 / np.sqrt(2), 0.0]}}
    compiled = run_system(System(parse_scene(doc)))
    readable_system = System(parse_scene(doc))
    readable_system.fast_path_gaps = [READABLE]
    readable = run_system(readable_system)
    assert [e["kind"] for e in compiled.events] == [e["kind"] for e in readable.events] == ["stick", "slip"]
    assert compiled.stats["fallback_modes"] == {} and readable.stats["compiled_modes"] == 0
    assert compiled.stats["segments_by_method"]["LSODA"] == 1  # the launch segment
    for key in ("q", "v", "contact.table.F_f", "contact.table.v_slip"):
        scale = float(np.abs(readable[key]).max())
        np.testing.assert_allclose(compiled[key], readable[key], rtol=0, atol=1e-8 * scale)


@pytest.mark.slow
@pytest.mark.parametrize("path", sorted(sims_dir().glob("*.toml")) + sorted(HARD.glob("*.toml")),
                         ids=lambda p: p.stem)
def test_every_scene_runs_every_mode_on_the_compiled_path(path):
    r = run_system(System(load_scene(path)))
    assert r.stats["fallback_modes"] == {}, r.stats["fallback_modes"]


def test_a_call_writes_phi_in_place_and_phi_at_returns_its_own_array():
    """The call's φ is one buffer rewritten in place; ``phi_at`` hands out copies (a caller keeping one
    is not changed by the next call), and each is the φ of its own state: the call at that state gives
    System.evaluate's ẋ (the pieces written in place, not stale values of an earlier state)."""
    system = System(load_scene("b1", {"duration": 0.05}))
    run_system(system)
    plan = next(p for p in _PLANS[system].values() if p.ok)
    x0, _ = system.initial_state()
    rng = np.random.default_rng(3)
    states = [x0 + 1e-2 * rng.normal(size=system.n) for _ in range(3)]
    phis = [plan.phi_at(0.1, x) for x in states]
    kept = [phi.copy() for phi in phis]
    for x, phi, first in zip(states, phis, kept, strict=True):
        assert np.array_equal(phi, first)  # no later call changed it
        assert np.array_equal(plan.phi_at(0.1, x), phi)
    assert not np.array_equal(phis[0], phis[1])
    for x in states[::-1]:
        want = system.evaluate(0.1, x, plan.modes, plan.phase).xdot
        np.testing.assert_allclose(plan.rhs(0.1, x.copy()), want, rtol=1e-9, atol=1e-9 * np.abs(want).max())


@pytest.mark.parametrize("scene, duration", [("b1", 0.3), ("case2_writer_motors", 1.0)])
def test_a_contact_on_another_frame_than_the_tip_runs_compiled_as_the_readable_model(scene, duration):
    """The contact on link2's frame, the controller on the tip's: φ carries two frames (the second's terms by
    plan_phi.frame_motion after Pinocchio's call, written by write_frame), on the plain plan (B1) and in the
    motors' kernel (writer_motors' task PD through its DC motors); the run is the readable model's."""
    overrides = {"duration": duration, "contact.tip.frame": "link2"}
    compiled_system = System(load_scene(scene, overrides))
    compiled = run_system(compiled_system)
    readable_system = System(load_scene(scene, overrides))
    readable_system.fast_path_gaps = [READABLE]
    readable = run_system(readable_system)
    assert {len(p.fids) for p in _PLANS[compiled_system].values() if p.ok} == {2}
    assert compiled.stats["fallback_modes"] == {} and readable.stats["compiled_modes"] == 0
    assert [e["kind"] for e in compiled.events] == [e["kind"] for e in readable.events]
    for key in ("q", "v", "contact.tip.F_n"):
        scale = 1.0 + float(np.abs(readable[key]).max())
        np.testing.assert_allclose(compiled[key], readable[key], rtol=0, atol=1e-6 * scale)


def test_the_assembly_probed_all_at_once_is_probed_one_by_one():
    """P read off ``_assemble`` with every unit probe as a column of one matrix (plan_probe.affine_map's
    ``columns``) is bitwise P read off one probe at a time, on modes with rows, motors and a folded law."""
    from contactdyn.compiled.plan_probe import affine_map

    checked = 0
    for name in ("b1", "case1_cart", "case3_b_force"):
        system = System(load_scene(name, {"duration": 1.2}))
        run_system(system)
        for plan in (p for p in _PLANS[system].values() if p.ok):
            one_by_one = affine_map(plan._assemble, plan.i_e + plan.ne)
            assert np.array_equal(one_by_one, plan.P)
            checked += 1
    assert checked >= 5


def test_the_self_check_holds_each_rate_to_the_size_of_its_terms_not_of_its_value_at_an_equilibrium():
    """At an equilibrium a law's integral state has a rate of ~1e-7 made of forces of 50 N times a gain of
    400/s: the plan and the readable model differ there by rounding (~1e-9), which a tolerance relative to the
    rate's own value called a disagreement and ran the mode on the readable model. The perturbed state of the
    check shows the terms' size; a law changed on one path only is still caught
    (test_laws.test_a_friction_law_changed_on_the_readable_path_only_is_caught)."""
    from contactdyn.scene.reader import read_toml

    document = read_toml(sims_dir() / "force_loop_real_cell.toml")
    for key in ("sample_rate", "delay"):  # the scene's continuous twin: its law acts at every instant
        document["controller"].pop(key, None)
    r = run_system(System(parse_scene(document, file=str(sims_dir() / "force_loop_real_cell.toml"))))
    assert r.stats["fallback_modes"] == {}
    assert all(row["path"] != "readable model" for row in r.stats["paths"].values())
