"""contactdyn.Robot: closed forms, finite differences, locking, example-robot-data, bad robots.

Tolerances: central differences with step ε have truncation error O(ε²) and round-off
O(1e-16/ε); ε = 1e-6 on first derivatives gives ≈ 1e-10, checked at 1e-8 (scaled by the
size of the quantity). Second differences use ε = 1e-4: ≈ 1e-8 each way, checked at 1e-6.
"""

from __future__ import annotations

import math
import os
import string
import sys
from functools import cache
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest

from contactdyn import Robot, RobotError
from contactdyn.robot.robot import EXAMPLE_ROBOTS, FrameTerms, urdf_dir

G = 9.81  # [m/s²], Robot.load's default gravity magnitude
OUR_URDFS = sorted(p.stem for p in urdf_dir().glob("*.urdf"))


@cache
def robot(name: str, compensation: float = 0.0) -> Robot:
    return Robot.load(name, gravity_compensation=compensation)


def random_state(r: Robot, rng: np.random.Generator, vmax: float = 2.0) -> tuple[np.ndarray, np.ndarray]:
    """q inside the joint limits (clipped to ±π where they are wider), q̇ uniform in ±vmax [rad/s or m/s]."""
    lo = np.maximum(r.model.lowerPositionLimit, -math.pi)
    hi = np.minimum(r.model.upperPositionLimit, math.pi)
    free = lo >= hi  # double_pendulum's URDF says lower = upper = 0: no limits meant
    lo[free], hi[free] = -math.pi, math.pi
    return rng.uniform(lo, hi), rng.uniform(-vmax, vmax, r.nv)


# frames whose kinematics are checked by finite differences: (robot, frame)
FRAMES = [("writer2r", "tip"), ("arm2r_cart", "tip"), ("planar2r_b1", "tip"), ("writer5dof", "tip"),
          ("cylindrical3", "tip"), ("ur5", "tool0"), ("panda", "panda_hand_tcp"), ("double_pendulum", "link2")]


# ---- closed form, eq. (3), through Robot (with case 1's gravity compensation) ---------------
def closed_form_2r(q, v, m1, m2, l1, l11, l22, I1, I2, g):
    """H, Coriolis c and gravity G of the vertical-plane 2R of eq. (3), angles from the vertical."""
    (q1, q2), (dq1, dq2) = q, v
    c2, s2 = math.cos(q2), math.sin(q2)
    H12 = m2 * l22 * (l22 + l1 * c2) + I2
    H = np.array([[m1 * l11**2 + m2 * (l1**2 + l22**2 + 2 * l1 * l22 * c2) + I1 + I2, H12], [H12, m2 * l22**2 + I2]])
    c = m2 * l1 * l22 * s2 * np.array([-(2 * dq1 * dq2 + dq2**2), dq1**2])
    G2 = -g * m2 * l22 * math.sin(q1 + q2)
    return H, c, np.array([-g * (m1 * l11 + m2 * l1) * math.sin(q1) + G2, G2])


@pytest.mark.parametrize("name,par", [
    ("arm2r_cart", dict(m1=60.0, m2=40.0, l1=1.0, l11=0.5, l22=0.5, I1=5.0, I2=3.5)),  # Table 1
    ("writer2r", dict(m1=3.0, m2=3.0, l1=0.3, l11=0.15, l22=0.15, I1=0.025, I2=0.025)),  # sec. 5.2
])
@pytest.mark.parametrize("compensation", [0.0, 0.7])
def test_2r_H_h_closed_form_eq3(name, par, compensation):
    r = robot(name, compensation)
    rng = np.random.default_rng(7)
    for _ in range(20):
        q, v = random_state(r, rng, vmax=3.0)
        H_ref, c_ref, G_ref = closed_form_2r(q, v, g=G, **par)
        r.update(q, v)
        np.testing.assert_allclose(r.H, H_ref, rtol=0, atol=1e-10)
        np.testing.assert_allclose(r.h, c_ref + (1.0 - compensation) * G_ref, rtol=0, atol=1e-10)


