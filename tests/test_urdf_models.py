"""Checks of the paper's robots as URDF files (urdf/*.urdf) against closed forms.

Uses only pinocchio + numpy (and the standard library's XML parser to look at the
files themselves); it does not import contactdyn.

Sources of the closed forms: Potkonjak, Vukobratovic, Matijevic (1999), Part II:
eq. (3) (2R inertia matrix and Coriolis terms), eq. (5) (case 1 tip), eqs. (41-42)
(case 2 Jacobians), eq. (47-49) (cylindrical robot block structure), and the
benchmark definition /work/shared/bench/B1.md.
"""

import math
import os
import xml.etree.ElementTree as ET

import numpy as np
import pinocchio as pin
import pytest

URDF_DIR = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "urdf")
# the point-mass test bodies have massless carriages by design (H = m I); tests/test_friction.py checks them
TEST_BODIES = {"point_mass_xz.urdf", "point_mass_xyz.urdf"}
ALL_URDFS = sorted(f for f in os.listdir(URDF_DIR) if f.endswith(".urdf") and f not in TEST_BODIES)
EXPECTED = {"arm2r_cart.urdf", "writer2r.urdf", "writer5dof.urdf",
            "cylindrical3.urdf", "planar2r_b1.urdf"}

N_RANDOM = 20

# Nominal writing pose of writer5dof (urdf/README.md).
WRITER5_NOMINAL_Q = np.array([0.3, 0.678629948129, 1.834747110377, 0.428215595084, 0.0])

# Benchmark B1 initial state (/work/shared/bench/B1.md).
B1_Q0 = np.array([0.337307481430, -1.318116071653])
B1_V0 = np.array([0.287298334621, -0.774596669241])


def path(name):
    return os.path.join(URDF_DIR, name)


def load(name):
    model = pin.buildModelFromUrdf(path(name))
    return model, model.createData()


def gravity_magnitude(model):
    g = np.asarray(model.gravity.linear)
    # all models assume gravity along -z
    assert np.allclose(g[:2], 0.0)
    assert g[2] < 0.0
    return -g[2]


def mass_matrix(model, data, q):
    H = pin.crba(model, data, q).copy()
    return np.triu(H) + np.triu(H, 1).T


def tip_position(model, data, q):
    pin.framesForwardKinematics(model, data, q)
    return data.oMf[model.getFrameId("tip")].translation.copy()


def random_states(rng, nq, n=N_RANDOM, qmax=math.pi, vmax=3.0):
    for _ in range(n):
        yield rng.uniform(-qmax, qmax, nq), rng.uniform(-vmax, vmax, nq)


def check_inertia_tensor(I, what):
    I = np.asarray(I, dtype=float)
    assert np.allclose(I, I.T, atol=0.0, rtol=0.0), f"{what}: not symmetric"
    ev = np.linalg.eigvalsh(I)
    assert ev.min() > 0.0, f"{what}: not positive definite, eigenvalues {ev}"
    a, b, c = ev
    tol = 1e-12 * ev.max()
    assert a + b >= c - tol and a + c >= b - tol and b + c >= a - tol, (
        f"{what}: principal moments {ev} violate the triangle inequality")


# --------------------------------------------------------------------------------------
# Planar 2R closed forms, eq. (3): links along the arm, angles from the vertical
# --------------------------------------------------------------------------------------

