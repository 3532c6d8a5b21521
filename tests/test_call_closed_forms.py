"""The one pipeline's call against closed forms computed with Pinocchio alone (no function of the call's own).

The call computes the robot's terms in its own rigid-body table, the tip's frame terms, the law, the contact rows
and one KKT solve. Here each answer is rebuilt from Pinocchio's ``aba``, ``crba``, ``nonLinearEffects``, frame
Jacobian and classical acceleration, and from the law's formula as the docs write it:

- a UR5 in free space under the operational-space law (gravity on, the tool axis held): q̈ = ABA(q, q̇, τ) for the
  call's own command τ, and the task acceleration J_t q̈ + J̇_t q̇ = a* + Λ⁻¹ f (Λ⁻¹ = J_t H⁻¹ J_tᵀ), at random
  states;
- the same arm holding its pencil on a rigid table (stuck: three rigid rows at the point): the contact force solves
  J H⁻¹ Jᵀ f_c = −(J H⁻¹ (τ − h) + J̇q̇), and q̈ = H⁻¹ (τ − h + Jᵀ f_c); the normal force and the friction are f_c's
  components.
"""

from __future__ import annotations

import tomllib

import numpy as np
import pinocchio as pin
import pytest

from contactdyn.hybrid.pipeline_mode import mode_runner
from contactdyn.scene.scene_file import parse_scene, sims_dir
from contactdyn.simulate import prepare


def _writer_doc() -> dict:
    with open(sims_dir() / "case2_writer_ur5.toml", "rb") as fh:
        return tomllib.load(fh)


_LAW = _writer_doc()["controller"]
KP, KD, KO, DO = (float(_LAW[k]) for k in ("kp", "kd", "ko", "do"))  #: [N/m, N·s/m, 1/s², 1/s] the writer's gains


def _free_arm(compiled: bool):
    """The UR5 writer's arm and law without its contact, holding a fixed point x_d 5 cm above the paper: (system, x0,
    the mode's call, x_d [m])."""
    doc = _writer_doc()
    tip0 = doc["robot"]["tip0"]
    x_d = [tip0[0], tip0[1], 0.05]
    del doc["contact"]
    doc["controller"].pop("kd_normal")
    doc["controller"]["axes"] = np.eye(3).tolist()
    doc["phase"] = [{"name": "hold", "reference": {"start": x_d}}]
    doc["duration"] = 0.1
    system, modes, phase, x0 = prepare(parse_scene(doc))
    return system, x0, mode_runner(system, compiled=compiled)(modes, phase), np.array(x_d)


def _tip(robot, q, v):
    """Pinocchio's tip terms at (q, q̇): p [m], ṗ [m/s], R, J (6, nv; linear rows first), J̇q̇ (6), H, h."""
    model, data = robot.model, robot.model.createData()
    fid = model.getFrameId("tool0")
    pin.forwardKinematics(model, data, q, v, np.zeros(model.nv))
    pin.updateFramePlacements(model, data)
    frame = pin.ReferenceFrame.LOCAL_WORLD_ALIGNED
    J = pin.computeFrameJacobian(model, data, q, fid, frame)
    drift = pin.getFrameClassicalAcceleration(model, data, fid, frame)
    velocity = pin.getFrameVelocity(model, data, fid, frame)
    H = pin.crba(model, data, q)
    H = np.triu(H) + np.triu(H, 1).T
    h = pin.nonLinearEffects(model, data, q, v)
    return (data.oMf[fid].translation.copy(), velocity.linear.copy(), data.oMf[fid].rotation.copy(), J.copy(),
            np.concatenate((drift.linear, drift.angular)), H, h)


