"""Coulomb friction: true stick and slip, break-away, stopping, 2-D sliding, impacts with jamming.

Every closed form uses the point-mass test bodies (urdf/point_mass_x*.urdf: H = m I, the
tip is the mass, J̇q̇ = 0) on a rigid ground z = 0 with gravity, so the normal force is
m g exactly while resting or sliding, and the friction laws can be checked digit by digit.
"""

from __future__ import annotations

import copy
import math

import numpy as np
import pytest
from run_agreement import interpreted_evaluate

import contactdyn
from contactdyn import SceneError, parse_scene, simulate
from contactdyn.hybrid.pipeline_mode import mode_runner
from contactdyn.model.contact import ContactMode
from contactdyn.model.system import System
from contactdyn.robot.robot import Robot

M = 2.0  #: [kg] mass of the point-mass URDFs
G = 9.81  #: [m/s²]
W = M * G  #: [N] weight = normal force on the ground


def scene(dims: int = 1, mu_s: float = 0.5, mu_k: float = 0.4, duration: float = 1.0, **extra) -> dict:
    """A point mass on the ground z = 0, friction along x (1-D) or in the x-y plane (2-D)."""
    doc = {
        "name": f"friction{dims}d",
        "duration": duration,
        "solver": {"rtol": 1e-10, "atol": 1e-12, "output_rate": 200.0},
        "robot": {"urdf": "point_mass_xz" if dims == 1 else "point_mass_xyz", "q0": [0.0] * (dims + 1)},
        "contact": {"ground": {
            "point": [0.0, 0.0, 0.0], "normal": {"direction": [0.0, 0.0, 1.0]},
            "tangent": {"model": "friction", "directions": [[1.0, 0.0, 0.0]] if dims == 1 else
                        [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]], "mu_s": mu_s, "mu_k": mu_k},
        }},
        "controller": {"kind": "task_force"},
    }
    for key, value in extra.items():
        node = doc
        parts = key.split(".")
        for p in parts[:-1]:
            node = node.setdefault(p, {})
        node[parts[-1]] = value
    return doc


def run(doc: dict):
    return simulate(parse_scene(copy.deepcopy(doc)))


def events(result, kind: str) -> list[dict]:
    return [e for e in result.events if e["kind"] == kind]


def sliding(result) -> np.ndarray:
    return (result["contact.ground.touching"] == 1) & (result["contact.ground.stuck"] == 0)


# ---- the test bodies ---------------------------------------------------------------------
@pytest.mark.parametrize("name, nv", [("point_mass_xz", 2), ("point_mass_xyz", 3)])
def test_point_mass_urdfs_are_a_free_mass(name, nv):
    robot = Robot.load(name)
    q, v = np.array([0.3, -0.2, 0.1][:nv]), np.array([1.0, 2.0, -0.5][:nv])
    robot.update(q, v)
    assert robot.H == pytest.approx(M * np.eye(nv), abs=1e-14)
    assert robot.h == pytest.approx(np.r_[np.zeros(nv - 1), W], abs=1e-12)
    ft = robot.frame_terms(robot.frame_id("tip"))
    rows = [0, 2] if nv == 2 else [0, 1, 2]
    assert ft.position[rows] == pytest.approx(q, abs=1e-15)
    assert ft.jacobian[rows] == pytest.approx(np.eye(nv), abs=1e-15)
    assert ft.drift == pytest.approx(np.zeros(3), abs=1e-15)
    model = robot.model
    assert np.all(model.lowerPositionLimit < model.upperPositionLimit)
    assert [model.inertias[i].mass for i in range(1, model.njoints)] == [0.0] * (nv - 1) + [M]  # massless carriages


