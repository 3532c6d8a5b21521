"""task_pd's orientation holds (the tool axis, the full orientation): the law's closed forms, the one pipeline's call
compiled and interpreted alike, and benchmark B2 on the pipeline."""

from __future__ import annotations

import tomllib
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest
from run_agreement import interpreted_evaluate
from scipy.integrate import solve_ivp

from contactdyn.errors import SceneError
from contactdyn.hybrid.loop import HybridRun
from contactdyn.laws.controllers import task_pd_law
from contactdyn.model.paths import PIPELINE
from contactdyn.model.pipeline.pipeline import Pipeline
from contactdyn.model.system import System
from contactdyn.robot.robot import Robot
from contactdyn.scene.scene_file import parse_scene
from contactdyn.simulate import prepare, run_system

B2 = Path(__file__).resolve().parent.parent / "benchmarks" / "b2.toml"  #: /work/shared/bench/B2.md's scene
R_DOWN = [[1.0, 0.0, 0.0], [0.0, -1.0, 0.0], [0.0, 0.0, -1.0]]  #: B2's tool0: x along x, the tool axis down


def _b2(**controller) -> dict:
    """B2's scene document, its controller's keys changed (a value None: the key removed)."""
    with open(B2, "rb") as fh:
        doc = tomllib.load(fh)
    for key, value in controller.items():
        if value is None:
            doc["controller"].pop(key, None)
        else:
            doc["controller"][key] = value
    return doc


B2_FULL = {"tool_axis": None, "tool_target": None, "orientation": R_DOWN}  #: B2 with the full orientation held


def _rotation(rng) -> np.ndarray:
    return pin.exp3(rng.normal(size=3))


def test_the_orientation_error_is_minus_sin_theta_about_the_error_axis():
    """R = exp(θ [k]ₓ) R_d: e_R = −sin θ k (to rounding) and, at rest, the moment is K_o θ back about k to O(θ³)."""
    rng = np.random.default_rng(1)
    ko, do = 50.0, 2.0  # [N·m/rad], [N·m·s/rad]
    for theta in (1e-3, 0.3, 2.0):  # [rad]
        k = rng.normal(size=3)
        k /= np.linalg.norm(k)
        R_d = _rotation(rng)
        R = pin.exp3(theta * k) @ R_d
        np.testing.assert_allclose(task_pd_law.orientation_error(R, R_d), -np.sin(theta) * k, rtol=0, atol=1e-15)
        m = task_pd_law.moment(R, np.zeros(3), np.empty(0), np.empty(0), R_d, ko, do)
        np.testing.assert_allclose(m, -ko * np.sin(theta) * k, rtol=0, atol=1e-13)
    m = task_pd_law.moment(pin.exp3(1e-3 * k) @ R_d, np.zeros(3), np.empty(0), np.empty(0), R_d, ko, do)
    np.testing.assert_allclose(m, -ko * 1e-3 * k, rtol=2e-7)  # K_o θ [N·m]: sin θ = θ (1 − θ²/6)


def test_the_orientation_moment_damps_the_whole_angular_velocity_and_the_tool_axis_moment_not_its_roll():
    rng = np.random.default_rng(2)
    R, R_d, omega = _rotation(rng), _rotation(rng), rng.normal(size=3)  # [rad/s]
    ko, do = 50.0, 2.0
    full = task_pd_law.moment(R, omega, np.empty(0), np.empty(0), R_d, ko, do)
    e = 0.5 * sum(np.cross(R[:, c], R_d[:, c]) for c in range(3))
    np.testing.assert_allclose(full, ko * e - do * omega, rtol=1e-14, atol=1e-14)
    skew = R_d @ R.T - R @ R_d.T  # ½ vee(R_d Rᵀ − R R_dᵀ): the same error
    np.testing.assert_allclose(e, 0.5 * np.array([skew[2, 1], skew[0, 2], skew[1, 0]]), rtol=1e-14, atol=1e-15)
    tool, target = np.array([0.0, 0.0, 1.0]), np.array([0.0, 0.6, -0.8])
    a = R @ tool
    axis = task_pd_law.moment(R, omega, tool, target, np.empty((0, 3)), ko, do)
    np.testing.assert_allclose(axis, ko * np.cross(a, target) - do * (omega - (omega @ a) * a), rtol=1e-14,
                               atol=1e-14)


def test_the_compiled_law_is_the_module_formula():
    """task_pd_law.torque against its docstring's formula in numpy, on random inputs of a 6-joint arm."""
    rng = np.random.default_rng(3)
    nv = 6
    v, J, J_ang = rng.normal(size=nv), rng.normal(size=(3, nv)), rng.normal(size=(3, nv))
    p, pd, x_d, v_d = (rng.normal(size=3) for _ in range(4))
    axes = np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])
    kp, kd = np.array([2000.0, 1500.0]), np.array([100.0, 80.0])
    forced, F_d = np.array([[0.0, 0.0, 1.0]]), np.array([40.0])
    R, R_d, ff = _rotation(rng), _rotation(rng), rng.normal(size=nv)
    ko, do, kd_joint, kd_normal = 50.0, 2.0, 1.0, 30.0
    tau = task_pd_law.torque(v, J, J_ang, p, pd, x_d, v_d, F_d, R, axes, forced, kp, kd, np.empty(0), np.empty(0),
                             R_d, ko, do, kd_joint, kd_normal, ff)
    f = sum(a * (kp[i] * a @ (x_d - p) + kd[i] * a @ (v_d - pd)) for i, a in enumerate(axes))
    f = f - (F_d[0] + kd_normal * forced[0] @ pd) * forced[0]
    e = 0.5 * sum(np.cross(R[:, c], R_d[:, c]) for c in range(3))
    expected = J.T @ f + J_ang.T @ (ko * e - do * J_ang @ v) - kd_joint * v + ff
    np.testing.assert_allclose(tau, expected, rtol=1e-12, atol=1e-12 * np.abs(expected).max())