def test_gravity_compensation_leaves_30_percent():
    full, case1 = robot("arm2r_cart"), robot("arm2r_cart", 0.7)
    rng = np.random.default_rng(8)
    for _ in range(10):
        q, v = random_state(full, rng)
        g = full.gravity_torque(q)
        assert np.linalg.norm(g) > 1.0  # a real load [N·m], not a trivially zero check
        case1.update(q, np.zeros(2))
        np.testing.assert_allclose(case1.h, 0.3 * g, rtol=1e-12, atol=1e-12)
        np.testing.assert_allclose(case1.gravity_torque(q), 0.3 * g, rtol=1e-12, atol=1e-12)
        # compensation removes gravity only: H and the velocity terms are untouched
        np.testing.assert_allclose(case1.bias(q, v) - case1.bias(q, 0 * v), full.bias(q, v) - full.bias(q, 0 * v),
                                   rtol=0, atol=1e-10)
        np.testing.assert_allclose(case1.mass_matrix(q), full.mass_matrix(q), rtol=0, atol=0)


@pytest.mark.parametrize("c", [-0.1, 1.5])
def test_gravity_compensation_out_of_range(c):
    with pytest.raises(RobotError, match=r"gravity_compensation must be in \[0, 1\]"):
        Robot.load("writer2r", gravity_compensation=c)


# ---- finite differences -----------------------------------------------------------------
@pytest.mark.parametrize("name,frame", FRAMES)
def test_frame_jacobian_central_differences(name, frame):
    """Linear rows: ∂p/∂q; angular rows: world angular velocity per unit joint rate."""
    r, eps = robot(name), 1e-6
    rng = np.random.default_rng(11)
    for _ in range(3):
        q, _ = random_state(r, rng)
        J = r.frame_jacobian(q, frame)
        assert J.shape == (6, r.nv)
        fd = np.empty((6, r.nv))
        for i in range(r.nv):
            dq = np.zeros(r.nv)
            dq[i] = eps
            Mp, Mm = r.frame_placement(q + dq, frame), r.frame_placement(q - dq, frame)
            fd[:3, i] = (Mp.translation - Mm.translation) / (2 * eps)
            fd[3:, i] = pin.log3(Mp.rotation @ Mm.rotation.T) / (2 * eps)  # world-aligned ω
        np.testing.assert_allclose(J, fd, rtol=0, atol=1e-8 * max(1.0, np.abs(J).max()))


@pytest.mark.parametrize("name,frame", FRAMES)
def test_frame_drift_central_differences(name, frame):
    """J̇q̇ = d/dt J(q + t q̇) q̇ at t = 0, all six rows."""
    r, eps = robot(name), 1e-6
    rng = np.random.default_rng(12)
    for _ in range(3):
        q, v = random_state(r, rng)
        drift = r.frame_drift(q, v, frame)
        fd = (r.frame_jacobian(q + eps * v, frame) - r.frame_jacobian(q - eps * v, frame)) @ v / (2 * eps)
        assert np.abs(fd).max() > 1e-3  # a non-trivial drift at these states
        np.testing.assert_allclose(drift, fd, rtol=0, atol=1e-8 * max(1.0, np.abs(fd).max()))


@pytest.mark.parametrize("name,frame", FRAMES)
def test_tip_acceleration_along_trajectory(name, frame):
    """p̈ = J q̈ + J̇q̇ along q(t) = q + t q̇ + ½t² q̈ (second central difference of the position).

    Independent of how J̇ is formed: it is the classical (not the spatial) acceleration."""
    r, eps = robot(name), 1e-4
    rng = np.random.default_rng(13)
    fid = r.frame_id(frame)
    for _ in range(3):
        q, v = random_state(r, rng)
        a = rng.uniform(-2.0, 2.0, r.nv)
        p = [r.frame_position(q + t * v + 0.5 * t * t * a, frame) for t in (-eps, 0.0, eps)]
        acc_fd = (p[2] - 2 * p[1] + p[0]) / eps**2
        vel_fd = (p[2] - p[0]) / (2 * eps)
        r.update(q, v)
        ft = r.frame_terms(fid)
        scale = max(1.0, np.abs(acc_fd).max())
        np.testing.assert_allclose(ft.jacobian @ a + ft.drift, acc_fd, rtol=0, atol=1e-6 * scale)
        np.testing.assert_allclose(ft.velocity, vel_fd, rtol=0, atol=1e-6 * max(1.0, np.abs(vel_fd).max()))