# ---- stick, then break away -----------------------------------------------------------------
@pytest.mark.parametrize("mu_s, mu_k, sign", [(0.5, 0.4, 1.0), (0.4, 0.4, 1.0), (0.5, 0.3, -1.0)])
def test_breakaway_at_the_closed_form_time(mu_s, mu_k, sign):
    """A push f = r t along ±x: stuck (x = 0, F_f = −f) until r t* = μ_s m g, then sliding."""
    rate = 20.0  # [N/s]
    t_star = mu_s * W / rate
    res = run(scene(mu_s=mu_s, mu_k=mu_k, **{"controller.rate": [sign * rate, 0.0, 0.0]}))
    slips = events(res, "slip")
    assert [e["kind"] for e in res.events] == ["stick", "slip"]
    assert abs(slips[0]["t"] - t_star) < 1e-8
    t, x, F_f = res.t, res["q"][:, 0], res["contact.ground.F_f"][:, 0]
    stuck = t < t_star
    assert np.all(res["contact.ground.stuck"][stuck] == 1) and np.all(res["contact.ground.stuck"][~stuck] == 0)
    assert np.max(np.abs(x[stuck])) < 1e-12
    assert F_f[stuck] == pytest.approx(-sign * rate * t[stuck], rel=1e-12, abs=1e-12)
    assert res["contact.ground.F_n"] == pytest.approx(W, rel=1e-12)
    # sliding where the push points; friction = −μ_k F sgn(v)
    after = ~stuck
    assert np.all(np.sign(res["v"][after][1:, 0]) == sign)
    assert F_f[after] == pytest.approx(-sign * mu_k * W, rel=1e-12)
    # x(t) = [r (t − t*)³/6 + (r t* − μ_k m g)(t − t*)²/2] / m after break-away
    s = t[after] - t_star
    x_exact = sign * (rate * s**3 / 6 + (rate * t_star - mu_k * W) * s**2 / 2) / M
    assert x[after] == pytest.approx(x_exact, rel=1e-8, abs=1e-12)


def test_kinetic_friction_exact_and_inside_the_cone():
    """A push 16 sin(2π t) N back and forth: |F_f| = μ_k F while sliding, |F_f| ≤ μ_s F always.

    The mass breaks away each time |push| reaches μ_s F (F = m g + 5 N), at
    t_k = asin(μ_s F / 16)/(2π) + k/2, slides, stops and sticks again. At the solver's
    default tolerance a step can span a whole excursion out of the cone while the state
    stands still; every break-away must still be found, at its closed-form time.
    """
    mu_s, mu_k, A = 0.6, 0.35, 16.0
    doc = scene(mu_s=mu_s, mu_k=mu_k, duration=3.0, **{
        "solver": {"rtol": 1e-8, "atol": 1e-10, "output_rate": 200.0},
        "controller.force": [0.0, 0.0, -5.0],  # pressing harder: F = m g + 5
        "controller.amplitude": [A, 0.0, 0.0], "controller.frequency": 1.0})
    res = run(doc)
    F_n, F_f = res["contact.ground.F_n"], res["contact.ground.F_f"][:, 0]
    assert F_n == pytest.approx(W + 5.0, rel=1e-12)
    t_slip = math.asin(mu_s * (W + 5.0) / A) / (2 * math.pi) + 0.5 * np.arange(6)
    assert np.array([e["t"] for e in events(res, "slip")]) == pytest.approx(t_slip, abs=1e-8)
    assert len(events(res, "stick")) == 6  # at the start, then after each stop but the last (t > 3 s)
    slide = sliding(res)
    assert slide.sum() > 100 and (~slide).sum() > 100  # both modes visited
    assert np.abs(F_f[slide]) == pytest.approx(mu_k * F_n[slide], rel=1e-12)
    assert np.all(np.abs(F_f) <= mu_s * F_n * (1 + 1e-9))


def test_no_hidden_regularisation_at_tiny_slip():
    """Sliding at 1e-7 m/s still gives the full μ_k F (no tanh(v/ε) in the right-hand side), 1-D and 2-D (the
    model as a run takes it: the compiled call)."""
    system = System(parse_scene(scene()))
    runner = mode_runner(system)
    x, _ = system.initial_state()
    phase = system.start_phase(0, 0.0, x, None)
    for v in (1e-7, -1e-7, 3.0):
        x[system.nQ] = v
        ev = runner([ContactMode(touching=True, slip=(math.copysign(1.0, v),))], phase).evaluation(0.0, x)
        assert ev.friction["ground"][0] == -math.copysign(0.4 * W, v)
        assert ev.xdot[system.nQ] == pytest.approx(-math.copysign(0.4 * G, v), rel=1e-14)
    system = System(parse_scene(scene(dims=2)))
    runner = mode_runner(system)
    x, _ = system.initial_state()
    phase = system.start_phase(0, 0.0, x, None)
    for v in (1e-7 * np.array([0.6, -0.8]), np.array([-2.0, 1.0])):
        x[system.nQ:system.nQ + 2] = v
        c45 = math.sqrt(0.5)
        u = v / np.linalg.norm(v)
        r = (c45 * (u[0] - u[1]), c45 * (u[0] + u[1]))  # a reference 45° off: the force follows v itself
        ev = runner([ContactMode(touching=True, slip=r)], phase).evaluation(0.0, x)
        assert ev.friction["ground"] == pytest.approx(-0.4 * W * v / np.linalg.norm(v), rel=1e-15, abs=1e-14)


