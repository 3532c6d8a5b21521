"""Which path runs each mode (contactdyn.model.paths): the one pipeline's compiled call for every mode of every scene
(a mode it cannot pack stops the run with the pipeline's own reason, pack.unsupported: tests/test_rigid_body.py),
a law numba cannot compile a declared Python stage in it."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from contactdyn import parse_scene, simulate
from contactdyn.model.paths import INTERPRETED, PIPELINE
from contactdyn.model.system import System
from contactdyn.scene.scene_file import load_scene, sims_dir
from contactdyn.simulate import run_system

HARD = Path(__file__).resolve().parent.parent / "benchmarks" / "hard"
PYTHON_STAGE_CONTROLLER = "controller 'uncompilable_ctl' is a Python stage (numba cannot compile"


def axis_scene(normal: dict, duration: float):
    """The cylindrical robot's vertical axis (1 DOF) falling at 0.5 m/s onto a surface 1 mm below its tip."""
    return parse_scene({
        "duration": duration, "solver": {"rtol": 1e-10, "atol": 1e-13},
        "robot": {"urdf": "cylindrical3", "active_joints": ["q3"], "gravity": [0.0, 0.0, 0.0], "q0": [0.999],
                  "v0": [0.5]},
        "contact": {"tip": {"point": [1.0, 0.0, 0.2], "normal": {"direction": [0, 0, 1], **normal}}},
        "controller": {"kind": "task_pd", "kp": 0.0, "kd": 0.0},
    })


def _paths(result) -> set[str]:
    return {row["path"] for row in result.stats["paths"].values()}


def _all_compiled(result) -> None:
    assert _paths(result) == {PIPELINE}, result.stats["paths"]


@pytest.mark.parametrize("path", sorted(sims_dir().glob("*.toml")) + sorted(HARD.glob("*.toml")),
                         ids=lambda p: p.stem)
def test_every_scene_runs_every_mode_on_the_pipeline(path):
    """Every shipped scene, full length (≤ 3.6 s each, ~15 s for all 22 on this machine once compiled)."""
    _all_compiled(run_system(System(load_scene(path))))


def test_a_controller_numba_cannot_compile_keeps_its_modes_on_the_compiled_call(uncompilable_controller):
    """A controller numba cannot compile is a declared Python stage of the compiled call
    (tests/test_python_controller): every mode on the compiled call, each naming the controller and numba's
    reason."""
    r = simulate(parse_scene({
        "duration": 0.05, "robot": {"urdf": "cylindrical3", "active_joints": ["q3"], "q0": [0.999], "v0": [0.5]},
        "contact": {"tip": {"point": [1.0, 0.0, 0.2], "normal": {"direction": [0, 0, 1], "model": "chain",
                                                                  "environment": [{"k": 5e4, "b": 1500.0}]}}},
        "controller": {"kind": uncompilable_controller.name}}))
    assert {row["path"] for row in r.stats["paths"].values()} == {PIPELINE}
    assert all(row["why"].startswith(PYTHON_STAGE_CONTROLLER) for row in r.stats["paths"].values())


def test_a_stage_law_numba_cannot_compile_keeps_its_mode_on_the_compiled_call(uncompilable_law):
    """A stage law numba cannot compile is a declared Python stage of the compiled call (tests/test_python_stages):
    every mode on the compiled call, the touching one naming the law."""
    r = simulate(axis_scene({"model": "chain", "environment": [{"k": 5e4, "b": 1500.0, "law": uncompilable_law.name}]},
                            0.05))
    assert r.stats["paths"]["main: tip touching"]["path"] == PIPELINE
    why = r.stats["paths"]["main: tip touching"]["why"]
    assert why.startswith("stage law 'uncompilable' of tip.n is a Python stage"), why
    assert r.stats["paths"]["main: tip free"] == {"path": PIPELINE, "why": "", "segments": 1}


def test_the_energy_audit_through_motors_runs_on_the_compiled_call_and_agrees_with_the_interpreted_run():
    """The DC-motor writer with the energy audit: the drives' own power and the motors' losses (as each kind's law
    gives them) in the audit's rates on the compiled call; the work and dissipated energy the interpreted run's (the
    same call as its Python twins, ``compiled=False``) to 1e-9 of their largest value, the audit closing."""
    settings = {"solver.record_energy": True, "duration": 0.3}
    fast = simulate("case2_writer_motors", settings)
    _all_compiled(fast)
    interpreted = simulate("case2_writer_motors", settings, compiled=False)
    assert _paths(interpreted) == {INTERPRETED}
    for key in ("energy.work", "energy.dissipated", "q", "contact.tip.F_n"):
        ref = np.asarray(interpreted[key], float)
        np.testing.assert_allclose(fast[key], ref, rtol=0, atol=1e-9 * np.abs(ref).max(), err_msg=key)
    assert np.abs(fast["energy.work"]).max() > 0.0
    assert fast.meta["check_warnings"] == []


def test_a_new_affine_stage_law_runs_on_the_pipeline_by_its_address(doubled_law):
    """A stage law registered by the test (F = 2k x + 2b ẋ) is compiled to its address: the run is on the pipeline,
    and it is the run of the linear law at (2k, 2b) (to 1e-9 of the force; measured bitwise equal)."""
    k, b = 5e4, 1500.0  # [N/m], [N·s/m]
    doubled = simulate(axis_scene({"model": "chain", "environment": [{"k": k, "b": b, "law": doubled_law}]}, 0.05))
    linear = simulate(axis_scene({"model": "chain", "environment": [{"k": 2 * k, "b": 2 * b}]}, 0.05))
    _all_compiled(doubled)
    assert doubled.stats["compiled_modes"] == linear.stats["compiled_modes"] >= 2  # approach, then touching
    np.testing.assert_allclose(doubled["contact.tip.F_n"], linear["contact.tip.F_n"], rtol=0,
                               atol=1e-9 * np.abs(linear["contact.tip.F_n"]).max())


@pytest.mark.parametrize("scene", ["case2_writer5dof", "case2_writer_ur5"])
def test_the_writers_2d_slip_launching_from_rest_runs_on_the_pipeline(scene):
    """Both writers stick at the start, then break away (a 2-D slide from rest, its direction solved per call):
    up to 0.85 s every mode, the launch included, is on the pipeline."""
    r = simulate(scene, {"duration": 0.85})
    assert [e["kind"] for e in r.events if e["kind"] != "phase"] == ["stick", "slip"]
    assert r.events[-1]["t"] < 0.8  # the launch segment ran for more than 50 ms
    _all_compiled(r)
    assert r.stats["segments_by_method"].get("LSODA") == 1  # the launch segment (contactdyn.hybrid.loop)
