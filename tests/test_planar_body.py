"""A body with a planar joint (issue 32): a scene body's ``planar`` joint <j> becomes three one-coordinate joints
<j>_x, <j>_y (prismatic, in the plane) and <j>_yaw (revolute about its normal, the joint's ``<axis>``;
:func:`contactdyn.robot.urdf_model.split_planar_joints`): an articulated body. Its H(q) and h(q, q̇) are
Pinocchio's own planar joint's (q = (x, y, cos θ, sin θ), v = (v_x, v_y, ω) in the joint's turned frame) mapped to
(x, y, θ); a puck on a vertical plane, thrown, follows its parabola and keeps its spin; a name taken already and a
joint left unsupported are one clear error each.
"""

from __future__ import annotations

import numpy as np
import pytest

from contactdyn import parse_scene, simulate
from contactdyn.errors import RobotError, SceneError
from contactdyn.robot.body import load_body

pytestmark = pytest.mark.filterwarnings("ignore:.*the scene has no contacts")

G = 9.81  #: [m/s²]
M_PUCK = 2.0  #: [kg]


def _puck(axis: str | None = "0 0 1", joint: str = "slide", extra: str = "") -> str:
    """A puck on a planar joint (its inertial off its frame's origin and tilted: every term of H shows)."""
    ax = f'<axis xyz="{axis}"/>' if axis is not None else ""
    return f"""<?xml version="1.0"?>
<robot name="puck"><link name="world"/>
  <joint name="{joint}" type="planar"><parent link="world"/><child link="puck"/>
    <origin xyz="0.1 0.2 0.3" rpy="0.3 -0.2 0.5"/>{ax}</joint>
  <link name="puck"><inertial><origin xyz="0.1 0.02 0.03" rpy="0.1 0.2 0.3"/><mass value="{M_PUCK}"/>
    <inertia ixx="0.2" iyy="0.25" izz="0.3" ixy="0.01" ixz="0" iyz="0.02"/></inertial>
    <visual><geometry><cylinder radius="0.05" length="0.02"/></geometry></visual></link>{extra}
</robot>
"""


def test_its_three_joints_have_pinocchio_s_planar_dynamics(tmp_path):
    """H = Jᵀ H_p J and h = Jᵀ (H_p J̇ q̇ + h_p), v_p = J q̇ = (R(θ)ᵀ (ẋ, ẏ), θ̇), at random states, to 1e-12."""
    import pinocchio as pin

    (tmp_path / "puck.urdf").write_text(_puck())
    body = load_body(str(tmp_path / "puck.urdf"))
    assert body.articulated and body.joints == ["slide_x", "slide_y", "slide_yaw"]
    ours = body.robot
    ref = pin.buildModelFromXML(_puck())
    assert ref.joints[1].shortname() == "JointModelPlanar"
    ref.gravity = ours.model.gravity
    data = ref.createData()
    rng = np.random.default_rng(7)
    for _ in range(5):
        q, qd = rng.uniform(-2.0, 2.0, 3), rng.uniform(-3.0, 3.0, 3)
        c, s = np.cos(q[2]), np.sin(q[2])
        J = np.array([[c, s, 0.0], [-s, c, 0.0], [0.0, 0.0, 1.0]])  # v_p = J q̇
        Jd = qd[2] * np.array([[-s, c, 0.0], [-c, -s, 0.0], [0.0, 0.0, 0.0]])
        qp, vp = np.array([q[0], q[1], c, s]), J @ qd
        H_p = pin.crba(ref, data, qp).copy()
        H_p = np.triu(H_p) + np.triu(H_p, 1).T
        h_p = pin.nonLinearEffects(ref, data, qp, vp).copy()
        ours.update(q, qd)
        np.testing.assert_allclose(ours.H, J.T @ H_p @ J, rtol=0, atol=1e-12)
        np.testing.assert_allclose(ours.h, J.T @ (H_p @ Jd @ qd + h_p), rtol=0, atol=1e-12)


def test_its_axis_is_the_plane_s_normal(tmp_path):
    """Normal y: the in-plane axes are x and −z (the shortest turn of z onto y), the yaw about y."""
    (tmp_path / "puck.urdf").write_text(_puck("0 1 0").replace('rpy="0.3 -0.2 0.5"', 'rpy="0 0 0"'))
    body = load_body(str(tmp_path / "puck.urdf"))
    np.testing.assert_allclose(body.axes, [[1, 0, 0], [0, 0, -1], [0, 1, 0]], rtol=0, atol=1e-15)


