"""The robot's terms computed in the one call (contactdyn.robot.rigid_body) against Pinocchio's computeAllTerms."""

from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest

from contactdyn.robot.catalog import example_robots
from contactdyn.robot.rigid_body import forest_table, rigid_table, rigid_terms
from contactdyn.robot.robot import Robot

URDF = Path(__file__).resolve().parent.parent / "urdf"


def _tree() -> pin.Model:
    """A branched tree of every joint kind the table takes: aligned and unaligned revolute and prismatic joints,
    two branches off the second joint, a rotated placement, bodies with off-axis centres and full inertias."""
    model = pin.Model()
    rng = np.random.default_rng(3)
    joints = [pin.JointModelRZ(), pin.JointModelPY(), pin.JointModelRevoluteUnaligned(np.array([0.6, 0.0, 0.8])),
              pin.JointModelPrismaticUnaligned(np.array([0.0, 0.6, 0.8])), pin.JointModelRX()]
    parents = [0, 1, 2, 2, 4]
    for k, (joint, parent) in enumerate(zip(joints, parents, strict=True)):
        placement = pin.SE3(pin.rpy.rpyToMatrix(*rng.uniform(-1, 1, 3)), rng.uniform(-0.3, 0.3, 3))
        jid = model.addJoint(parent, joint, placement, f"j{k}")
        A = rng.normal(size=(3, 3))
        model.appendBodyToJoint(jid, pin.Inertia(rng.uniform(0.2, 2.0), rng.uniform(-0.1, 0.1, 3),
                                                 A @ A.T + 0.1 * np.eye(3)), pin.SE3.Identity())
    model.armature = np.array([0.0, 0.01, 0.0, 0.2, 0.05])
    return model


def _models():
    for path in sorted(URDF.glob("*.urdf")):
        yield path.stem, pin.buildModelFromUrdf(str(path))
    yield "manipulator", pin.buildSampleModelManipulator()
    yield "tree", _tree()
    robots = example_robots()
    for name in ("ur5", "panda"):
        if name in robots:
            yield name, pin.buildModelFromUrdf(str(robots[name]))


@pytest.mark.parametrize("name,model", list(_models()), ids=lambda v: v if isinstance(v, str) else "")
def test_rigid_terms_are_pinocchios(name, model):
    """M, nle, g, the joint Jacobians and each joint's placement, v and a at q̈ = 0 as computeAllTerms's, to
    rounding, at random states (the gravity turned off its axis, so every component enters)."""
    model.gravity = pin.Motion(np.array([1.3, -2.1, -9.5, 0.0, 0.0, 0.0]))
    data, ref = model.createData(), model.createData()
    table = rigid_table(model)
    assert table is not None
    nv, nj = model.nv, model.njoints
    M, nle, g, J = np.zeros((nv, nv)), np.zeros(nv), np.zeros(nv), np.zeros((6, nv))
    rng = np.random.default_rng(nv)
    for _ in range(3):
        q = rng.uniform(-2.0, 2.0, nv)
        v = 3.0 * rng.normal(size=nv)
        pin.computeAllTerms(model, ref, q, v)
        pin.computeGeneralizedGravity(model, data, q)
        scale = 1.0 + np.abs(ref.M).max() + np.abs(ref.nle).max()
        for j0 in range(1, nj):
            R, p, vj, aj = np.zeros((3, 3)), np.zeros(3), np.zeros(6), np.zeros(6)
            rigid_terms(q, v, table, j0, M, nle, g, R, p, vj, aj, J)
            assert np.abs(R - ref.oMi[j0].rotation).max() < 1e-14
            assert np.abs(p - ref.oMi[j0].translation).max() < 1e-14 * (1.0 + np.abs(p).max())
            assert np.abs(vj - ref.v[j0].vector).max() < 1e-13 * (1.0 + np.abs(vj).max())
            assert np.abs(aj - ref.a[j0].vector).max() < 1e-13 * (1.0 + np.abs(aj).max())
        assert np.abs(M - ref.M).max() < 1e-13 * scale, name
        assert np.abs(nle - ref.nle).max() < 1e-13 * scale, name
        assert np.abs(g - data.g).max() < 1e-13 * scale, name
        assert np.abs(J - np.asarray(ref.J).reshape(6, nv)).max() < 1e-13 * (1.0 + np.abs(J).max()), name


