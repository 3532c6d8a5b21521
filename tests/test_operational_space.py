"""The operational-space law (``operational_space``): closed forms of its decoupling.

In free space the commanded task acceleration is realised exactly (reference acceleration on the
position axes, the tilt's ko (a × d) − do ω⊥) and the null-space motion of a redundant arm decays
as q̈_N = −k_null q̇_N; on a rigid surface at rest the normal force equals the set-point while the
position stiffness pushes sideways against stuck friction; a singular task and a task with more
directions than joints are clear errors.
"""

from __future__ import annotations

import tomllib
from types import SimpleNamespace

import numpy as np
import pytest

from contactdyn import Robot, simulate
from contactdyn.errors import SceneError, SimulationError
from contactdyn.laws.controllers.base import BindContext, ControlInput
from contactdyn.laws.controllers.operational import OperationalSpace, OperationalSpaceConfig
from contactdyn.model.pipeline.pipeline import Pipeline, call
from contactdyn.robot.catalog import TOOL_FRAMES
from contactdyn.scene.scene_file import load_scene, parse_scene, sims_dir
from contactdyn.simulate import prepare

KO, DO, K_NULL = 400.0, 40.0, 10.0  #: [1/s², 1/s, 1/s]
TARGET = np.array([0.18979606, 0.0587108, -0.98006658])  #: the writer's pencil direction
TARGET /= np.linalg.norm(TARGET)


def _law(nv: int, axes=None, forces=(), contacts=None, target=TARGET) -> OperationalSpace:
    cfg = OperationalSpaceConfig(np.array([800.0]), np.array([40.0]), axes, np.array([0.0, 0.0, 1.0]), target,
                                 KO, DO, K_NULL, 0.0)
    law = OperationalSpace(cfg, nv)
    scene = SimpleNamespace(contacts=contacts or {}, file="test.toml")
    law.bind(BindContext(scene, SimpleNamespace(reference=None, forces=forces), 0, [], np.zeros(nv, bool),
                         "controller"))
    return law


def _input(robot: Robot, tip: str, q, v, a_d, force_d=None) -> ControlInput:
    """What the law reads at (q, q̇), with the reference on the tip (zero position error)."""
    robot.update(q, v)
    ft = robot.frame_terms(robot.frame_id(tip))
    return ControlInput(0.0, q, v, robot.H.copy(), robot.h.copy(), None, ft.position, ft.velocity, ft.jacobian,
                        ft.drift, ft.position.copy(), ft.velocity.copy(), a_d, {}, force_d or {},
                        {"pencil": np.array([0.0, 0.0, 1.0])}, np.zeros(0), R_tip=ft.rotation,
                        J_ang=ft.angular_jacobian, drift_ang=ft.angular_drift)


@pytest.mark.parametrize("name, tip", [("ur5", "tool0"), ("panda", "panda_hand_tcp"), ("writer5dof", "tip")])
def test_free_space_the_commanded_task_acceleration_is_realised_exactly(name, tip):
    robot = Robot.load(name, tip=tip)
    rng = np.random.default_rng(7)
    law = _law(robot.nv)
    for _ in range(3):
        q = np.clip(rng.uniform(-1.0, 1.0, robot.nv), robot.lower, robot.upper)
        v = rng.uniform(-1.0, 1.0, robot.nv)  # [rad/s]
        a_d = rng.uniform(-2.0, 2.0, 3)  # [m/s²]
        inp = _input(robot, tip, q, v, a_d)
        tau, _ = law.command(inp)
        qdd = np.linalg.solve(inp.H, tau - inp.h)  # the robot alone
        np.testing.assert_allclose(inp.J @ qdd + inp.drift, a_d, rtol=0, atol=1e-9)  # [m/s²]
        a = inp.R_tip[:, 2]  # the pencil
        omega = inp.J_ang @ v
        alpha = inp.J_ang @ qdd + inp.drift_ang  # [rad/s²]
        perp = np.eye(3) - np.outer(a, a)
        np.testing.assert_allclose(perp @ alpha, perp @ (KO * np.cross(a, TARGET) - DO * omega), rtol=0, atol=1e-8)
        if robot.nv > 5:  # the null space (the roll about the pencil, the Panda's elbow) decays at k_null
            Jt = np.vstack((inp.J, inp.J_ang))
            Jt = np.vstack((Jt[:3], np.linalg.svd(perp)[0][:, :2].T @ Jt[3:]))
            Hinv_JtT = np.linalg.solve(inp.H, Jt.T)
            N = np.eye(robot.nv) - Hinv_JtT @ np.linalg.solve(Jt @ Hinv_JtT, Jt)  # I − J̄ J_t
            np.testing.assert_allclose(N @ qdd, -K_NULL * (N @ v), rtol=0, atol=1e-8)