# ---- the update path agrees with the convenience functions ------------------------------
@pytest.mark.parametrize("name,frame", FRAMES)
def test_frame_terms_match_convenience(name, frame):
    r = robot(name)
    fid = r.frame_id(frame)
    rng = np.random.default_rng(14)
    q, v = random_state(r, rng)
    r.update(q, v)
    ft = r.frame_terms(fid)
    assert isinstance(ft, FrameTerms)
    # the convenience functions use their own data: calling them at another state changes nothing
    q2, v2 = random_state(r, rng)
    r.frame_drift(q2, v2, fid), r.mass_matrix(q2), r.bias(q2, v2), r.frame_position(q2, fid), r.gravity_torque(q2)
    for again, first in zip(r.frame_terms(fid), ft, strict=True):
        np.testing.assert_array_equal(again, first)
    np.testing.assert_allclose(r.H, r.mass_matrix(q), rtol=0, atol=1e-12)
    np.testing.assert_allclose(r.H, r.H.T, rtol=0, atol=0)  # full, symmetric (not one triangle)
    assert np.linalg.eigvalsh(r.H).min() > 0.0
    np.testing.assert_allclose(r.h, r.bias(q, v), rtol=0, atol=1e-12)
    J6 = r.frame_jacobian(q, fid)
    np.testing.assert_allclose(ft.position, r.frame_position(q, frame), rtol=0, atol=1e-14)
    np.testing.assert_allclose(ft.jacobian, J6[:3], rtol=0, atol=1e-14)
    np.testing.assert_allclose(ft.velocity, J6[:3] @ v, rtol=0, atol=1e-12)
    np.testing.assert_allclose(ft.drift, r.frame_drift(q, v, frame)[:3], rtol=0, atol=1e-12)
    np.testing.assert_allclose(ft.rotation, r.frame_placement(q, frame).rotation, rtol=0, atol=1e-14)
    np.testing.assert_allclose(ft.angular_jacobian, J6[3:], rtol=0, atol=1e-14)
    # the returned arrays are the caller's: the next update does not change them
    kept = [x.copy() for x in ft]
    r.update(q2, v2)
    assert not np.allclose(r.frame_terms(fid).position, kept[0])
    for old, x in zip(kept, ft, strict=True):
        np.testing.assert_array_equal(old, x)


def test_frame_id_accepts_numpy_index_in_convenience():
    r = robot("writer2r")
    fid = np.int64(r.frame_id("tip"))
    np.testing.assert_allclose(r.frame_position(np.zeros(2), fid), [0.0, 0.0, 0.6], atol=1e-15)


# ---- cylindrical robot: eq. (47) structure and case 3's reduction -------------------------
M3 = 50.0  # [kg], sec. 5.3


def test_cylindrical3_block_structure_eq47_and_decoupled_row():
    r = robot("cylindrical3")
    rng = np.random.default_rng(21)
    for _ in range(10):
        q, v = random_state(r, rng)
        r.update(q, v)
        H = r.H
        np.testing.assert_array_equal(H[:2, 2], 0.0)
        np.testing.assert_array_equal(H[2, :2], 0.0)
        assert H[2, 2] == pytest.approx(M3, abs=1e-12)
        assert r.h[2] == pytest.approx(-M3 * G, abs=1e-10)  # velocity-free, gravity only
        # q̈3 = (τ3 − h3)/m whatever τ1, τ2 and the other joints' motion: the row decouples
        tau = rng.uniform(-100.0, 100.0, 3)
        qdd = pin.aba(r.model, pin.Data(r.model), q, v, tau)
        assert qdd[2] == pytest.approx((tau[2] + M3 * G) / M3, abs=1e-10)