def closed_form_2r(q, v, m1, m2, l1, l11, l22, I1, I2, g, vertical):
    """H, Coriolis c, gravity G of the planar 2R of eq. (3).

    vertical=True: vertical plane, angles measured from the vertical, the COM heights
    are l11 cos q1 and l1 cos q1 + l22 cos(q1+q2) (true for both arm2r_cart, eq. (5),
    and writer2r, eqs. (41-42)), so the potential is
        V = g [m1 l11 cos q1 + m2 (l1 cos q1 + l22 cos(q1+q2))]
    and the gravity torque is G = dV/dq.
    vertical=False: horizontal plane (B1), G = 0.
    """
    q1, q2 = q
    dq1, dq2 = v
    c2, s2 = math.cos(q2), math.sin(q2)
    H11 = m1 * l11 ** 2 + m2 * (l1 ** 2 + l22 ** 2 + 2 * l1 * l22 * c2) + I1 + I2
    H12 = m2 * l22 * (l22 + l1 * c2) + I2
    H22 = m2 * l22 ** 2 + I2
    H = np.array([[H11, H12], [H12, H22]])
    c = np.array([-m2 * l1 * l22 * s2 * (2 * dq1 * dq2 + dq2 ** 2),
                  m2 * l1 * l22 * s2 * dq1 ** 2])
    if vertical:
        G = np.array([-g * ((m1 * l11 + m2 * l1) * math.sin(q1) + m2 * l22 * math.sin(q1 + q2)),
                      -g * m2 * l22 * math.sin(q1 + q2)])
    else:
        G = np.zeros(2)
    return H, c, G


ARM2R_CART = dict(m1=60.0, m2=40.0, l1=1.0, l11=0.5, l22=0.5, I1=5.0, I2=3.5)   # Table 1
WRITER2R = dict(m1=3.0, m2=3.0, l1=0.3, l11=0.15, l22=0.15, I1=0.025, I2=0.025)  # sec. 5.2


@pytest.mark.parametrize("name,par,vertical", [
    ("arm2r_cart.urdf", ARM2R_CART, True),
    ("writer2r.urdf", WRITER2R, True),
    ("planar2r_b1.urdf", WRITER2R, False),
])
def test_2r_dynamics_closed_form(name, par, vertical):
    model, data = load(name)
    assert model.nq == 2 and model.nv == 2
    assert [model.names[i] for i in range(1, model.njoints)] == ["q1", "q2"]
    g = gravity_magnitude(model)
    rng = np.random.default_rng(12345)
    for q, v in random_states(rng, 2):
        H_ref, c_ref, G_ref = closed_form_2r(q, v, g=g, vertical=vertical, **par)
        H = mass_matrix(model, data, q)
        np.testing.assert_allclose(H, H_ref, rtol=0, atol=1e-10)
        h = pin.nonLinearEffects(model, data, q, v).copy()
        np.testing.assert_allclose(h, c_ref + G_ref, rtol=0, atol=1e-10)
        G = pin.computeGeneralizedGravity(model, data, q).copy()
        np.testing.assert_allclose(G, G_ref, rtol=0, atol=1e-10)


def test_2r_gravity_sign_physical():
    """Independent sanity check of the gravity sign: arm2r_cart tilted to +q1 (tip at
    negative x, eq. 5) is pulled further down, i.e. the holding torque about the joint
    axis (0,-1,0) is negative: G1 = dV/dq1 < 0 for 0 < q1 < pi."""
    model, data = load("arm2r_cart.urdf")
    G = pin.computeGeneralizedGravity(model, data, np.array([0.3, 0.0]))
    assert G[0] < 0.0 and G[1] < 0.0
    # upright arm: no gravity torque
    G0 = pin.computeGeneralizedGravity(model, data, np.zeros(2))
    np.testing.assert_allclose(G0, 0.0, atol=1e-12)


# --------------------------------------------------------------------------------------
# Kinematics
# --------------------------------------------------------------------------------------

def test_arm2r_cart_tip_eq5():
    model, data = load("arm2r_cart.urdf")
    l1 = l2 = 1.0  # Table 1
    rng = np.random.default_rng(1)
    for q, _ in random_states(rng, 2):
        q1, q2 = q
        ref = np.array([-l1 * math.sin(q1) - l2 * math.sin(q1 + q2), 0.0,
                        l1 * math.cos(q1) + l2 * math.cos(q1 + q2)])
        np.testing.assert_allclose(tip_position(model, data, q), ref, rtol=0, atol=1e-12)


