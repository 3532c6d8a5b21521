"""Drives against closed forms: DC motor, gear/wheel reflection, elastic transmission, limits, scene errors."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.linalg import expm

from contactdyn import SceneError, parse_scene, simulate
from contactdyn.laws.drives import DriveSpec
from contactdyn.model.system import System

TIGHT = {"rtol": 1e-12, "atol": 1e-14}
AXIS_MASS = 50.0  # [kg] cylindrical3's vertical slide (q3 down, tip z = 1.2 − q3)
SURFACE_Z = 0.2  # [m] the tip touches at q3 = 1.0
# case 3 (sec. 5.3): motor, harmonic drive, wheel; C_E = C_M in SI units
CASE3 = {"R": 0.175, "C_M": 0.0575, "J": 7.9e-4, "N": 50.0, "wheel_radius": 0.15}
TUBE = {"c": 14000.0, "d": 0.0196}
# case 2 (sec. 5.2): speed ratio 160, torque ratio 65.12
CASE2 = {"kind": "dc_motor", "R": 0.272, "C_M": 0.061, "J": 0.000452, "N": 160.0, "N_star": 65.12}


def axis_doc(drive: dict, *, q0: float = 1.0, duration: float = 0.3, controller: dict | None = None,
             contact: dict | None = None, solver: dict | None = None, joint: str = "q3") -> dict:
    doc = {
        "duration": duration,
        "solver": {**TIGHT, "output_rate": 1000.0, **(solver or {})},
        "robot": {"urdf": "cylindrical3", "active_joints": [joint], "gravity": [0.0, 0.0, 0.0], "q0": [q0],
                  "drive": drive},
        "controller": controller or {"kind": "voltage", "u": 5.0},
    }
    if contact is not None:
        doc["contact"] = {"tip": {"point": [1.0, 0.0, SURFACE_Z], **contact}}
    return doc


def linear_response(A: np.ndarray, B: np.ndarray, x0: np.ndarray, t: np.ndarray) -> np.ndarray:
    """x(t) of ẋ = A x + B (constant B) by the matrix exponential of the augmented system."""
    n = len(x0)
    aug = np.zeros((n + 1, n + 1))
    aug[:n, :n], aug[:n, n] = A, B
    return np.array([(expm(aug * tk) @ np.append(x0, 1.0))[:n] for tk in t])


# ---- DC motor through a rigid gear ----------------------------------------------------------
@pytest.mark.parametrize("joint, drive, inertia", [
    # prismatic axis through gear + wheel, N* ≠ N: reflected mass N N* J / r²
    ("q3", {**CASE3, "N_star": 40.0}, AXIS_MASS),
    # revolute base joint with case 2's lossy gear (H11 at q2 = 0, see urdf/README.md)
    ("q1", CASE2, 0.576 + 2.536 + 0.09 + 30 * 0.5**2 + 50 * 1.0**2),
])
def test_dc_motor_constant_voltage_reaches_no_load_speed_and_stall_torque(joint, drive, inertia):
    u = 24.0  # [V]
    R, C_M, J, N, N_star = drive["R"], drive["C_M"], drive["J"], drive["N"], drive["N_star"]
    rw = drive.get("wheel_radius", 1.0)
    ns, nt = N / rw, N_star / rw  # speed and torque ratios onto the coordinate
    spec = DriveSpec("dc_motor", R=R, C_M=C_M, C_E=C_M, J=J, N=N, N_star=N_star, wheel_radius=rw)
    assert spec.n_speed == pytest.approx(ns) and spec.n_torque == pytest.approx(nt)
    assert spec.reflected_inertia == pytest.approx(N * N_star * J / rw**2)
    stall = nt * C_M * u / R  # [N·m or N]: zero speed, full current u/R
    no_load = u / (C_M * ns)  # [rad/s or m/s]: back-EMF balances u (C_E = C_M)
    T = (inertia + ns * nt * J) * R / (nt * ns * C_M * C_M)  # mechanical time constant [s]
    doc = axis_doc({"kind": "dc_motor", **drive}, q0=0.0, duration=6.0 * T, joint=joint,
                   controller={"kind": "voltage", "u": u}, solver={"output_rate": 100.0})
    doc["robot"]["joint_limits"] = "ignore"  # the free spin passes q1's ±π limits: a motor test, not a limit test
    r = simulate(parse_scene(doc))
    assert r["tau"][0, 0] == pytest.approx(stall, rel=1e-12)
    assert r["u"][0, 0] == u
    v_exact = no_load * (1.0 - np.exp(-r.t / T))
    assert np.max(np.abs(r["v"][:, 0] - v_exact)) <= 1e-9 * no_load
    assert r["v"][-1, 0] == pytest.approx(no_load, rel=3e-3)  # e⁻⁶ after 6 T


def test_dc_motor_stalled_against_a_rigid_clamp_holds_the_stall_force():
    u = 12.0
    r = simulate(parse_scene(axis_doc({"kind": "dc_motor", **CASE3}, controller={"kind": "voltage", "u": u},
                                      contact={"bonded": True, "normal": {"direction": [0, 0, 1]}}, duration=0.05)))
    stall = CASE3["N"] / CASE3["wheel_radius"] * CASE3["C_M"] * u / CASE3["R"]  # [N]
    assert np.max(np.abs(r["v"])) < 1e-9
    assert np.max(np.abs(r["contact.tip.F_n"] - stall)) <= 1e-9 * stall


def test_voltage_limit_clips_and_the_clipped_voltage_acts():
    u_max = 6.0
    drive = {"kind": "dc_motor", **CASE3, "u_max": u_max}
    ctl = {"kind": "joint_pd", "kp": 2e5, "kd": 0.0}  # asks for far more than 6 V can give
    doc = axis_doc(drive, q0=0.0, controller=ctl, duration=0.3)
    doc["phase"] = [{"name": "go", "reference": {"space": "joint", "start": [0.2], "moves": []}}]
    r = simulate(parse_scene(doc))
    u, v, tau = r["u"][:, 0], r["v"][:, 0], r["tau"][:, 0]
    assert np.max(np.abs(u)) == pytest.approx(u_max, rel=1e-12)
    assert np.mean(np.abs(u) == u_max) > 0.2  # clipped for a good part of the move
    ns = nt = CASE3["N"] / CASE3["wheel_radius"]
    expected = nt * CASE3["C_M"] / CASE3["R"] * (u - CASE3["C_M"] * ns * v)  # eq. 51 at the clipped u
    assert np.max(np.abs(tau - expected)) <= 1e-9 * np.max(np.abs(expected))
    free = np.abs(u) < u_max
    assert np.allclose(tau[free], r["tau_cmd"][free, 0], rtol=1e-9, atol=1e-9)


# ---- the cart: motor through a wheel, velocity servo ----------------------------------------
def test_cart_motor_through_wheel_follows_the_servo_law_with_reflected_mass():
    m_e, gain, v_ref, r_w = 100.0, 2000.0, 0.25, 0.1  # case 1: 100 kg, wheel 0.1 m, no gear
    motor = {"kind": "dc_motor", "R": 1.3, "C_M": 0.5, "J": 0.00079, "wheel_radius": r_w}  # Table 1
    doc = {"duration": 0.5, "solver": {**TIGHT, "output_rate": 200.0},
           "robot": {"urdf": "writer2r", "gravity": [0.0, 0.0, 0.0], "q0": [0.3, 1.2]},
           "body": {"cart": {"mass": m_e, "servo": {"velocity": v_ref, "gain": gain}, "drive": motor}},
           "controller": {"kind": "joint_pd", "kp": 0.0, "kd": 0.0}}
    r = simulate(parse_scene(doc))
    m_tot = m_e + motor["J"] / r_w**2  # N = N* = 1 through the wheel
    v_exact = v_ref * (1.0 - np.exp(-gain * r.t / m_tot))
    v = r["body.cart.v"]
    assert np.max(np.abs(v - v_exact)) <= 1e-9
    F = gain * (v_ref - v)
    u_exact = motor["R"] * F * r_w / motor["C_M"] + motor["C_M"] * v / r_w  # eq. 51 inverted
    assert np.max(np.abs(r["body.cart.u"] - u_exact)) <= 1e-9
    assert "u" not in r.channels  # the robot joints have ideal drives


# ---- elastic transmission ----------------------------------------------------------------
def elastic_axis_matrices(u: float, env: dict) -> tuple[np.ndarray, np.ndarray]:
    """Eqs 53, 54, 59–61 written out: X = [y, ẏ, ϑ, ϑ̇, x″, ẋ″], y = q3 − 1, ϑ = θ − (N/r)·1."""
    R, C_M, J, N, r = (CASE3[k] for k in ("R", "C_M", "J", "N", "wheel_radius"))
    c, d, m = TUBE["c"], TUBE["d"], AXIS_MASS
    k1, b1, k2, b2, me = env["k_ext"], env["b_ext"], env["k_int"], env["b_int"], env["m"]
    A = np.zeros((6, 6))
    A[0, 1] = A[2, 3] = A[4, 5] = 1.0
    # link (54) with the contact force F = k′(y − x″) + b′(ẏ − ẋ″) (59, 61)
    A[1] = [-(c / r**2 + k1) / m, -(d / r**2 + b1) / m, c / (N * r) / m, d / (N * r) / m, k1 / m, b1 / m]
    # motor (53), C_E = C_M
    A[3] = [c / (N * r) / J, d / (N * r) / J, -c / N**2 / J, -(C_M * C_M / R + d / N**2) / J, 0.0, 0.0]
    # environment mass (60)
    A[5] = [k1 / me, b1 / me, 0.0, 0.0, -(k1 + k2) / me, -(b1 + b2) / me]
    B = np.zeros(6)
    B[3] = C_M / R * u / J
    return A, B


def test_elastic_axis_with_model_a_under_constant_voltage_is_the_linear_system():
    u = 5.0
    env = {"model": "a", "m": 10.0, "k_ext": 1e5, "b_ext": 1.0, "k_int": 1e5, "b_int": 0.5}  # case 3, env (a)
    doc = axis_doc({"kind": "elastic", **CASE3, **TUBE}, controller={"kind": "voltage", "u": u},
                   contact={"normal": {"direction": [0, 0, 1], **env}}, duration=0.25,
                   solver={"rtol": 1e-13, "atol": 1e-15})
    r = simulate(parse_scene(doc))
    assert r["contact.tip.touching"].min() == 1.0 and r["contact.tip.F_n"].min() >= -1e-9  # stays linear
    X = linear_response(*elastic_axis_matrices(u, env), np.zeros(6), r.t)
    N_r = CASE3["N"] / CASE3["wheel_radius"]
    for sim, exact in ((r["q"][:, 0] - 1.0, X[:, 0]), (r["v"][:, 0], X[:, 1]),
                       (r["drive.q3.theta"] - N_r, X[:, 2]), (r["drive.q3.omega"], X[:, 3])):
        assert np.max(np.abs(sim - exact)) <= 1e-8 * np.max(np.abs(exact))
    F = 1e5 * (X[:, 0] - X[:, 4]) + 1.0 * (X[:, 1] - X[:, 5])
    assert np.max(np.abs(r["contact.tip.F_n"] - F)) <= 1e-8 * np.max(np.abs(F))


@pytest.mark.parametrize("g", [0.0, 0.05])
def test_clamped_transmission_rings_at_the_torsional_frequency(g):
    """Link clamped: J ϑ̈ + (C_M C_E/R + d/N² + g) ϑ̇ + (c/N²) ϑ = M₀, a step response in closed form.

    g = 0: constant voltage u (the back-EMF damps θ̇). g > 0: a constant torque command
    τ (a clamped joint under a PD); the drive inverts at the clamped link's speed 0, so the
    back-EMF still damps θ̇, and twist_damping g adds its own damping.
    """
    drive = {"kind": "elastic", **CASE3, **TUBE, "twist_damping": g}
    J, R, C_M, N, r_w = CASE3["J"], CASE3["R"], CASE3["C_M"], CASE3["N"], CASE3["wheel_radius"]
    if g == 0.0:
        u = 5.0
        ctl, phase, M0 = {"kind": "voltage", "u": u}, {}, C_M * u / R  # [N·m]
    else:
        tau = 500.0  # [N] = kp × 0.01 m
        ctl = {"kind": "joint_pd", "kp": tau / 0.01, "kd": 0.0}
        phase = {"reference": {"space": "joint", "start": [1.01], "moves": []}}
        M0 = tau * r_w / N
    doc = axis_doc(drive, controller=ctl, duration=0.5, solver={"output_rate": 4000.0},
                   contact={"bonded": True, "normal": {"direction": [0, 0, 1]}})  # the link is clamped
    if phase:
        doc["phase"] = [{"name": "hold", **phase}]
    r = simulate(parse_scene(doc))
    s = DriveSpec("elastic", **CASE3, C_E=C_M, **TUBE)
    k_t = TUBE["c"] / N**2  # tube stiffness seen by the motor [N·m/rad]
    w0 = np.sqrt(k_t / J)
    assert s.natural_frequency == pytest.approx(w0)
    zeta = (C_M * C_M / R + TUBE["d"] / N**2 + g) / (2.0 * np.sqrt(k_t * J))  # back-EMF, tube, active damping
    wd = w0 * np.sqrt(1.0 - zeta**2)
    theta_eq = M0 / k_t  # static twist × N [rad]
    e = r["drive.q3.theta"] - N / r_w - theta_eq
    i = np.nonzero(np.sign(e[:-1]) != np.sign(e[1:]))[0]
    crossings = r.t[i] - e[i] * (r.t[i + 1] - r.t[i]) / (e[i + 1] - e[i])
    # only where the ringing (envelope θ_eq e^(−ζ ω₀ t)) stands above round-off: θ ≈ 333 rad carries
    # ~1e-13 rad of it, which moves a crossing of a 1e-10 rad ringing by ~1e-3 of its period
    crossings = crossings[np.exp(-zeta * w0 * crossings) > 1e-7]
    assert len(crossings) >= 6
    # zero crossings, linearly interpolated at 4 kHz: 7e-8 at g = 0, 7e-6 with the stronger damping
    assert np.pi / np.mean(np.diff(crossings)) == pytest.approx(wd, rel=2e-5)  # g = 0: 84.19 → 83.34 rad/s
    sig = zeta * w0
    exact = theta_eq * (1.0 - np.exp(-sig * r.t) * (np.cos(wd * r.t) + sig / wd * np.sin(wd * r.t)))
    assert np.max(np.abs(e + theta_eq - exact)) <= 1e-9 * theta_eq
    assert np.max(np.abs(r["v"])) < 1e-9


def test_elastic_transmission_tends_to_the_rigid_gear_as_the_tube_stiffens():
    u = 5.0
    rigid = simulate(parse_scene(axis_doc({"kind": "dc_motor", **CASE3}, q0=0.0, duration=0.1,
                                          controller={"kind": "voltage", "u": u}, solver={"rtol": 1e-10})))
    errors = []
    for c in (1e4, 1e5, 1e6):
        d = 2.0 * np.sqrt(c / CASE3["N"] ** 2 * CASE3["J"]) * CASE3["N"] ** 2  # tube damping ratio 1
        el = simulate(parse_scene(axis_doc({"kind": "elastic", **CASE3, "c": c, "d": d}, q0=0.0, duration=0.1,
                                           controller={"kind": "voltage", "u": u}, solver={"rtol": 1e-10})))
        errors.append(np.max(np.abs(el["q"][:, 0] - rigid["q"][:, 0])))
    assert errors[0] > errors[1] > errors[2]
    assert errors[2] < 1e-3 * np.max(np.abs(rigid["q"][:, 0]))


def test_elastic_drive_energy_audit_balances():
    """Clamped: ∫M θ̇ dt − ∫d φ̇² dt = ½ J θ̇² + ½ c φ² (the back-EMF loss is inside M)."""
    drive = {"kind": "elastic", **CASE3, **TUBE}
    doc = axis_doc(drive, controller={"kind": "voltage", "u": 5.0}, duration=0.2,
                   contact={"bonded": True, "normal": {"direction": [0, 0, 1]}}, solver={"record_energy": True})
    r = simulate(parse_scene(doc))
    N_r = CASE3["N"] / CASE3["wheel_radius"]
    twist = (r["drive.q3.theta"] - N_r) / CASE3["N"]
    stored = 0.5 * CASE3["J"] * r["drive.q3.omega"] ** 2 + 0.5 * TUBE["c"] * twist**2  # [J]
    balance = r["energy.work"] - r["energy.dissipated"] - stored
    assert np.max(np.abs(balance)) <= 1e-8 * np.max(stored)


# ---- impacts with drives -------------------------------------------------------------------
@pytest.mark.parametrize("kind", ["dc_motor", "elastic"])
def test_impact_momentum_law_with_drives(kind):
    """Rigid gear: the rotor joins the impact, (m + D) v⁻ = (m + D + m′) v⁺. Elastic: eq. 58, motor unaffected."""
    m_e, v0 = 10.0, 1.0
    drive = {"kind": kind, **CASE3, **(TUBE if kind == "elastic" else {})}
    doc = axis_doc(drive, q0=0.95, duration=0.06, controller={"kind": "joint_pd", "kp": 0.0, "kd": 0.0},
                   contact={"normal": {"direction": [0, 0, 1], "model": "b", "k": 1e5, "b": 0.5, "m": m_e}})
    doc["robot"]["v0"] = [v0]
    r = simulate(parse_scene(doc))
    (imp,) = r.impacts
    v_minus, v_plus = imp["v_before"][0], imp["v_after"][0]
    D = (CASE3["N"] / CASE3["wheel_radius"]) ** 2 * CASE3["J"] if kind == "dc_motor" else 0.0
    m = AXIS_MASS + D
    assert v_plus == pytest.approx(m * v_minus / (m + m_e), rel=1e-12)
    if kind == "elastic":
        i_motor = len(imp["v_before"]) - 1  # motor angle: the last coordinate
        assert imp["v_after"][i_motor] == imp["v_before"][i_motor]


# ---- scene validation --------------------------------------------------------------------
def _error(doc: dict) -> SceneError:
    with pytest.raises(SceneError) as info:
        System(parse_scene(doc))
    return info.value


@pytest.mark.parametrize("drive, key, words", [
    ({"kind": "dc_motor", **CASE3, "Kt": 1.0}, "robot.drive.Kt", "known key"),
    ({"kind": "dc_mottor", **CASE3}, "robot.drive.kind", "dc_motor"),
    ({"kind": "dc_motor", "C_M": 0.1, "J": 1e-4}, "robot.drive.R", "required"),
    ({"kind": "elastic", **CASE3, "c": 1e4, "N_star": 20.0}, "robot.drive.N_star", "one ratio"),
    ({"kind": "elastic", **CASE3}, "robot.drive.c", "required"),
    ({"kind": "dc_motor", **CASE3, "R": -1.0}, "robot.drive.R", "> 0"),
    ({"kind": "dc_motor", **CASE3, "u_max": [1.0, 2.0]}, "robot.drive.u_max", "one value or 1"),
    ({"kind": ["dc_motor", "torque"], **CASE3}, "robot.drive.kind", "one value or 1"),
])
def test_bad_drive_tables_name_the_key(drive, key, words):
    err = _error(axis_doc(drive))
    assert err.key == key and words in str(err)


def test_bad_body_drive_and_voltage_without_motor():
    doc = {"duration": 0.1, "robot": {"urdf": "writer2r", "q0": [0.3, 1.2]},
           "body": {"cart": {"mass": 100.0, "drive": {"kind": "dc_motor", "R": [1.0, 2.0], "C_M": 0.5, "J": 1e-3}}},
           "controller": {"kind": "joint_pd"}}
    err = _error(doc)
    assert err.key == "body.cart.drive.R" and "a number" in str(err)
    err = _error(axis_doc({"kind": "torque"}, controller={"kind": "voltage", "u": 3.0}))
    assert err.key == "controller.kind" and "q3" in str(err)


def test_mixed_drives_per_joint():
    doc = {"duration": 0.05, "solver": {"output_rate": 100.0},
           "robot": {"urdf": "cylindrical3", "active_joints": ["q2", "q3"], "gravity": [0, 0, 0], "q0": [0.0, 0.5],
                     "drive": {"kind": ["torque", "elastic"], **CASE3, **TUBE, "N": [1.0, 50.0]}},
           "controller": {"kind": "joint_pd", "kp": 100.0, "kd": 10.0}}
    system = System(parse_scene(doc))
    assert [s.kind for s in system.drives.specs] == ["torque", "elastic"]
    assert system.nQ == 3  # q2, q3 and one motor angle
    r = simulate(parse_scene(doc))
    assert np.isnan(r["u"][:, 0]).all() and np.isfinite(r["u"][:, 1]).all()
    assert "drive.q3.theta" in r.channels and "drive.q2.theta" not in r.channels


def test_stiff_pd_approach_through_the_elastic_transmission_tracks_like_the_rigid_gear():
    """Case 3's approach: a PD that ignores the elasticity. The drive inverts eq. 51 at the link's speed, so
    the back-EMF keeps damping the twist (inverting at the measured θ̇ would cancel it: this diverged)."""
    ref = {"space": "joint", "start": [0.0],
           "moves": [{"kind": "trapezoid", "delta": [1.0], "duration": 1.0, "accel_fraction": 0.2}]}
    errors = {}
    for kind in ("dc_motor", "elastic"):
        drive = {"kind": kind, **CASE3, **(TUBE if kind == "elastic" else {})}
        doc = axis_doc(drive, q0=0.0, duration=1.0, controller={"kind": "joint_pd", "kp": 3e4, "kd": 3e3},
                       solver={"rtol": 1e-8, "atol": 1e-10, "output_rate": 200.0})
        doc["phase"] = [{"name": "approach", "reference": ref}]
        r = simulate(parse_scene(doc))
        errors[kind] = np.max(np.abs(r["q"][:, 0] - r["q"][0, 0] - _trapezoid(r.t)))
    assert errors["dc_motor"] == pytest.approx(0.027, rel=0.05)  # [m] the PD's own lag
    assert errors["elastic"] == pytest.approx(errors["dc_motor"], rel=0.05)


def _trapezoid(t: np.ndarray) -> np.ndarray:
    from contactdyn.laws.trajectory import profile

    return np.array([profile("trapezoid", tk, 0.2)[0] for tk in t])