# ---- a slide that stops -------------------------------------------------------------------
@pytest.mark.parametrize("push", [0.0, 0.3, 0.6])
def test_slide_stops_at_the_closed_form_time_and_position(push):
    """v0 = −3 m/s, push p m g along +x: stops at t1 = 3/((μ_k + p) g); sticks if p ≤ μ_s, else reverses."""
    mu_s, mu_k, v0 = 0.5, 0.4, -3.0
    doc = scene(mu_s=mu_s, mu_k=mu_k, duration=1.2, **{"robot.v0": [v0, 0.0],
                                                       "controller.force": [push * W, 0.0, 0.0]})
    res = run(doc)
    a = (mu_k + push) * G  # [m/s²] deceleration
    t1, x1 = -v0 / a, -v0**2 / (2 * a)
    stop = events(res, "stop")[0]
    assert abs(stop["t"] - t1) < 1e-8
    t, x, v = res.t, res["q"][:, 0], res["v"][:, 0]
    before, after = t < t1, t > t1
    assert x[before] == pytest.approx(v0 * t[before] + a * t[before]**2 / 2, rel=1e-9, abs=1e-10)
    if push <= mu_s:  # then stays stuck exactly where it stopped
        assert [e["kind"] for e in res.events] == ["stop", "stick"]
        assert np.all(res["contact.ground.stuck"][after] == 1)
        assert np.all(v[after] == 0.0)
        assert x[after] == pytest.approx(x1, abs=1e-9)
        assert res["contact.ground.F_f"][after, 0] == pytest.approx(-push * W, rel=1e-12)
    else:  # slides back: a = (p − μ_k) g from rest at x1
        assert [e["kind"] for e in res.events] == ["stop", "slip"]
        s = t[after] - t1
        assert x[after] == pytest.approx(x1 + (push - mu_k) * G * s**2 / 2, rel=1e-8, abs=1e-9)
        assert res["contact.ground.F_f"][after, 0] == pytest.approx(-mu_k * W, rel=1e-12)


def test_viscous_friction_stop_time():
    """m v̇ = −μ m g − c v: stops at t1 = (m/c) ln(1 + c v0 / (μ m g))."""
    mu, c, v0 = 0.3, 4.0, 2.5
    doc = scene(mu_s=mu, mu_k=mu, **{"robot.v0": [v0, 0.0], "contact.ground.tangent.viscous": c})
    res = run(doc)
    t1 = M / c * math.log(1 + c * v0 / (mu * W))
    assert abs(events(res, "stop")[0]["t"] - t1) < 1e-8
    slide = sliding(res)
    F_f, v = res["contact.ground.F_f"][:, 0], res["v"][:, 0]
    assert F_f[slide] == pytest.approx(-mu * W - c * v[slide], rel=1e-12)
    x1 = (M / c) * (v0 + mu * W / c) * (1 - math.exp(-c * t1 / M)) - mu * W / c * t1
    assert res["q"][-1, 0] == pytest.approx(x1, abs=1e-9)