def test_writer2r_tip_and_jacobian_eq41_42():
    model, data = load("writer2r.urdf")
    l1 = l2 = 0.3  # sec. 5.2
    fid = model.getFrameId("tip")
    rng = np.random.default_rng(2)
    for q, _ in random_states(rng, 2):
        q1, q2 = q
        s1, s12 = math.sin(q1), math.sin(q1 + q2)
        c1, c12 = math.cos(q1), math.cos(q1 + q2)
        ref = np.array([l1 * s1 + l2 * s12, 0.0, l1 * c1 + l2 * c12])
        np.testing.assert_allclose(tip_position(model, data, q), ref, rtol=0, atol=1e-12)
        J = pin.computeFrameJacobian(model, data, q, fid, pin.LOCAL_WORLD_ALIGNED)
        Jz_ref = np.array([-l1 * s1 - l2 * s12, -l2 * s12])   # eq. (41)
        Jx_ref = np.array([l1 * c1 + l2 * c12, l2 * c12])     # eq. (42)
        np.testing.assert_allclose(J[2], Jz_ref, rtol=0, atol=1e-12)
        np.testing.assert_allclose(J[0], Jx_ref, rtol=0, atol=1e-12)
        np.testing.assert_allclose(J[1], 0.0, rtol=0, atol=1e-12)


def test_planar2r_b1_kinematics():
    model, data = load("planar2r_b1.urdf")
    l1 = l2 = 0.3  # B1
    rng = np.random.default_rng(3)
    for q, _ in random_states(rng, 2):
        q1, q2 = q
        ref = np.array([l1 * math.cos(q1) + l2 * math.cos(q1 + q2),
                        l1 * math.sin(q1) + l2 * math.sin(q1 + q2), 0.0])
        np.testing.assert_allclose(tip_position(model, data, q), ref, rtol=0, atol=1e-12)


def test_planar2r_b1_initial_state():
    model, data = load("planar2r_b1.urdf")
    p = tip_position(model, data, B1_Q0)
    np.testing.assert_allclose(p, [0.45, -0.15, 0.0], rtol=0, atol=1e-9)
    assert B1_Q0[1] < 0.0  # elbow up, as B1 states
    fid = model.getFrameId("tip")
    J = pin.computeFrameJacobian(model, data, B1_Q0, fid, pin.LOCAL_WORLD_ALIGNED)
    np.testing.assert_allclose(J[:3] @ B1_V0, [-0.15, 0.0, 0.0], rtol=0, atol=1e-9)


# --------------------------------------------------------------------------------------
# Cylindrical robot, eqs. (47-49)
# --------------------------------------------------------------------------------------

CYL = dict(m2=30.0, m3=50.0, Izz1=0.576, Izz2=2.536, Izz3=0.09,
           r2=0.5, r3=1.0, z_q1=0.2, z_arm=2.2, tool=1.2)


def test_cylindrical3_structure_eq47():
    model, data = load("cylindrical3.urdf")
    assert model.nq == 3 and model.nv == 3
    assert [model.names[i] for i in range(1, model.njoints)] == ["q1", "q2", "q3"]
    g = gravity_magnitude(model)
    m3 = 50.0  # sec. 5.3
    rng = np.random.default_rng(4)
    for _ in range(N_RANDOM):
        q = np.array([rng.uniform(-math.pi, math.pi), rng.uniform(-0.5, 0.5),
                      rng.uniform(-0.4, 1.2)])
        v = rng.uniform(-2.0, 2.0, 3)
        H = mass_matrix(model, data, q)
        for (i, j) in [(0, 2), (1, 2), (2, 0), (2, 1)]:
            assert abs(H[i, j]) <= 1e-12, (i, j, H)
        assert abs(H[2, 2] - m3) <= 1e-12
        h = pin.nonLinearEffects(model, data, q, v)
        # axis (0,0,-1): gravity pulls along +q3, so holding needs tau3 = -m3 g
        assert abs(h[2] - (-m3 * g)) <= 1e-10