@pytest.mark.parametrize("compiled", [True, False], ids=["compiled", "interpreted"])
def test_free_space_the_call_is_aba_and_the_task_acceleration_is_the_law_s(compiled):
    system, x0, mode, x_d = _free_arm(compiled)
    robot, nQ, nv = system.robot, system.nQ, system.nv
    target = np.asarray(_LAW["tool_target"], float)
    target /= np.linalg.norm(target)
    rng = np.random.default_rng(11)
    for _ in range(4):
        x = x0.copy()
        x[:nv] += rng.uniform(-0.05, 0.05, nv)  # [rad] around the writing posture (the task regular)
        x[nQ:nQ + nv] = rng.uniform(-0.5, 0.5, nv)  # [rad/s]
        q, v = x[:nv], x[nQ:nQ + nv]
        ev = mode.evaluation(0.0, x)
        qdd = ev.xdot[nQ:nQ + nv]
        np.testing.assert_allclose(ev.tau, ev.tau_cmd, rtol=0, atol=1e-12)  # ideal drives: the command acts
        reference = pin.aba(robot.model, robot.model.createData(), q, v, ev.tau_cmd)
        np.testing.assert_allclose(qdd, reference, rtol=1e-9, atol=1e-9 * np.abs(reference).max())
        p, pdot, R, J, drift, H, h = _tip(robot, q, v)
        a = R[:, 2]  # the pencil, tool0's +z
        E = np.linalg.svd(np.eye(3) - np.outer(a, a))[0][:, :2].T  # an orthonormal basis of a⊥ (rows)
        Jt = np.vstack((J[:3], E @ J[3:]))
        omega = J[3:] @ v
        a_star = np.concatenate((np.zeros(3), E @ (KO * np.cross(a, target) - DO * omega)))
        f = np.concatenate((KP * (x_d - p) - KD * pdot, np.zeros(2)))  # [N] the stiffness, directly
        task = Jt @ qdd + np.concatenate((drift[:3], E @ drift[3:]))
        expected = a_star + Jt @ np.linalg.solve(H, Jt.T) @ f
        np.testing.assert_allclose(task, expected, rtol=0, atol=1e-8 * max(1.0, np.abs(expected).max()))
        np.testing.assert_allclose(ev.x_d, x_d, rtol=0, atol=1e-15)  # [m] the reference the call read


def _rigid_table(compiled: bool):
    """The writer's press on a rigid table, the reference 2.2 mm beside the pencil point: at the start, stuck."""
    doc = _writer_doc()
    tip0 = doc["robot"]["tip0"]
    doc["contact"]["pencil"]["normal"] = {"direction": [0.0, 0.0, 1.0], "model": "rigid"}
    doc["phase"] = [{"name": "hold", "reference": {"start": [tip0[0] + 1e-3, tip0[1] - 2e-3, 0.0]},
                     "force": [{"contact": "pencil", "value": 5.0, "kind": "step"}]}]
    doc["duration"] = 0.1
    system, modes, phase, x0 = prepare(parse_scene(doc))
    return system, modes, x0, mode_runner(system, compiled=compiled)(modes, phase)


@pytest.mark.parametrize("compiled", [True, False], ids=["compiled", "interpreted"])
def test_a_stuck_point_on_a_rigid_table_takes_the_kkt_force_pinocchio_gives(compiled):
    system, modes, x0, mode = _rigid_table(compiled)
    assert modes[0].touching and modes[0].stuck
    robot, nQ, nv = system.robot, system.nQ, system.nv
    rng = np.random.default_rng(5)
    for k in range(3):
        x = x0.copy()
        if k:  # a moving arm whose tip velocity is zero at the point (the rows' velocity terms vanish)
            q, _, _, J, *_ = _tip(robot, x[:nv], np.zeros(nv))
            x[nQ:nQ + nv] = np.linalg.svd(J[:3])[2][3:].T @ rng.uniform(-0.5, 0.5, nv - 3)  # [rad/s] ṗ = 0
        q, v = x[:nv], x[nQ:nQ + nv]
        ev = mode.evaluation(0.0, x)
        _, pdot, _, J, drift, H, h = _tip(robot, q, v)
        assert np.abs(pdot).max() < 1e-12
        Jp = J[:3]
        HinvJT = np.linalg.solve(H, Jp.T)
        f_c = -np.linalg.solve(Jp @ HinvJT, Jp @ np.linalg.solve(H, ev.tau - h) + drift[:3])  # [N] on the tip
        qdd = np.linalg.solve(H, ev.tau - h + Jp.T @ f_c)
        scale = np.abs(f_c).max()
        assert abs(ev.normal_force["pencil"] - f_c[2]) <= 1e-9 * scale  # [N] the normal +z, pressing > 0
        np.testing.assert_allclose(ev.friction["pencil"], f_c[:2], rtol=0, atol=1e-9 * scale)  # tangents x, y
        free = np.linalg.solve(H, ev.tau - h)  # [rad/s²] what the arm would do without the table: the scale
        np.testing.assert_allclose(ev.xdot[nQ:nQ + nv], qdd, rtol=0, atol=1e-9 * np.abs(free).max())