# ---- 2-D sliding ----------------------------------------------------------------------------
def test_2d_friction_opposes_slip_round_a_circle():
    """A push P (cos ωt, sin ωt): steady circular sliding with F_f = −μ F v/|v| exactly.

    Balance: P cos α = μ m g, P sin α = m ω s (α: lag of v behind the push, s: speed).
    Starting on the steady velocity, the tip traces the circle of radius s/ω about
    c = (s/ω)(sin α, cos α).
    """
    mu, P, f = 0.4, 10.0, 1.0
    w = 2 * math.pi * f
    alpha = math.acos(mu * W / P)
    s = P * math.sin(alpha) / (M * w)
    doc = scene(dims=2, mu_s=mu, mu_k=mu, duration=1.5, **{
        "robot.v0": [s * math.cos(alpha), -s * math.sin(alpha), 0.0],
        "controller.amplitude": [P, P, 0.0], "controller.frequency": f,
        "controller.phase": [math.pi / 2, 0.0, 0.0]})
    res = run(doc)
    assert {e["kind"] for e in res.events} == {"turn"}  # never stops, never sticks
    assert len(res.events) == pytest.approx(1.5 * 360 / 60, abs=1)  # the reference refreshed every 60°
    F_f, vs = res["contact.ground.F_f"], res["contact.ground.v_slip"]
    unit_f = F_f / np.linalg.norm(F_f, axis=1)[:, None]
    unit_v = vs / np.linalg.norm(vs, axis=1)[:, None]
    assert np.max(np.linalg.norm(unit_f + unit_v, axis=1)) < 1e-12
    assert np.linalg.norm(F_f, axis=1) == pytest.approx(mu * W, rel=1e-12)
    t = res.t
    phase = w * t - alpha
    centre = s / w * np.array([math.sin(alpha), math.cos(alpha)])
    exact = centre + s / w * np.c_[np.sin(phase), -np.cos(phase)]
    assert np.max(np.linalg.norm(res["q"][:, :2] - exact, axis=1)) < 1e-8
    assert np.linalg.norm(vs, axis=1) == pytest.approx(s, rel=1e-8)


def test_2d_breakaway_direction_and_stop():
    """2-D: a push ramp along 30° breaks away at μ_s m g / r in that direction; a diagonal slide stops."""
    rate, th = 30.0, math.radians(30.0)
    u = np.array([math.cos(th), math.sin(th)])
    res = run(scene(dims=2, **{"controller.rate": [rate * u[0], rate * u[1], 0.0]}))
    t_star = 0.5 * W / rate
    assert abs(events(res, "slip")[0]["t"] - t_star) < 1e-8
    after = res.t > t_star
    v = res["v"][after][1:, :2]
    assert np.max(np.abs(v @ np.array([-u[1], u[0]])) / np.linalg.norm(v, axis=1)) < 1e-10  # along the push
    assert np.all(v @ u > 0)
    F_f, vs = res["contact.ground.F_f"][after][1:], res["contact.ground.v_slip"][after][1:]
    assert F_f == pytest.approx(-0.4 * W * vs / np.linalg.norm(vs, axis=1)[:, None], rel=1e-12, abs=1e-12)
    assert F_f == pytest.approx(np.tile(-0.4 * W * u, (len(F_f), 1)), rel=1e-9)  # v's direction: integrated
    # a slide along (0.6, 0.8) at 2 m/s stops after v0/(μ_k g), v0²/(2 μ_k g) away, and stays
    d = np.array([0.6, 0.8])
    res = run(scene(dims=2, **{"robot.v0": [1.2, 1.6, 0.0]}))
    t1 = 2.0 / (0.4 * G)
    assert abs(events(res, "stop")[0]["t"] - t1) < 1e-8
    assert [e["kind"] for e in res.events] == ["stop", "stick"]
    assert res["q"][-1, :2] == pytest.approx(d * 4.0 / (2 * 0.4 * G), abs=1e-9)
    assert np.all(res["v"][res.t > t1] == 0.0)