def test_cylindrical3_reduced_to_vertical_axis_case3():
    full = robot("cylindrical3")
    rng = np.random.default_rng(22)
    for q1, q2 in [(0.0, 0.0), (0.4, 0.1), (-2.0, -0.3)]:
        locked = {"q1": q1, "q2": q2} if q1 or q2 else None
        red = Robot.load("cylindrical3", active_joints=["q3"], locked=locked)
        assert red.nq == red.nv == 1 and red.joint_names == ["q3"]
        assert red.locked == {"q1": q1, "q2": q2}
        fid, fid_full = red.frame_id("tip"), full.frame_id("tip")
        for _ in range(5):
            q3, v3 = rng.uniform(-0.4, 1.2), rng.uniform(-2.0, 2.0)
            red.update(np.array([q3]), np.array([v3]))
            np.testing.assert_allclose(red.H, [[M3]], rtol=0, atol=1e-12)
            np.testing.assert_allclose(red.h, [-M3 * G], rtol=0, atol=1e-10)
            full.update(np.array([q1, q2, q3]), np.array([0.0, 0.0, v3]))
            a, b = red.frame_terms(fid), full.frame_terms(fid_full)
            assert a.jacobian.shape == a.angular_jacobian.shape == (3, 1)
            assert red.frame_jacobian(np.array([q3]), fid).shape == (6, 1)
            assert red.H.shape == (1, 1) and red.h.shape == (1,)
            np.testing.assert_allclose(a.position, b.position, rtol=0, atol=1e-12)
            np.testing.assert_allclose(a.velocity, b.velocity, rtol=0, atol=1e-12)
            np.testing.assert_allclose(a.jacobian[:, 0], b.jacobian[:, 2], rtol=0, atol=1e-12)
            np.testing.assert_allclose(a.jacobian[:, 0], [0.0, 0.0, -1.0], rtol=0, atol=1e-12)
            np.testing.assert_allclose(a.drift, b.drift, rtol=0, atol=1e-12)
            np.testing.assert_allclose(red.H[0, 0], full.H[2, 2], rtol=0, atol=1e-12)
            np.testing.assert_allclose(red.h[0], full.h[2], rtol=0, atol=1e-10)


def test_lock_with_locked_only_keeps_the_rest_active():
    r = Robot.load("cylindrical3", locked={"q2": 0.2})
    assert r.joint_names == ["q1", "q3"] and r.locked == {"q2": 0.2}
    full = robot("cylindrical3")
    np.testing.assert_allclose(r.frame_position(np.array([0.3, 0.5]), "tip"),
                               full.frame_position(np.array([0.3, 0.2, 0.5]), "tip"), rtol=0, atol=1e-12)


def test_panda_with_locked_fingers():
    fingers = {"panda_finger_joint1": 0.02, "panda_finger_joint2": 0.02}
    r = Robot.load("panda", locked=fingers)
    assert r.nv == 7 and r.joint_names == [f"panda_joint{i}" for i in range(1, 8)]
    full = robot("panda")
    q7 = random_state(r, np.random.default_rng(3))[0]
    np.testing.assert_allclose(r.frame_position(q7, "panda_hand_tcp"),
                               full.frame_position(np.r_[q7, 0.02, 0.02], "panda_hand_tcp"), rtol=0, atol=1e-12)
    # the locked fingers' mass moves with the hand: H of the arm equals the arm block of the full H
    np.testing.assert_allclose(r.mass_matrix(q7), full.mass_matrix(np.r_[q7, 0.02, 0.02])[:7, :7], rtol=0, atol=1e-12)
    # meshes of the locked fingers hang on the last arm joint
    assert len(r.visual_model.geometryObjects) == len(full.visual_model.geometryObjects)


# ---- every robot we ship, and example-robot-data ------------------------------------------
@pytest.mark.parametrize("name", OUR_URDFS)
def test_our_urdfs_load(name):
    r = Robot.load(name)
    assert r.nq == r.nv == len(r.joint_names) >= 1
    assert r.model.existFrame("tip")
    assert Robot.load(urdf_dir() / f"{name}.urdf").joint_names == r.joint_names  # by path, too