def test_cylindrical3_closed_form():
    """Full closed form of this particular model (urdf/cylindrical3.urdf header)."""
    model, data = load("cylindrical3.urdf")
    g = gravity_magnitude(model)
    c = CYL
    rng = np.random.default_rng(5)
    for _ in range(N_RANDOM):
        q = np.array([rng.uniform(-math.pi, math.pi), rng.uniform(-0.5, 0.5),
                      rng.uniform(-0.4, 1.2)])
        v = rng.uniform(-2.0, 2.0, 3)
        R2, R3 = c["r2"] + q[1], c["r3"] + q[1]
        H11 = c["Izz1"] + c["Izz2"] + c["Izz3"] + c["m2"] * R2 ** 2 + c["m3"] * R3 ** 2
        H_ref = np.diag([H11, c["m2"] + c["m3"], c["m3"]])
        np.testing.assert_allclose(mass_matrix(model, data, q), H_ref, rtol=0, atol=1e-10)
        k = c["m2"] * R2 + c["m3"] * R3
        h_ref = np.array([2 * k * v[0] * v[1], -k * v[0] ** 2, -c["m3"] * g])
        np.testing.assert_allclose(pin.nonLinearEffects(model, data, q, v), h_ref,
                                   rtol=0, atol=1e-10)
        tip_ref = np.array([R3 * math.cos(q[0]), R3 * math.sin(q[0]),
                            c["z_q1"] + c["z_arm"] - c["tool"] - q[2]])
        np.testing.assert_allclose(tip_position(model, data, q), tip_ref, rtol=0, atol=1e-12)


def test_cylindrical3_dz_dq3_is_minus_one():
    model, data = load("cylindrical3.urdf")
    fid = model.getFrameId("tip")
    q = np.array([0.4, 0.1, 0.3])
    J = pin.computeFrameJacobian(model, data, q, fid, pin.LOCAL_WORLD_ALIGNED)
    np.testing.assert_allclose(J[:3, 2], [0.0, 0.0, -1.0], rtol=0, atol=1e-12)


# --------------------------------------------------------------------------------------
# 5-DOF writer
# --------------------------------------------------------------------------------------

def pencil_task(model, data, q):
    """s = (x, y, z, theta, phi): pencil point and the pencil direction d (tip frame's
    local z axis, pointing to the paper) as the two tilt angles
    theta = atan2(d_x, -d_z), phi = atan2(d_y, -d_z) (regular near vertical)."""
    pin.framesForwardKinematics(model, data, q)
    M = data.oMf[model.getFrameId("tip")]
    d = M.rotation[:, 2]
    return np.concatenate([M.translation, [math.atan2(d[0], -d[2]), math.atan2(d[1], -d[2])]])


def pencil_task_jacobian(model, data, q):
    fid = model.getFrameId("tip")
    J = pin.computeFrameJacobian(model, data, q, fid, pin.LOCAL_WORLD_ALIGNED)
    pin.framesForwardKinematics(model, data, q)
    d = data.oMf[fid].rotation[:, 2]
    Jd = -pin.skew(d) @ J[3:]            # d_dot = omega x d
    dx, dy, dz = d
    Jth = (-dz * Jd[0] + dx * Jd[2]) / (dx ** 2 + dz ** 2)
    Jph = (-dz * Jd[1] + dy * Jd[2]) / (dy ** 2 + dz ** 2)
    return np.vstack([J[:3], Jth, Jph])


