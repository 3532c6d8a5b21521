"""A frame's motion from its joint's (contactdyn.robot.rigid_body.frame_motion_into, the one pipeline's frame terms)
against Pinocchio's own frame calls."""

from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest

from contactdyn.robot.rigid_body import frame_motion_into

URDF = Path(__file__).resolve().parent.parent / "urdf"
LWA = pin.ReferenceFrame.LOCAL_WORLD_ALIGNED


def _models():
    """Our robots (revolute and prismatic chains, 1 to 5 DOF), Pinocchio's sample manipulator, and its branched
    humanoid on a free-flyer (frames whose joints do not move the others: the support columns)."""
    for path in sorted(URDF.glob("*.urdf")):
        yield path.stem, pin.buildModelFromUrdf(str(path))
    yield "manipulator", pin.buildSampleModelManipulator()
    yield "humanoid", pin.buildSampleModelHumanoid()


def _constants(model, fid: int) -> tuple[np.ndarray, np.ndarray]:
    """(frame, support) as the pipeline packs them: [r [m], the frame's rotation by rows] in its joint's frame, and
    the velocity columns of the joints that move it."""
    frame = model.frames[fid]
    support = [k for jj in model.supports[frame.parentJoint][1:]
               for k in range(model.joints[jj].idx_v, model.joints[jj].idx_v + model.joints[jj].nv)]
    return (np.concatenate([frame.placement.translation, frame.placement.rotation.ravel()]),
            np.array(support, dtype=np.int64))


@pytest.mark.parametrize("name,model", list(_models()), ids=lambda v: v if isinstance(v, str) else "")
def test_frame_motion_is_pinocchios_frame_jacobian_acceleration_and_placement(name, model):
    """Every frame, one more at a rotated offset on the last joint and one fixed in the world: J (6 rows), J̇q̇ at
    q̈ = 0 (classical: linear, angular), p and R in LOCAL_WORLD_ALIGNED as Pinocchio's to 1e-13, at random states,
    from the joint's placement and motion (Pinocchio's computeAllTerms here; rigid_body's in the pipeline,
    tests/test_rigid_body.py)."""
    offset = pin.SE3(pin.rpy.rpyToMatrix(0.3, -0.7, 1.1), np.array([0.05, -0.2, 0.13]))
    model.addFrame(pin.Frame("offset", model.njoints - 1, offset, pin.FrameType.OP_FRAME))
    model.addFrame(pin.Frame("fixed", 0, offset, pin.FrameType.OP_FRAME))
    data = model.createData()
    rng = np.random.default_rng(len(name))
    nv = model.nv
    for _ in range(3):
        lo, hi = np.clip(model.lowerPositionLimit, -3.0, 3.0), np.clip(model.upperPositionLimit, -3.0, 3.0)
        q = pin.normalize(model, rng.uniform(lo, hi))
        v = rng.normal(size=nv)
        pin.computeAllTerms(model, data, q, v)
        Jw = np.array(data.J).reshape(6, nv)
        for fid in range(model.nframes):
            j = model.frames[fid].parentJoint
            J6, a6, p, R = np.zeros((6, nv)), np.zeros(6), np.zeros(3), np.zeros((3, 3))
            frame_motion_into(np.array(data.oMi[j].rotation), np.array(data.oMi[j].translation),
                              np.array(data.v[j].vector), np.array(data.a[j].vector), Jw, *_constants(model, fid),
                              J6, a6, p, R)
            pin.updateFramePlacement(model, data, fid)
            J_ref = pin.getFrameJacobian(model, data, fid, LWA).reshape(6, nv)
            a_ref = pin.getFrameClassicalAcceleration(model, data, fid, LWA).vector
            scale = 1.0 + np.abs(J_ref).max() + np.abs(a_ref).max()
            where = (name, model.frames[fid].name)
            assert np.abs(J6 - J_ref).max() < 1e-13 * scale, where
            assert np.abs(a6 - a_ref).max() < 1e-13 * scale * (1.0 + v @ v), where
            assert np.abs(p - data.oMf[fid].translation).max() < 1e-13 * (1.0 + np.abs(p).max()), where
            assert np.abs(R - data.oMf[fid].rotation).max() < 1e-14, where