def _deepest_body(name: str) -> str:
    """The body frame with the most joints above it: a tip every robot has."""
    from contactdyn.robot.frames import chain_joints
    from contactdyn.robot.urdf_model import build_urdf_model

    model = build_urdf_model(name, inertia="trust").model
    bodies = [i for i, f in enumerate(model.frames) if f.type == pin.FrameType.BODY]
    return model.frames[max(bodies, key=lambda i: len(chain_joints(model, i)))].name


@pytest.mark.parametrize("name", sorted(EXAMPLE_ROBOTS))
def test_example_robot_data_loads(name):
    """Every robot example-robot-data ships loads by name (inertia repaired where the file's fails),
    with the chain to its deepest body active; robots without joints say so."""
    if name in ("iris_simple", "quadrotor_base"):
        load_error(name, "no active joint")
        return
    if name == "ur_description/ur3":  # a xacro-made file without links or a robot name: not a URDF
        load_error(name, "expected <link> elements in <robot>, found none")
        return
    tip = _deepest_body(name)
    if name in ("romeo", "romeo_laas_small"):  # the finger or gripper links at their leaves carry no inertial
        load_error(name, "move no mass or inertia", tip=tip, inertia="repair")
        tip = "r_wrist"  # the arm to its wrist loads
    r = Robot.load(name, tip=tip, inertia="repair")
    if name == "romeo_laas_small":  # meshes named by absolute paths of the authors' machine: drawn without them
        assert len(r.visual_notes) == 1 and "20 visual mesh(es) not found" in r.visual_notes[0]
    assert r.nv >= 1 and len(r.joint_names) == r.nv
    q, v = random_state(r, np.random.default_rng(4))
    r.update(q, v)
    assert np.all(np.isfinite(r.h)) and np.linalg.eigvalsh(r.H).min() > 0.0


@pytest.mark.parametrize("name,nv", [("ur5", 6), ("panda", 9), ("double_pendulum", 2)])
def test_example_robot_meshes_resolved(name, nv):
    r = robot(name)
    assert r.nv == nv
    meshes = [g.meshPath for g in r.visual_model.geometryObjects if g.meshPath]
    assert len(meshes) >= nv
    for mesh in meshes:
        assert "package://" not in mesh and Path(mesh).is_file(), mesh


# ---- bad robots: one clear message naming the file and the reason --------------------------
GOOD = string.Template("""<?xml version="1.0"?>
<robot name="bad">
  <link name="base"/>
  <joint name="q1" type="$type1">
    <parent link="base"/><child link="link1"/><axis xyz="0 1 0"/>
    $limit1
  </joint>
  <link name="link1">
    <inertial><origin xyz="0 0 0.1"/><mass value="$mass1"/>
      <inertia ixx="$ixx" ixy="$ixy" ixz="0" iyy="0.01" iyz="0" izz="$izz"/></inertial>
    $visual1
  </link>
  <joint name="q2" type="revolute">
    <parent link="link1"/><child link="link2"/><origin xyz="0 0 0.3"/><axis xyz="0 1 0"/>
    <limit lower="-1" upper="1" effort="10" velocity="1"/>
  </joint>
  <link name="link2">
    $inertial2
  </link>
  <joint name="tip_joint" type="fixed"><parent link="link2"/><child link="tip"/><origin xyz="0 0 0.3"/></joint>
  <link name="tip">$tip</link>
</robot>
""")
DEFAULTS = dict(type1="revolute", limit1='<limit lower="-1" upper="1" effort="10" velocity="1"/>', mass1="1.0",
                ixx="0.01", ixy="0", izz="0.005", visual1="", tip="",
                inertial2='<inertial><mass value="1"/><inertia ixx="0.01" iyy="0.01" izz="0.001" '
                          'ixy="0" ixz="0" iyz="0"/></inertial>')
ZERO_INERTIAL = '<inertial><mass value="0"/><inertia ixx="0" ixy="0" ixz="0" iyy="0" iyz="0" izz="0"/></inertial>'


def write(tmp_path: Path, text: str, name: str = "bad.urdf") -> Path:
    path = tmp_path / name
    path.write_text(text)
    return path


def urdf(tmp_path: Path, **changes: str) -> Path:
    return write(tmp_path, GOOD.substitute(DEFAULTS | changes))