def _thrown_scene(tmp_path, v0):
    """A puck on a vertical plane (normal y: its coordinates x [m], y along −z [m], yaw about y [rad]) thrown."""
    (tmp_path / "puck.urdf").write_text(_puck("0 1 0").replace(' rpy="0.3 -0.2 0.5"', ""))
    doc = {"name": "puck", "duration": 0.5,
           "solver": {"method": "DOP853C", "rtol": 1e-10, "atol": 1e-12, "output_rate": 100.0, "record_energy": True},
           "robot": {"urdf": "point_mass_xz", "tip": "tip", "q0": [0.5, 0.2]},
           "body": {"puck": {"urdf": str(tmp_path / "puck.urdf"), "position0": [0.0, 0.0, 0.3],
                             "velocity0": list(v0)}},
           "controller": {"kind": "task_pd", "axes": [[1.0, 0.0, 0.0], [0.0, 0.0, 1.0]], "kp": 1e4, "kd": 300.0,
                          "feedforward": "gravity"},
           "phase": [{"name": "wait"}]}
    return parse_scene(doc, None, tmp_path / "scene.toml")


def test_a_puck_thrown_on_a_vertical_plane_follows_its_parabola_and_keeps_its_spin(tmp_path):
    """Its centre of mass falls freely in the plane and its spin about the normal stays (no torque about it):
    with the inertial off the frame's origin the coordinates couple, so the centre is checked, not the origin."""
    r = simulate(_thrown_scene(tmp_path, [0.4, -1.0, 6.0]))
    t = r["t"]
    x, y, yaw = (r[f"body.puck.slide_{c}.x"] for c in ("x", "y", "yaw"))
    np.testing.assert_allclose(r["body.puck.slide_yaw.v"], 6.0, rtol=0, atol=1e-9)
    # the centre of mass: the inertial's origin (0.1, 0.02, 0.03) turned by yaw about y, in (x, −z) coordinates
    cx = x + 0.1 * np.cos(yaw) + 0.03 * np.sin(yaw)
    cy = y - (-0.1 * np.sin(yaw) + 0.03 * np.cos(yaw))
    np.testing.assert_allclose(cx, cx[0] + _rate(cx, t) * t, rtol=0, atol=1e-9)
    np.testing.assert_allclose(cy - 0.5 * G * t**2, cy[0] + _rate(cy - 0.5 * G * t**2, t) * t, rtol=0, atol=1e-9)
    residual = r.meta["checks"]["energy_residual"]
    assert residual["value"] <= residual["tol"], residual


def _rate(s: np.ndarray, t: np.ndarray) -> float:
    """[per s] the slope of a sampled straight line (its ends)."""
    return float((s[-1] - s[0]) / (t[-1] - t[0]))


def test_a_planar_joint_s_new_names_taken_already_are_one_robot_error(tmp_path):
    extra = '<joint name="slide_yaw" type="fixed"><parent link="puck"/><child link="tag"/></joint><link name="tag"/>'
    (tmp_path / "puck.urdf").write_text(_puck(extra=extra))
    with pytest.raises(RobotError, match="planar joint 'slide' becomes joints slide_x, slide_y, slide_yaw.*"
                                         "'slide_yaw' already"):
        load_body(str(tmp_path / "puck.urdf"))


def test_a_joint_left_of_several_coordinates_is_still_one_clear_error(tmp_path):
    """A joint that stays several coordinates (here a floating joint below the root: not a free body's) is named
    with its type."""
    extra = ('<joint name="loose" type="floating"><parent link="puck"/><child link="bead"/></joint>'
             '<link name="bead"><inertial><mass value="0.1"/><inertia ixx="1e-4" iyy="1e-4" izz="1e-4" ixy="0" '
             'ixz="0" iyz="0"/></inertial></link>')
    (tmp_path / "puck.urdf").write_text(_puck(extra=extra))
    with pytest.raises(RobotError, match=r"found loose \(JointModelFreeFlyer\)"):
        load_body(str(tmp_path / "puck.urdf"))


def test_a_robot_s_planar_joint_is_not_split(tmp_path):
    """Only a scene body's URDF is rewritten: a robot with a planar joint still says it is not supported."""
    from contactdyn.robot.robot import Robot

    (tmp_path / "puck.urdf").write_text(_puck())
    with pytest.raises(RobotError, match="spherical, planar or free"):
        Robot.load(str(tmp_path / "puck.urdf"))


def test_a_scene_reads_a_planar_body_as_articulated_with_three_coordinates(tmp_path):
    """An articulated body of three coordinates: one start value is one SceneError."""
    scene = _thrown_scene(tmp_path, [0.0, 0.0, 0.0])
    assert scene.bodies["puck"].articulated
    with pytest.raises(SceneError):
        parse_scene({**scene.document, "body": {"puck": {**scene.document["body"]["puck"], "position0": [0.0]}}},
                    None, tmp_path / "scene.toml")
