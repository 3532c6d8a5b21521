"""φ's frame terms computed from the joint's (compiled.plan_phi.frame_motion) against Pinocchio's own frame calls."""

from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest

from contactdyn.compiled.plan_phi import LWA, frame_constants, frame_motion, joint_terms

URDF = Path(__file__).resolve().parent.parent / "urdf"


def _models():
    """Our robots (revolute and prismatic chains, 1 to 5 DOF), Pinocchio's sample manipulator, and its branched
    humanoid on a free-flyer (frames whose joints do not move the others: the support columns)."""
    for path in sorted(URDF.glob("*.urdf")):
        yield path.stem, pin.buildModelFromUrdf(str(path))
    yield "manipulator", pin.buildSampleModelManipulator()
    yield "humanoid", pin.buildSampleModelHumanoid()


@pytest.mark.parametrize("name,model", list(_models()), ids=lambda v: v if isinstance(v, str) else "")
def test_frame_motion_is_pinocchios_frame_jacobian_acceleration_and_placement(name, model):
    """Every frame, one more at a rotated offset on the last joint and one fixed in the world: J (6 rows), J̇q̇ at
    q̈ = 0 (classical: linear, angular), p and R in LOCAL_WORLD_ALIGNED as Pinocchio's to 1e-13, at random states."""
    offset = pin.SE3(pin.rpy.rpyToMatrix(0.3, -0.7, 1.1), np.array([0.05, -0.2, 0.13]))
    model.addFrame(pin.Frame("offset", model.njoints - 1, offset, pin.FrameType.OP_FRAME))
    model.addFrame(pin.Frame("fixed", 0, offset, pin.FrameType.OP_FRAME))
    data = model.createData()
    rng = np.random.default_rng(len(name))
    frames = range(model.nframes)
    views = {fid: (joint_terms(model, data, fid), frame_constants(model, fid)) for fid in frames}  # read once, as
    for _ in range(3):  # the plans do: Pinocchio's data updated in place
        lo, hi = np.clip(model.lowerPositionLimit, -3.0, 3.0), np.clip(model.upperPositionLimit, -3.0, 3.0)
        q = pin.normalize(model, rng.uniform(lo, hi))
        v = rng.normal(size=model.nv)
        pin.computeAllTerms(model, data, q, v)
        for fid in frames:
            J6, a6, p, R = frame_motion(*views[fid][0], *views[fid][1])
            pin.updateFramePlacement(model, data, fid)
            J_ref = pin.getFrameJacobian(model, data, fid, LWA).reshape(6, model.nv)
            a_ref = pin.getFrameClassicalAcceleration(model, data, fid, LWA).vector
            scale = 1.0 + np.abs(J_ref).max() + np.abs(a_ref).max()
            assert np.abs(J6 - J_ref).max() < 1e-13 * scale, (name, model.frames[fid].name)
            assert np.abs(a6 - a_ref).max() < 1e-13 * scale * (1.0 + v @ v), (name, model.frames[fid].name)
            assert np.abs(p - data.oMf[fid].translation).max() < 1e-13 * (1.0 + np.abs(p).max())
            assert np.abs(R - data.oMf[fid].rotation).max() < 1e-14