@pytest.mark.parametrize("mu_k", [0.3, 0.5])
def test_2d_breakaway_of_an_anisotropic_arm_slides_the_consistent_way(mu_k):
    """cylindrical3 on a table: tangential inertia 80 kg radially, 60.7 kg sideways.

    After break-away the tip slides along d with W(u − μ_k F d) ∥ d (W the tangential
    mobility J H⁻¹ Jᵀ, u the push): 48.2° for a push at 45° with μ_k = 0.3, not the push's
    direction. With μ_k = μ_s the push is just at the cone when it breaks away: the slip
    starts with zero acceleration and its direction relaxes at a rate ∝ 1/|v_t| (stiff);
    the run must stay cheap (launch segments go to LSODA) and on the consistent direction.
    """
    from scipy.optimize import brentq

    rate, mu_s = 500.0, 0.5
    doc = {"name": "cyl", "duration": 0.6, "solver": {"rtol": 1e-10, "atol": 1e-12, "output_rate": 1000.0},
           "robot": {"urdf": "cylindrical3", "q0": [0.0, 0.0, 1.0]},
           "contact": {"table": {"point": [0.0, 0.0, 0.2], "normal": {"direction": [0.0, 0.0, 1.0]},
                                 "tangent": {"model": "friction", "directions": [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]],
                                             "mu_s": mu_s, "mu_k": mu_k}}},
           "controller": {"kind": "task_force", "rate": [rate / math.sqrt(2), rate / math.sqrt(2), 0.0]}}
    res = run(doc)
    F = 50.0 * G  # the slide's weight presses on the table
    t_b = mu_s * F / rate
    assert abs(events(res, "slip")[0]["t"] - t_b) < 1e-8
    assert res.stats["rhs_evals"] < 2000
    robot = Robot.load("cylindrical3")
    q = np.array([0.0, 0.0, 1.0])
    robot.update(q, np.zeros(3))
    J = robot.frame_jacobian(q, robot.frame_id("tip"))[:2]
    Wt = J @ np.linalg.solve(robot.H, J.T)
    for k in (1, 3):
        i = np.searchsorted(res.t, t_b) + k
        u = rate * res.t[i] * np.array([1.0, 1.0]) / math.sqrt(2)

        def phi(th, u=u):
            d = np.array([math.cos(th), math.sin(th)])
            a = Wt @ (u - mu_k * F * d)
            return d[0] * a[1] - d[1] * a[0]

        th = brentq(phi, 0.2, 1.4)
        v = res["contact.table.v_slip"][i]
        assert math.degrees(abs(math.atan2(v[1], v[0]) - th)) < 0.02
        if mu_k < mu_s:
            assert abs(math.degrees(th) - 45.0) > 3.0  # not the push's direction


# ---- impacts with friction ----------------------------------------------------------------
def _drop(vx: float, vy: float = 0.0, mu: float = 0.4, h: float = 0.01, vz0: float = -1.0):
    """Drop the mass from height h with velocity (vx, vy, vz0); no push."""
    dims = 2 if vy else 1
    v0 = [vx, vy, vz0] if dims == 2 else [vx, vz0]
    q0 = [0.0] * dims + [h]
    res = run(scene(dims=dims, mu_s=mu, mu_k=mu, duration=0.2, **{"robot.q0": q0, "robot.v0": v0}))
    vz_touch = math.sqrt(vz0**2 + 2 * G * h)  # [m/s] downwards at touch
    return res, vz_touch


def test_sliding_impact_friction_impulse_is_mu_times_normal():
    res, vz = _drop(vx=2.0)
    (imp,) = res.impacts
    assert imp["normal_impulse"] == pytest.approx(M * vz, rel=1e-9)
    assert not imp["jammed"]
    assert imp["friction_impulse"][0] == pytest.approx(-0.4 * imp["normal_impulse"], rel=1e-12)
    assert imp["slip_before"][0] == pytest.approx(2.0, rel=1e-12)
    assert imp["slip_after"][0] == pytest.approx(2.0 - 0.4 * vz, rel=1e-9)
    # 2-D: the impulse opposes the slip direction it had before the impact
    res, vz = _drop(vx=1.5, vy=-2.0)
    (imp,) = res.impacts
    d = np.array([1.5, -2.0]) / 2.5
    assert imp["friction_impulse"] == pytest.approx(-0.4 * imp["normal_impulse"] * d, rel=1e-12)
    assert imp["slip_after"] == pytest.approx((2.5 - 0.4 * vz) * d, rel=1e-9)