def test_an_orientation_is_a_rotation_and_not_with_a_tool_axis():
    with pytest.raises(SceneError, match="controller.orientation: expected a rotation matrix"):
        parse_scene(_b2(**B2_FULL | {"orientation": [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, -1.0]]}))
    with pytest.raises(SceneError, match="controller.orientation: expected a rotation matrix: 3 rows"):
        parse_scene(_b2(**B2_FULL | {"orientation": [[1.0, 0.0, 0.0]]}))
    with pytest.raises(SceneError, match="controller.orientation: expected either orientation"):
        parse_scene(_b2(orientation=R_DOWN))


@pytest.mark.parametrize("what", ["tool axis (B2)", "full orientation"])
def test_the_compiled_call_is_the_interpreted_call(what):
    """B2's first mode (the tool sliding on the table, bonded, 2-D friction) on the one pipeline with the task PD law
    in its call: along 10 ms of the run its compiled ẋ is the interpreted call's (run_agreement.interpreted_evaluate:
    the same functions run as Python) to 1e-10 relative (measured 0), no call without an answer."""
    system, modes, phase, x0 = prepare(parse_scene(_b2(**(B2_FULL if "full" in what else {}))))
    pipe = Pipeline(system, modes, phase)
    sol = solve_ivp(pipe.rhs, (0.0, 0.01), x0, method="DOP853", rtol=1e-8, atol=1e-10)
    assert len(sol.t) >= 3
    for t, x in zip(sol.t[:40], sol.y.T[:40], strict=True):
        ref = interpreted_evaluate(system, t, x, modes, phase).xdot
        np.testing.assert_allclose(pipe.rhs(t, x), ref, rtol=1e-10, atol=1e-10 * np.abs(ref).max())
    assert pipe.failed_calls == 0


@pytest.mark.parametrize("what", ["tool axis (B2)", "full orientation"])
def test_b2_runs_on_the_compiled_call(what):
    """B2 (0.2 s of it): every mode on the one pipeline's compiled call, no call solved by least squares or without
    an answer."""
    run = HybridRun(System(parse_scene(_b2(**(B2_FULL if "full" in what else {})), {"duration": 0.2})))
    result = run.run(0.0)
    assert {row["path"] for row in result.stats["paths"].values()} == {PIPELINE}
    assert run.pipelines.pipes and all(mode.singular == 0 for mode in run.pipelines.pipes.values())
    assert np.all(result["contact.tool.F_n"][20:] > 10.0)  # [N] pressing throughout


def test_a_free_arm_without_gravity_settles_to_the_commanded_orientation():
    """A UR5 without gravity or contact, the tip held at its start position and at an orientation 0.3 rad away from
    its start (about a skew axis): the energy-based moment and its damping turn it there (2.5e-5 rad left after
    3 s, from 0.3 rad), on the one pipeline."""
    q0 = [0.1004, -1.3488, 2.3093, -2.5313, -1.5708, -1.4704]  # [rad] B2's start
    robot = Robot.load("ur5", tip="tool0")
    start = robot.frame_placement(np.array(q0), "tool0")
    k = np.array([1.0, 2.0, -0.5]) / np.linalg.norm([1.0, 2.0, -0.5])
    R_d = pin.exp3(0.3 * k) @ start.rotation
    doc = {"name": "free_orientation", "duration": 3.0,
           "solver": {"method": "DOP853C", "rtol": 1e-9, "atol": 1e-11, "output_rate": 100.0},
           "robot": {"urdf": "ur5", "tip": "tool0", "gravity": [0.0, 0.0, 0.0], "q0": q0},
           "controller": {"kind": "task_pd", "kp": 2000.0, "kd": 100.0, "orientation": R_d.tolist(), "ko": 50.0,
                          "do": 2.0},
           "phase": [{"name": "hold", "reference": {"start": start.translation.tolist()}}]}
    result = run_system(System(parse_scene(doc)))
    assert {row["path"] for row in result.stats["paths"].values()} == {PIPELINE}
    angle = [np.linalg.norm(pin.log3(R_d.T @ robot.frame_placement(q, "tool0").rotation)) for q in result["q"]]
    assert angle[0] == pytest.approx(0.3, abs=1e-12)
    assert angle[-1] < 1e-4  # [rad]
    assert max(angle[200:]) < 1e-3  # after 2 s
    assert np.linalg.norm(result["tip"][-1] - start.translation) < 1e-5  # [m]


def test_task_pd_with_a_joint_space_reference_is_a_scene_error():
    doc = _b2()
    doc["phase"][0]["reference"] = {"space": "joint", "start": [0.0] * 6}
    with pytest.raises(SceneError, match=r"phase\[0\].reference.space: expected 'task' \(task_pd tracks the tip\)"):
        System(parse_scene(doc))