def test_what_rigid_terms_does_not_compute_is_left_to_pinocchio():
    """A free-flyer, a spherical joint, an unbounded revolute joint (q = (cos, sin)): no table."""
    assert rigid_table(pin.buildSampleModelHumanoid()) is None
    model = pin.Model()
    model.addJoint(0, pin.JointModelRUBZ(), pin.SE3.Identity(), "wheel")
    assert rigid_table(model) is None
    model = pin.Model()
    jid = model.addJoint(0, pin.JointModelRZ(), pin.SE3.Identity(), "a")
    model.addJoint(jid, pin.JointModelSpherical(), pin.SE3.Identity(), "b")
    assert rigid_table(model) is None
    assert rigid_table(pin.Model()) is None  # no joint at all


def test_a_robot_without_a_table_stops_the_run_with_the_reason(monkeypatch):
    """With the table withheld (as for a free-flyer), the one pipeline cannot pack the robot (the call computes its
    terms from the table, there is no other model to run it on): the run stops where its first mode starts, naming
    the mode and the reason, compiled and interpreted alike."""
    from contactdyn.errors import SimulationError
    from contactdyn.simulate import simulate

    monkeypatch.setattr(Robot, "rigid_table", property(lambda robot: None))
    for compiled in (True, False):
        with pytest.raises(SimulationError, match=r"case2_writer5dof: the model cannot run phase .*: a robot "
                                                  r"rigid_body does not compute"):
            simulate("case2_writer5dof", {"duration": 0.8}, compiled=compiled)


def test_a_forest_of_two_trees_gives_each_tree_s_terms_side_by_side():
    """The branched tree as the robot and a manipulator as an articulated body whose coordinates start at 7 in Q
    (two coordinates between, a translating body's: their columns zero): H block-diagonal with each model's CRBA, h
    each one's RNEA at q̈ = 0, the Jacobians' columns each one's (Pinocchio's, to 1e-12)."""
    robot, body = _tree(), pin.buildSampleModelManipulator()
    table, starts = forest_table(rigid_table(robot), [(rigid_table(body), robot.nv + 2)])
    assert starts == [robot.njoints]
    n = robot.nv + 2 + body.nv
    rng = np.random.default_rng(5)
    q, v = rng.uniform(-1, 1, n), rng.uniform(-1, 1, n)
    M, nle, g, J = np.zeros((n, n)), np.zeros(n), np.zeros(n), np.zeros((6, n))
    rigid_terms(q, v, table, 1, M, nle, g, np.zeros((3, 3)), np.zeros(3), np.zeros(6), np.zeros(6), J)
    cols = (np.arange(robot.nv), np.arange(robot.nv + 2, n))
    want = np.zeros((n, n))
    for model, c in zip((robot, body), cols, strict=True):
        data = model.createData()
        pin.computeAllTerms(model, data, q[c], v[c])
        want[np.ix_(c, c)] = pin.crba(model, data, q[c])  # (the armature on its diagonal)
        np.testing.assert_allclose(nle[c], pin.nonLinearEffects(model, data, q[c], v[c]), rtol=0, atol=1e-12)
        np.testing.assert_allclose(g[c], pin.computeGeneralizedGravity(model, data, q[c]), rtol=0, atol=1e-12)
        pin.computeJointJacobians(model, data, q[c])
        np.testing.assert_allclose(J[:, c], data.J, rtol=0, atol=1e-12)
    want = np.triu(want) + np.triu(want, 1).T
    np.testing.assert_allclose(M, want, rtol=0, atol=1e-12)
    assert not nle[robot.nv:robot.nv + 2].any() and not J[:, robot.nv:robot.nv + 2].any()