def test_impact_jams_when_sliding_is_inconsistent():
    """vx = 0.1 < μ v_z: sliding would reverse the slip, so the tip jams (eqs 30–31) and stays."""
    res, vz = _drop(vx=0.1)
    (imp,) = res.impacts
    assert imp["jammed"]
    assert imp["normal_impulse"] == pytest.approx(M * vz, rel=1e-9)
    assert imp["friction_impulse"][0] == pytest.approx(-M * 0.1, rel=1e-12)  # takes all the momentum
    assert abs(imp["friction_impulse"][0]) <= 0.4 * imp["normal_impulse"]
    assert imp["slip_after"] == [0.0]
    t_imp = imp["t"]
    after = res.t > t_imp
    assert np.all(res["contact.ground.stuck"][after] == 1)
    assert np.all(res["v"][after, 0] == 0.0)
    assert res["q"][after, 0] == pytest.approx(0.1 * t_imp, rel=1e-9)


def test_robot_impact_obeys_the_momentum_law():
    """writer2r hitting a rigid table: H(q̇⁺ − q̇⁻) = (J_z − μ d J_x)ᵀ FΔt, J_z q̇⁺ = 0 (eqs 27–29), or jams.

    At q = (0.6, 1.2) the arm's inertia couples the normal and tangential directions:
    arriving at v_x = 0.8 m/s the tip slides on; at v_x = −0.1 sliding on would reverse
    the slip, so it jams (eqs 30–31); at v_x = −0.05 even holding it would need more than
    μ FΔt, so it slides the other way (d = +1, slip reversed by the impact).
    """
    doc = {"name": "writer_impact", "duration": 0.1,
           "robot": {"urdf": "writer2r", "q0": [0.6, 1.2]},
           "contact": {"table": {"point": [0.0, 0.0, 0.0], "normal": {"direction": [0.0, 0.0, 1.0]},
                                 "tangent": {"model": "friction", "directions": [[1.0, 0.0, 0.0]], "mu": 0.4}}},
           "controller": {"kind": "task_force"}}
    system = System(parse_scene(doc))
    robot = system.robot
    x, _ = system.initial_state()
    q = x[:2]
    c = system.contacts[0]
    J = robot.frame_jacobian(q, system.tip_fid)[:3]
    Jx, Jz = J[0], J[2]
    H = robot.mass_matrix(q)
    for vx, jam, d in ((0.8, False, 1.0), (-0.1, True, 0.0), (-0.05, False, 1.0)):
        qd = np.linalg.solve(J[[0, 2]], np.array([vx, -0.5]))
        x[system.nQ:2 * system.nQ] = qd
        x_new, imp = system.impact(0.0, x, [ContactMode(touching=True, slip=(math.copysign(1.0, vx),))], c)
        qp = x_new[system.nQ:2 * system.nQ]
        assert imp.jammed == jam
        assert abs(Jz @ qp) < 1e-12
        assert imp.normal_impulse > 0 and imp.energy_loss > 0
        if jam:
            assert abs(Jx @ qp) < 1e-12
            assert abs(imp.friction_impulse[0]) <= 0.4 * imp.normal_impulse
            assert H @ (qp - qd) == pytest.approx(Jz * imp.normal_impulse + Jx * imp.friction_impulse[0],
                                                  abs=1e-12)
        else:
            assert imp.direction[0] == d
            assert imp.friction_impulse[0] == pytest.approx(-0.4 * d * imp.normal_impulse, rel=1e-12)
            assert H @ (qp - qd) == pytest.approx((Jz - 0.4 * d * Jx) * imp.normal_impulse, abs=1e-12)
            assert (Jx @ qp) * d >= 0


# ---- chatter at the edge of the cone ----------------------------------------------------------
@pytest.mark.parametrize("compiled", [True, False])
def test_a_load_exactly_at_the_cone_edge_holds(compiled):
    """μ_s = 0.5 > μ_k: a push of exactly μ_s m g holds the mass at rest for the whole run, as |F_f| ≤ μ_s F says
    (before: the slip watch's value, exactly 0 at both ends of the first step, counted as a fall and the mass slid
    off at 0.196 m/s by 0.2 s); one part in 1e9 more breaks it away at once."""
    for push, held in ((0.5 * W, True), (0.5 * W * (1.0 + 1e-9), False)):
        doc = scene(mu_s=0.5, mu_k=0.4, duration=0.2, **{"controller.force": [push, 0.0, 0.0]})
        r = simulate(parse_scene(doc), compiled=compiled)
        if held:
            assert [e["kind"] for e in r.events] == ["stick"] and np.all(r["v"][:, 0] == 0.0)
        else:
            assert [(e["kind"], e["t"]) for e in r.events] == [("slip", 0.0)] and r["v"][-1, 0] > 0.1  # (at once)