def load_error(source, *parts: str, **kwargs) -> str:
    """Load must fail with one RobotError whose message contains every part; no chained traceback."""
    with pytest.raises(RobotError) as info:
        Robot.load(source, **kwargs)
    err = info.value
    message = str(err)
    for part in parts:
        assert part in message, f"{part!r} not in {message!r}"
    assert err.__context__ is None or err.__suppress_context__, "a chained traceback"
    assert "Traceback" not in message
    return message


def test_good_template_loads(tmp_path):
    """Guards the bad-robot tests: each breaks exactly one thing of a robot that loads."""
    r = Robot.load(urdf(tmp_path))
    assert r.joint_names == ["q1", "q2"] and r.frame_id("tip") > 0


def test_massless_frame_link_is_fine(tmp_path):
    """Zero mass AND zero inertia (or no inertial at all) is a massless frame link: accepted."""
    r = Robot.load(urdf(tmp_path, tip=ZERO_INERTIAL))
    assert r.nv == 2


def test_malformed_xml(tmp_path, capfd):
    path = write(tmp_path, GOOD.substitute(DEFAULTS).replace("</robot>", ""))
    message = load_error(path, str(path), "malformed XML", "line ")
    assert "\n" not in message
    # urdfdom's stderr was captured and fd 2 is restored afterwards
    os.write(2, b"fd2-restored\n")
    sys.stderr.write("py-stderr-works\n")
    sys.stderr.flush()
    err = capfd.readouterr().err
    assert "fd2-restored" in err and "py-stderr-works" in err and "XML_ERROR" not in err


def test_revolute_without_limits_gives_urdfdom_reason(tmp_path):
    path = urdf(tmp_path, limit1="")
    message = load_error(path, str(path), "Joint [q1] is of type REVOLUTE but it does not specify limits")
    assert "does not contain a valid URDF model" not in message  # Pinocchio's reason-less text


def test_undefined_parent_link(tmp_path):
    path = write(tmp_path, GOOD.substitute(DEFAULTS).replace('<parent link="link1"/>', '<parent link="linkX"/>'))
    load_error(path, str(path), "joint 'q2': parent link 'linkX' is not defined")


@pytest.mark.parametrize("mass", ["-1.0", "-1e-9"])
def test_negative_mass(tmp_path, mass):
    path = urdf(tmp_path, mass1=mass)
    load_error(path, str(path), "link 'link1'", "mass must be >= 0 [kg]", f"found {float(mass)}")


def test_zero_mass_with_inertia(tmp_path):
    path = urdf(tmp_path, mass1="0")
    load_error(path, str(path), "link 'link1'", "zero mass", "non-zero rotational inertia")


def test_inertia_violates_triangle_inequality(tmp_path):
    # principal moments (0.01, 0.01, 0.05): 0.01 + 0.01 < 0.05, positive definite nonetheless
    path = urdf(tmp_path, izz="0.05")
    load_error(path, str(path), "link 'link1'", "triangle inequality", "[0.01, 0.01, 0.05]")


def test_inertia_not_positive_definite(tmp_path):
    # positive diagonal, but ixy = 0.02 makes the moments (-0.01, 0.005, 0.03)
    path = urdf(tmp_path, ixy="0.02")
    load_error(path, str(path), "link 'link1'", "not positive (semi-)definite", "-0.01")


def test_negative_moment(tmp_path):
    path = urdf(tmp_path, ixx="-0.01")
    load_error(path, str(path), "link 'link1'", "not positive (semi-)definite")


def test_lower_limit_above_upper(tmp_path):
    path = urdf(tmp_path, limit1='<limit lower="1" upper="-1" effort="10" velocity="1"/>')
    load_error(path, str(path), "joint 'q1'", "lower limit [1.0] > upper limit [-1.0]")


def test_joint_moving_no_mass(tmp_path):
    path = urdf(tmp_path, inertial2="")
    load_error(path, str(path), "['q2']", "move no mass or inertia")