def test_force_set_point_goes_straight_to_the_normal_while_the_stiffness_pushes_sideways():
    """At rest, with the position error held by a rigid sticking contact: the KKT's contact force is
    exactly −f (the set-point along the normal, the stiffness kp e along the axes), by the closed form
    J_t H⁻¹ J_tᵀ (f + F_c) = 0."""
    robot = Robot.load("ur5", tip="tool0")
    contact = SimpleNamespace(normal=np.array([0.0, 0.0, 1.0]), tangents=np.eye(3)[:2])
    force = SimpleNamespace(contact="pencil", direction="n", key="pencil")
    q = np.array([-0.07, -1.03, 2.67, -3.40, -1.50, -0.36])
    inp = _input(robot, "tool0", q, np.zeros(6), np.zeros(3), {"pencil": (5.0, 0.0)})
    offset = np.array([1e-3, -2e-3, 0.0])  # [m] the reference beside the tip
    inp.x_d = inp.p_tip + offset
    law = _law(6, axes=np.eye(3)[:2], forces=(force,), contacts={"pencil": contact},
               target=inp.R_tip[:, 2].copy())  # the pencil on its target: no tilt command
    tau, _ = law.command(inp)
    J = inp.J
    K = np.block([[inp.H, -J.T], [J, np.zeros((3, 3))]])  # H q̈ = τ − h + Jᵀ F_c, J q̈ + J̇q̇ = 0 (q̇ = 0)
    F_c = np.linalg.solve(K, np.concatenate((tau - inp.h, -inp.drift)))[6:]  # [N] on the tip
    np.testing.assert_allclose(F_c, [-800.0 * offset[0], -800.0 * offset[1], 5.0], rtol=0, atol=1e-9)


def _rigid_writer(controller: dict) -> dict:
    with open(sims_dir() / "case2_writer_ur5.toml", "rb") as fh:
        doc = tomllib.load(fh)
    doc["controller"] = controller
    doc["contact"]["pencil"]["normal"] = {"direction": [0.0, 0.0, 1.0], "model": "rigid"}
    tip0 = doc["robot"]["tip0"]
    doc["phase"] = [{"name": "hold", "reference": {"start": [tip0[0] + 1e-3, tip0[1] - 2e-3, 0.0]},
                     "force": [{"contact": "pencil", "value": 5.0, "kind": "step"}]}]
    doc["duration"] = 0.2
    return doc


def test_on_a_rigid_surface_at_rest_the_normal_force_is_the_set_point():
    """The writer's law on a rigid table, the reference 2.2 mm beside the pencil point: friction
    (μ F = 2 N) holds the stiffness's 1.8 N, nothing moves, and the normal force is 5 N to 1e-9."""
    with open(sims_dir() / "case2_writer_ur5.toml", "rb") as fh:
        controller = tomllib.load(fh)["controller"]
    r = simulate(parse_scene(_rigid_writer(controller), {"solver.output_rate": 100.0}))
    assert controller["kind"] == "operational_space"
    assert np.all(r["contact.pencil.stuck"] == 1.0)
    np.testing.assert_allclose(r["contact.pencil.F_n"], 5.0, rtol=0, atol=1e-9)  # [N]
    F_t = np.linalg.norm(r["contact.pencil.F_f"], axis=1)
    np.testing.assert_allclose(F_t, controller["kp"] * np.hypot(1e-3, 2e-3), rtol=1e-6)  # [N] kp |e|


@pytest.mark.parametrize("robot", ["panda", "ur5"])
def test_the_compiled_right_hand_side_calls_the_same_law(robot):
    """The writing scene's first mode runs on the one pipeline, and its compiled call equals the interpreted call's
    (run_agreement.interpreted_evaluate; 1e-10 relative; measured 0) along 20 ms of the run, every call answered
    (no failed call): one law, two paths."""
    from run_agreement import interpreted_evaluate
    from scipy.integrate import solve_ivp

    scene = load_scene("case2_writer_ur5", {"robot.urdf": robot, "robot.tip": TOOL_FRAMES[robot]})
    system, modes, phase, x0 = prepare(scene)
    pipe = Pipeline(system, modes, phase)
    sol = solve_ivp(pipe.rhs, (0.0, 0.02), x0, method="DOP853", rtol=1e-8, atol=1e-10)
    assert len(sol.t) >= 3
    for t, x in zip(sol.t, sol.y.T, strict=True):
        ref = interpreted_evaluate(system, t, x, modes, phase).xdot
        np.testing.assert_allclose(pipe.rhs(t, x), ref, rtol=1e-10, atol=1e-10 * np.abs(ref).max())
    assert pipe.failed_calls == 0


def test_a_singular_task_is_a_clear_error():
    robot = Robot.load("ur5", tip="tool0")
    law = _law(6)
    q = np.array([0.0, -1.2, 0.0, -1.0, 1.2, 0.0])  # elbow straight: the tip cannot move along the upper arm
    with pytest.raises(SimulationError, match=r"t = 0 s: operational_space: the task .* is singular at this posture"):
        law.command(_input(robot, "tool0", q, np.zeros(6), np.zeros(3)))