@pytest.mark.parametrize("compiled", [True, False])
def test_a_push_past_the_cone_for_4_ms_between_two_stages_breaks_the_stick(compiled):
    """A mass stuck on the ground (nothing moves: its steps grow to ~0.1 s) pushed by F0 + A sin(π t), whose peak at
    0.5 s passes μ_s m g by 2e-5 of it for ~4 ms, between two stages of one step: found on the step's dense output
    (StageWatch.dips), it slips at the closed form's instant, asin((μ_s W − F0)/A)/π (before: stuck throughout)."""
    A = 10.0  # [N]
    F0 = 0.5 * W * (1.0 + 2e-5) - A  # [N]
    push = {"controller.force": [F0, 0.0, 0.0], "controller.amplitude": [A, 0.0, 0.0], "controller.frequency": 0.5}
    doc = scene(mu_s=0.5, mu_k=0.4, duration=1.0, **push)
    r = simulate(parse_scene(doc), compiled=compiled)
    assert [e["kind"] for e in r.events][:2] == ["stick", "slip"] and r.stats["dips_seen_inside_a_step"] == 1
    assert r.events[1]["t"] == pytest.approx(math.asin((0.5 * W - F0) / A) / math.pi, abs=1e-9)


@pytest.mark.parametrize("method", ["DOP853C", "RK45"])
def test_a_resting_contact_pulled_off_for_a_while_separates(method):
    """A mass at rest on a frictionless floor, lifted by W − A + 1 + A sin(2π t) [N] (A = 10 N): its normal force falls
    below zero for 0.14 s from asin(0.9) / 2π = 0.17822 s. Nothing moves before, so the steps grow past the pull:
    ``separate`` is watched at every stage (events.ValuesWatch) and located there, then the mass flies and lands
    (before: no event, the floor held it down for the whole pull)."""
    A = 10.0
    doc = scene(duration=0.6, **{"controller.force": [0.0, 0.0, W - A + 1.0], "controller.amplitude": [0.0, 0.0, A],
                                 "controller.frequency": 1.0})
    del doc["contact"]["ground"]["tangent"]
    r = simulate(parse_scene(doc), {"solver.method": method})
    assert [e["kind"] for e in r.events if not e["kind"].endswith("_check")] == ["separate", "touch"]
    assert r.events[0]["t"] == pytest.approx(math.asin(0.9) / (2.0 * math.pi), abs=1e-9)
    assert r["q"][:, -1].max() > 5e-3  # [m] it flew


def test_push_held_at_the_cone_edge_finishes_quietly():
    """μ_s = μ_k and a push that rises to exactly μ m g and stays: the marginal case.

    Sticking and sliding at zero acceleration are both solutions; without the stick band
    the run would switch stick ↔ slip at every step. The guard keeps a slide at v ≈ 0
    with |F_f| = μ F: a handful of events, the cone respected, the mass where it was.
    """
    mu, rate = 0.4, 20.0
    doc = scene(mu_s=mu, mu_k=mu, duration=1.0, **{
        "controller.rate": [rate, 0.0, 0.0], "controller.ramp_time": mu * W / rate})
    res = run(doc)
    assert len(res.events) <= 4
    F_f, F_n = res["contact.ground.F_f"][:, 0], res["contact.ground.F_n"]
    assert np.all(np.abs(F_f) <= mu * F_n * (1 + 1e-9))
    assert np.max(np.abs(res["q"][:, 0])) < 1e-9  # at most band × time