def test_writer5dof_nominal_pose():
    model, data = load("writer5dof.urdf")
    assert model.nq == 5 and model.nv == 5
    assert [model.names[i] for i in range(1, model.njoints)] == ["q1", "q2", "q3", "q4", "q5"]
    q = WRITER5_NOMINAL_Q
    assert np.all(q >= model.lowerPositionLimit) and np.all(q <= model.upperPositionLimit)
    pin.framesForwardKinematics(model, data, q)
    M = data.oMf[model.getFrameId("tip")]
    # pencil point on the table top z = 0 (urdf/README.md)
    assert abs(M.translation[2]) < 1e-9
    np.testing.assert_allclose(M.translation, [0.305707676520, 0.094566466132, 0.0],
                               rtol=0, atol=1e-9)
    # pencil (local z) points down, tilted 0.2 rad (<= 0.3) from the vertical
    tilt = math.acos(-M.rotation[2, 2])
    assert abs(tilt - 0.2) < 1e-9 and tilt <= 0.3


def test_writer5dof_task_jacobian_full_rank():
    model, data = load("writer5dof.urdf")
    q = WRITER5_NOMINAL_Q
    A = pencil_task_jacobian(model, data, q)
    # analytic Jacobian agrees with central finite differences of s(q)
    eps = 1e-6
    A_fd = np.column_stack([
        (pencil_task(model, data, q + eps * e) - pencil_task(model, data, q - eps * e)) / (2 * eps)
        for e in np.eye(5)])
    np.testing.assert_allclose(A, A_fd, rtol=0, atol=1e-8)
    sv = np.linalg.svd(A, compute_uv=False)
    assert np.linalg.matrix_rank(A) == 5
    assert sv.min() > 0.05 and sv.max() / sv.min() < 50.0, sv


def test_writer5dof_dynamics_consistent():
    model, data = load("writer5dof.urdf")
    rng = np.random.default_rng(6)
    for q, v in random_states(rng, 5):
        H = mass_matrix(model, data, q)
        assert np.linalg.eigvalsh(H).min() > 0.0
        # RNEA with zero acceleration = nonlinear effects; with a = e_i adds H[:, i]
        h = pin.nonLinearEffects(model, data, q, v).copy()
        a = rng.standard_normal(5)
        np.testing.assert_allclose(pin.rnea(model, data, q, v, a), H @ a + h, rtol=0, atol=1e-10)


# --------------------------------------------------------------------------------------
# All files: load, inertias, limits, tip frame
# --------------------------------------------------------------------------------------

def test_expected_files_present():
    assert EXPECTED <= set(ALL_URDFS)


@pytest.mark.parametrize("name", ALL_URDFS)
def test_loads_and_pinocchio_inertias_valid(name):
    model, data = load(name)
    assert model.nq == model.nv >= 1          # fixed base, no free-flyer
    assert model.existFrame("tip")
    assert model.frames[model.getFrameId("tip")].type in (pin.FrameType.BODY,)
    for i in range(1, model.njoints):
        Y = model.inertias[i]
        assert Y.mass > 0.0
        check_inertia_tensor(Y.inertia, f"{name}: body of joint {model.names[i]}")
    for i in range(1, model.njoints):
        jt = model.joints[i].shortname()
        assert "Unbounded" not in jt, f"{name}: {model.names[i]} is continuous"
    assert np.all(np.isfinite(model.lowerPositionLimit))
    assert np.all(np.isfinite(model.upperPositionLimit))
    assert np.all(model.lowerPositionLimit < model.upperPositionLimit)
    assert np.all(model.effortLimit > 0.0) and np.all(model.velocityLimit > 0.0)