def test_the_compiled_call_declines_a_singular_task_and_the_law_raises_there():
    """The writer's pipeline call at the straight-elbow posture (the task singular) has no answer (status 0), and the
    mode's right-hand side raises the law's own error (its time, the singular task) instead of a torque through a
    near-singular Λ, compiled or interpreted: no other model answers for it."""
    from contactdyn.hybrid.pipeline_mode import mode_runner

    system, modes, phase, x0 = prepare(load_scene("case2_writer_ur5"))
    pipe = Pipeline(system, modes, phase)
    x = x0.copy()
    x[:6] = [0.0, -1.2, 0.0, -1.0, 1.2, 0.0]  # [rad] elbow straight (test_a_singular_task_is_a_clear_error)
    p = pipe.packed
    call(0.1, x.copy(), p.ints, p.reals, p.work, p.events)
    assert p.events[-1] == 0.0
    call(0.1, x0.copy(), p.ints, p.reals, p.work, p.events)
    assert p.events[-1] == 1.0  # (at the scene's own posture it answers)
    singular = r"t = 0\.1 s: operational_space: the task \(position axes, force directions.*\) is singular at this"
    with pytest.raises(SimulationError, match=singular):
        pipe.rhs(0.1, x)
    interpreted = mode_runner(system, compiled=False)(modes, phase)
    assert interpreted.interpreted
    with pytest.raises(SimulationError, match=singular):
        interpreted.rhs(0.1, x.copy())
    assert np.all(np.isfinite(interpreted.rhs(0.1, x0.copy())))  # (at the scene's own posture it answers)


def test_more_task_directions_than_joints_is_a_scene_error():
    with pytest.raises(SceneError, match=r"controller: expected a task of at most 4 directions \(the arm's joints\): "
                                         r"3 position axes, 0 force directions, 2 tool tilts, found 5"):
        _law(4)


def test_the_compiled_law_is_the_module_formula():
    """operational_law.torque (run by the law's command and the pipeline's call) against the formula in numpy:
    τ = J_tᵀ (Λ (a* − J̇_t q̇ + k_null J_t q̇) + f) − k_null H q̇ + h, on random inputs of a 7-joint arm, to 1e-10."""
    from contactdyn.laws.controllers import operational_law

    rng = np.random.default_rng(7)
    nv = 7
    for _ in range(20):
        B = rng.normal(size=(nv, nv))
        H, h, v = B @ B.T + nv * np.eye(nv), rng.normal(size=nv), rng.normal(size=nv)
        J6, drift6 = rng.normal(size=(6, nv)), rng.normal(size=6)
        p, pd, x_d, v_d, a_d = rng.normal(size=(5, 3))
        R = np.linalg.qr(rng.normal(size=(3, 3)))[0]
        axes, forced = np.eye(3)[:2], np.eye(3)[2:]
        kp, kd, F_d = np.array([800.0, 500.0]), np.array([40.0, 30.0]), np.array([5.0])
        tool, target, kd_n = np.array([0.0, 0.0, 1.0]), TARGET, 200.0
        tau, ratio = operational_law.torque(v, H, h, J6, drift6, p, pd, x_d, v_d, a_d, F_d, R, axes, forced, kp, kd,
                                            tool, target, KO, DO, K_NULL, kd_n)
        a = R @ tool
        e1, e2 = operational_law.perpendicular(a)
        assert np.allclose([e1 @ a, e2 @ a, e1 @ e2, e1 @ e1, e2 @ e2], [0, 0, 0, 1, 1], atol=1e-15)
        W = np.zeros((5, 6))
        W[:3, :3] = np.vstack((axes, forced))
        W[3:, 3:] = e1, e2
        a_task = np.concatenate((axes @ a_d, [0.0], W[3:, 3:] @ (KO * np.cross(a, target) - DO * J6[3:] @ v)))
        f = np.concatenate((kp * (axes @ (x_d - p)) + kd * (axes @ (v_d - pd)), -F_d - kd_n * (forced @ pd), [0, 0]))
        Jt = W @ J6
        L_inv = Jt @ np.linalg.solve(H, Jt.T)
        ref = Jt.T @ (np.linalg.solve(L_inv, a_task - W @ drift6 + K_NULL * Jt @ v) + f) - K_NULL * H @ v + h
        assert np.allclose(tau, ref, rtol=1e-10, atol=1e-10 * np.abs(ref).max())
        assert ratio == pytest.approx(np.linalg.det(L_inv) / np.prod(np.diag(L_inv)), rel=1e-10)


def test_the_hadamard_ratio_is_det_over_the_diagonal_and_zero_when_singular():
    from contactdyn.laws.controllers.operational_law import hadamard_ratio

    rng = np.random.default_rng(2)
    for n in (1, 2, 5):
        B = rng.normal(size=(n, n))
        S = B @ B.T + 1e-3 * np.eye(n)
        assert hadamard_ratio(S) == pytest.approx(np.linalg.det(S) / np.prod(np.diag(S)), rel=1e-10)
    assert hadamard_ratio(np.array([[1.0, 2.0], [2.0, 4.0]])) == 0.0  # rank 1
    assert np.isnan(hadamard_ratio(np.array([[np.nan, 0.0], [0.0, 1.0]])))