@pytest.mark.parametrize("amplitude", [1e-9, 1e-4])
def test_grazing_stick_slip_chatter_is_bounded(amplitude):
    """μ_s = μ_k = μ and a push μ m g + A sin ωt: every period the mass slips, and its slip
    speed A(1 − cos ωt)/(m ω) grazes zero at the cone's edge.

    Exact motion: x(t) = A/(m ω) (t − sin(ωt)/ω), whatever the mode at the grazing instants.
    With A = 1e-9 N the slip (≤ 2A/(m ω) ≈ 1.6e-11 m/s) never leaves the stick band: one
    slide for the whole run. With A = 1e-4 N (≤ 8e-7 m/s) each period stops, sticks and
    slips once (each dip of its speed through the band found, events.DipWatch). Never a storm; the cone holds;
    the position is exact, but for the creep the band holds still: at most v_ε per second stuck.
    """
    mu, f, T = 0.4, 20.0, 0.5
    w = 2 * math.pi * f
    doc = scene(mu_s=mu, mu_k=mu, duration=T, **{
        "controller.force": [mu * W, 0.0, 0.0],
        "controller.amplitude": [amplitude, 0.0, 0.0], "controller.frequency": f})
    res = run(doc)
    kinds = [e["kind"] for e in res.events]
    if amplitude < 1e-8:
        assert kinds == ["stick", "slip"]
    else:
        assert kinds.count("stop") == round(f * T) and len(kinds) <= 3 * f * T + 2
        ends = [e["t"] for e in res.events[1:]] + [T]
        stuck = sum(end - e["t"] for e, end in zip(res.events, ends, strict=True) if e["kind"] == "stick")  # [s]
        exact = amplitude * T / (M * w)
        assert abs(res["q"][-1, 0] - exact) <= 1e-9 * stuck + 1e-6 * exact  # (v_ε = 1e-9 m/s, the default)
    F_f, F_n = res["contact.ground.F_f"][:, 0], res["contact.ground.F_n"]
    assert np.all(np.abs(F_f) <= mu * F_n * (1 + 1e-9))


# ---- input errors -----------------------------------------------------------------------------
def test_bad_friction_inputs_name_the_key():
    with pytest.raises(SceneError, match="solver.stick_velocity"):
        parse_scene(scene(**{"solver.stick_velocity": -1.0}))
    with pytest.raises(SceneError, match="controller.rate"):
        parse_scene(scene(**{"controller.rate": [1.0, 2.0]}))
    with pytest.raises(SceneError, match="mu_s"):
        parse_scene(scene(mu_s=0.2, mu_k=0.4))
    assert "task_force" in contactdyn.laws.controllers.CONTROLLERS


def test_2d_coulomb_on_a_moving_body_compiled_equals_the_interpreted_call():
    """A compliant (chain) contact on a cart with 2-D friction: the compiled call's Coulomb force, its tip share
    and its reaction on the cart's row equal the interpreted call's (``interpreted_evaluate``) at slips in several
    directions, and the cart takes the reaction μ_k F_n d_x in closed form."""
    from contactdyn.model.pipeline.pipeline import Pipeline

    doc = scene(dims=2)
    doc["body"] = {"cart": {"mass": 5.0, "axis": [1.0, 0.0, 0.0]}}
    doc["contact"]["ground"].update(body="cart", normal={"direction": [0.0, 0.0, 1.0], "model": "chain",
                                                         "environment": [{"k": 1e6, "b": 2e3}]})
    system = System(parse_scene(doc))
    x0, _ = system.initial_state()
    phase = system.start_phase(0, 0.0, x0, None)
    modes = [ContactMode(touching=True, slip=(1.0, 0.0))]
    plan = Pipeline(system, modes, phase)
    assert system.nQ > system.nv  # the cart's coordinate: G's body columns are in play
    nQ, nv = system.nQ, system.nv
    got = {}
    for v in ([0.3, 0.0], [0.2, 0.5], [0.1, -0.4]):  # ahead of r = +x, each its own direction
        x = x0.copy()
        x[2] = -W / 1e6  # [m] pressed in: the compliant ground bears the weight
        x[nQ:nQ + 2] = v
        ref = interpreted_evaluate(system, 0.1, x, modes, phase).xdot
        got[tuple(v)] = out = plan.rhs(0.1, x.copy())
        assert np.abs(out - ref).max() <= 1e-10 * (1.0 + np.abs(ref).max())
    for v, xdot in got.items():  # the cart (5 kg, free along x) takes the reaction μ_k F_n d_x, F_n = W
        assert xdot[nQ + nv] == pytest.approx(0.4 * W * v[0] / math.hypot(*v) / 5.0, rel=1e-9)