def test_unknown_frame():
    r = robot("writer2r")
    with pytest.raises(RobotError) as info:
        r.frame_id("tpi")
    message = str(info.value)
    assert "writer2r.urdf" in message and "no frame named 'tpi'" in message and "'tip'" in message


def test_unknown_robot_name_suggests_close_match():
    message = load_error("ur55", "robot 'ur55'", "did you mean ur5")
    assert "known:" in message and "panda" in message and "writer2r" in message


def test_nonexistent_urdf_path(tmp_path):
    path = tmp_path / "missing" / "robot.urdf"
    load_error(path, str(path), "no such URDF file")


def test_missing_mesh_is_left_out_of_the_drawing_with_a_note(tmp_path):
    visual = '<visual><geometry><mesh filename="package://nowhere/meshes/link1.stl"/></geometry></visual>'
    path = urdf(tmp_path, visual1=visual)
    r = Robot.load(path)
    assert r.visual_notes == [f"{path.name}: 1 visual mesh(es) not found or unusable (searched the URDF's folders, "
                              "example-robot-data and ROS_PACKAGE_PATH; a mesh is a regular .dae, .stl or .obj "
                              "file): link 'link1' ('package://nowhere/meshes/link1.stl'); the viewer draws those "
                              "links without them"]
    assert r.describe()["visual_notes"] == r.visual_notes
    assert r.visual_model.ngeoms == 0  # the link's only visual was that mesh


@pytest.mark.parametrize("target", ["/etc/passwd", "/proc/self/mem"])
def test_a_mesh_that_is_no_mesh_file_is_left_out_with_the_same_note(tmp_path, target):
    visual = f'<visual><geometry><mesh filename="{target}"/></geometry></visual>'
    r = Robot.load(urdf(tmp_path, visual1=visual))
    assert len(r.visual_notes) == 1 and f"link 'link1' ('{target}')" in r.visual_notes[0]
    assert r.visual_model.ngeoms == 0


def test_relative_mesh_is_resolved(tmp_path):
    (tmp_path / "link1.stl").write_text("solid empty\nendsolid empty\n")
    visual = '<visual><geometry><mesh filename="link1.stl"/></geometry></visual>'
    assert Robot.load(urdf(tmp_path, visual1=visual)).nv == 2


def test_unknown_joint_names(tmp_path):
    load_error("cylindrical3", "no joint named 'q33'", "did you mean 'q3'", active_joints=["q33"])
    load_error("cylindrical3", "no joint named 'z'", locked={"z": 0.0})
    load_error("cylindrical3", "['q3'] are both active and locked", active_joints=["q3"], locked={"q3": 0.1})


def test_locked_outside_limits():
    load_error("cylindrical3", "locked joint 'q2' at 0.9 m", "outside its limits [-0.5, 0.5] m", locked={"q2": 0.9})
    load_error("cylindrical3", "locked joint 'q1' at 4.0 rad", "outside its limits", "rad", locked={"q1": 4.0})
    # panda joint 4 lives in [-3.07, -0.07]: its neutral value is 0 clipped into them
    assert Robot.load("panda", active_joints=["panda_joint1"]).locked["panda_joint4"] == pytest.approx(-0.0698)


def test_continuous_joint_is_an_unbounded_angle_active_or_locked(tmp_path):
    """A continuous joint is one coordinate, its angle [rad], without limits (not Pinocchio's (cos, sin))."""
    path = urdf(tmp_path, type1="continuous", limit1="")
    active = Robot.load(path)
    assert active.nq == active.nv == 2 and active.unbounded == ["q1"]
    assert active.lower[0] == -math.inf and active.upper[0] == math.inf
    np.testing.assert_allclose(active.frame_position(np.array([0.5 + 2 * math.pi, 0.0]), "tip"),
                               [0.6 * math.sin(0.5), 0.0, 0.6 * math.cos(0.5)], rtol=0, atol=1e-12)
    r = Robot.load(path, locked={"q1": 0.5})
    assert r.joint_names == ["q2"]
    np.testing.assert_allclose(r.frame_position(np.zeros(1), "tip"), [0.6 * math.sin(0.5), 0.0, 0.6 * math.cos(0.5)],
                               rtol=0, atol=1e-12)