@pytest.mark.parametrize("name", ALL_URDFS)
def test_urdf_xml_conventions(name):
    root = ET.parse(path(name)).getroot()
    links = {ln.get("name"): ln for ln in root.findall("link")}
    joints = {j.get("name"): j for j in root.findall("joint")}
    assert "base" in links
    # base is the root: never a child
    assert all(j.find("child").get("link") != "base" for j in joints.values())
    # massless tip link on a fixed tip_joint
    assert links["tip"].find("inertial") is None
    assert joints["tip_joint"].get("type") == "fixed"
    assert joints["tip_joint"].find("child").get("link") == "tip"
    for jname, j in joints.items():
        jtype = j.get("type")
        assert jtype in ("revolute", "prismatic", "fixed"), (jname, jtype)
        if jtype != "fixed":
            lim = j.find("limit")
            assert lim is not None, jname
            for key in ("lower", "upper", "effort", "velocity"):
                assert lim.get(key) is not None, (jname, key)
            assert float(lim.get("lower")) < float(lim.get("upper"))
            axis = np.array([float(x) for x in j.find("axis").get("xyz").split()])
            assert abs(np.linalg.norm(axis) - 1.0) < 1e-12
    for lname, ln in links.items():
        vis = ln.findall("visual")
        assert vis, f"{name}: link {lname} has no visual"
        for vv in vis:
            assert vv.find("material") is not None, f"{name}: {lname} visual has no material"
        if lname == "tip":
            continue
        inertial = ln.find("inertial")
        assert inertial is not None, f"{name}: link {lname} has no inertial"
        assert inertial.find("origin") is not None
        mass = float(inertial.find("mass").get("value"))
        assert mass > 0.0
        a = {k: float(v) for k, v in inertial.find("inertia").attrib.items()}
        I = np.array([[a["ixx"], a["ixy"], a["ixz"]],
                      [a["ixy"], a["iyy"], a["iyz"]],
                      [a["ixz"], a["iyz"], a["izz"]]])
        check_inertia_tensor(I, f"{name}: link {lname}")


def test_a_built_urdf_is_reused_until_its_file_changes(tmp_path, monkeypatch):
    """A process builds a URDF once per file content; every caller gets its own model."""
    import contactdyn.robot.urdf_model as urdf_model

    path = tmp_path / "arm.urdf"
    path.write_text(open(os.path.join(URDF_DIR, "planar2r_b1.urdf")).read())
    first = urdf_model.build_urdf_model(path)
    reads, check = [], urdf_model.check_urdf_tree
    monkeypatch.setattr(urdf_model, "check_urdf_tree", lambda p: reads.append(p) or check(p))
    second = urdf_model.build_urdf_model(path)
    assert reads == [] and second.xml == first.xml
    second.model.gravity.linear = np.array([0.0, 0.0, -1.0])  # a Robot sets its own gravity on its model
    assert first.model.gravity.linear[2] == pytest.approx(-9.81)
    path.write_text(path.read_text() + "\n")  # the file changed: read again
    urdf_model.build_urdf_model(path)
    assert reads == [path]


def test_the_process_keeps_the_latest_built_urdfs_only(tmp_path, monkeypatch):
    """A process that builds many robots (a sweep over URDFs) keeps the BUILT_MAX most recently used builds: the
    oldest is dropped and built again when asked for, one used since is kept."""
    import contactdyn.robot.urdf_model as urdf_model

    monkeypatch.setattr(urdf_model, "_BUILT", type(urdf_model._BUILT)())
    monkeypatch.setattr(urdf_model, "BUILT_MAX", 3)
    text = open(os.path.join(URDF_DIR, "planar2r_b1.urdf")).read()
    paths = []
    for k in range(5):
        paths.append(tmp_path / f"arm{k}.urdf")
        paths[-1].write_text(text + f"<!-- {k} -->\n")  # another content: another build
    for p in paths[:3]:
        urdf_model.build_urdf_model(p)
    urdf_model.build_urdf_model(paths[0])  # used again: the most recent
    for p in paths[3:]:
        urdf_model.build_urdf_model(p)
    assert len(urdf_model._BUILT) == 3
    kept = {os.path.basename(key[0]) for key in urdf_model._BUILT}
    assert kept == {"arm0.urdf", "arm3.urdf", "arm4.urdf"}
    reads, check = [], urdf_model.check_urdf_tree
    monkeypatch.setattr(urdf_model, "check_urdf_tree", lambda p: reads.append(p) or check(p))
    urdf_model.build_urdf_model(paths[1])  # dropped: built again (and arm0, now the oldest, dropped)
    urdf_model.build_urdf_model(paths[4])  # kept: not
    assert reads == [paths[1]]
