"""The contact layer against closed forms: impacts, chains, rigid contact, energy, convergence."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.linalg import expm

import contactdyn
from contactdyn import Robot, SceneError, parse_scene, simulate
from contactdyn.scene.sanity import SanityWarning

TIGHT = {"rtol": 1e-12, "atol": 1e-14}

# The cylindrical robot reduced to its vertical axis: tip z = 1.2 − q3 [m], link mass 50 kg.
AXIS_MASS = 50.0  # [kg] urdf/cylindrical3.urdf, link 3
SURFACE_Z = 0.2  # [m] so that the tip touches at q3 = 1.0


def axis_scene(normal: dict, *, q0: float, v0: float, duration: float, gravity=(0.0, 0.0, 0.0),
               push: float | None = None, solver: dict | None = None) -> contactdyn.Scene:
    """1-DOF body (cylindrical robot's vertical axis) over a horizontal surface."""
    doc = {
        "duration": duration,
        "solver": {**TIGHT, "output_rate": 2000.0, **(solver or {})},
        "robot": {"urdf": "cylindrical3", "active_joints": ["q3"], "gravity": list(gravity), "q0": [q0],
                  "v0": [v0]},
        "contact": {"tip": {"point": [1.0, 0.0, SURFACE_Z], "normal": {"direction": [0, 0, 1], **normal}}},
        "controller": {"kind": "task_pd", "kp": 0.0, "kd": 0.0},
    }
    if push is not None:
        doc["phase"] = [{"name": "push", "force": [{"contact": "tip", "value": push, "kind": "step"}]}]
    return parse_scene(doc)


def linear_response(A: np.ndarray, B: np.ndarray, x0: np.ndarray, t: np.ndarray) -> np.ndarray:
    """x(t) of ẋ = A x + B (constant B) by the matrix exponential of the augmented system."""
    n = len(x0)
    Aug = np.zeros((n + 1, n + 1))
    Aug[:n, :n], Aug[:n, n] = A, B
    z0 = np.append(x0, 1.0)
    return np.array([(expm(Aug * tk) @ z0)[:n] for tk in t])


def test_impact_on_model_b_is_momentum_law_then_linear_motion():
    m_e, k, b, v = 10.0, 1e5, 0.5, 1.0  # case 3's environment (b); approach speed [m/s]
    scene = axis_scene({"model": "b", "k": k, "b": b, "m": m_e}, q0=0.9, v0=v, duration=0.15)
    r = simulate(scene)
    (imp,) = r.impacts
    assert imp["t"] == pytest.approx(0.1, abs=1e-12)
    v_plus = imp["v_after"][0]
    assert v_plus == pytest.approx(AXIS_MASS * v / (AXIS_MASS + m_e), rel=1e-12)  # eq. (58)
    assert imp["normal_impulse"] == pytest.approx(AXIS_MASS * m_e * v / (AXIS_MASS + m_e), rel=1e-12)
    # after impact: (m + m′) ÿ = −k y − b ẏ, y = q3 − 1 (downward deformation)
    M = AXIS_MASS + m_e
    A = np.array([[0.0, 1.0], [-k / M, -b / M]])
    sel = (r.t > imp["t"]) & (r["contact.tip.touching"] > 0)
    assert sel.sum() > 50
    y = linear_response(A, np.zeros(2), np.array([0.0, v_plus]), r.t[sel] - imp["t"])[:, 0]
    assert np.max(np.abs(r["q"][sel, 0] - 1.0 - y)) <= 1e-8 * np.max(np.abs(y))
    # the struck mass rides with the tip
    mass_x = next(v for key, v in r.channels.items() if key.startswith("mass.") and key.endswith(".x"))
    assert np.max(np.abs((SURFACE_Z - mass_x[sel]) - y)) <= 1e-8 * np.max(np.abs(y))


def test_model_a_chain_under_constant_force_matches_matrix_exponential():
    m_e, k1, b1, k2, b2, F = 10.0, 1e5, 1.0, 1e5, 0.5, 100.0  # case 3's environment (a), push [N]
    normal = {"model": "a", "m": m_e, "k_ext": k1, "b_ext": b1, "k_int": k2, "b_int": b2}
    # rtol 1e-13: the states are absolute positions (~1 m) and the deformations ~2 mm
    r = simulate(axis_scene(normal, q0=1.0, v0=0.0, duration=0.2, push=F, solver={"rtol": 1e-13, "atol": 1e-15}))
    assert not r.impacts and r["contact.tip.touching"].min() == 1.0  # continuous: no impact
    # X = [d_tip, ḋ_tip, d_m, ḋ_m], downward displacements from the surface
    m = AXIS_MASS
    A = np.array([
        [0, 1, 0, 0],
        [-k1 / m, -b1 / m, k1 / m, b1 / m],
        [0, 0, 0, 1],
        [k1 / m_e, b1 / m_e, -(k1 + k2) / m_e, -(b1 + b2) / m_e],
    ])
    B = np.array([0.0, F / m, 0.0, 0.0])
    X = linear_response(A, B, np.zeros(4), r.t)
    d_tip = r["q"][:, 0] - 1.0
    assert np.max(np.abs(d_tip - X[:, 0])) <= 1e-8 * np.max(np.abs(X[:, 0]))
    assert np.max(np.abs(r["v"][:, 0] - X[:, 1])) <= 1e-8 * np.max(np.abs(X[:, 1]))
    # the force is k′ times a difference of two displacements, 50x smaller than each: one digit less
    F_ext = k1 * (X[:, 0] - X[:, 2]) + b1 * (X[:, 1] - X[:, 3])
    assert np.max(np.abs(r["contact.tip.F_n"] - F_ext)) <= 1e-7 * np.max(np.abs(F_ext))
    # the external stage is env2 (counted from the environment body), the internal one env1
    assert np.max(np.abs(r["stage.tip.n.env1.x"] - X[:, 2])) <= 1e-8 * np.max(np.abs(X[:, 2]))


def test_rigid_contact_held_statically_balances_gravity():
    g = 9.81
    r = simulate(axis_scene({"model": "rigid"}, q0=1.0, v0=0.0, duration=1.0, gravity=(0, 0, -g)))
    assert np.max(np.abs(r["contact.tip.F_n"] - AXIS_MASS * g)) <= 1e-10 * AXIS_MASS * g
    assert np.max(np.abs(r["q"][:, 0] - 1.0)) <= 1e-12


def test_rigid_contact_with_stiction_balances_gravity_on_an_arm():
    robot = Robot.load("writer2r")
    q0 = np.array([0.6, 1.9])
    p = robot.frame_position(q0, "tip")
    doc = {
        "duration": 0.5,
        "solver": {**TIGHT, "output_rate": 200.0},
        "robot": {"urdf": "writer2r", "q0": q0.tolist()},
        "contact": {"tip": {"point": [0.0, 0.0, p[2]], "normal": {"direction": [0, 0, 1]}, "bonded": True,
                            "tangent": {"model": "friction", "directions": [[1, 0, 0]], "mu": 5.0}}},
        "controller": {"kind": "joint_pd", "kp": 0.0, "kd": 0.0},
    }
    r = simulate(parse_scene(doc))
    assert r["contact.tip.stuck"].min() == 1.0
    gravity = robot.gravity_torque(q0)
    J = robot.frame_jacobian(q0, "tip")[:3]
    for k in (0, len(r.t) // 2, -1):
        F = np.array([r["contact.tip.F_f"][k, 0], 0.0, r["contact.tip.F_n"][k]])  # force on the tip [N]
        assert np.allclose(J.T @ F, gravity, rtol=0, atol=1e-10 * np.abs(gravity).max())
    assert np.max(np.abs(r["q"] - q0)) <= 1e-12


def test_rigid_constraint_does_not_drift_over_a_long_run():
    robot = Robot.load("writer2r")
    q0 = np.array([0.5, 1.2])
    z_s = robot.frame_position(q0, "tip")[2]
    doc = {
        "duration": 10.0,
        "solver": {"rtol": 1e-8, "atol": 1e-10, "output_rate": 100.0},
        "robot": {"urdf": "writer2r", "q0": q0.tolist()},
        "contact": {"tip": {"point": [0, 0, z_s], "normal": {"direction": [0, 0, 1]}, "bonded": True}},
        "controller": {"kind": "joint_pd", "kp": 0.0, "kd": 0.0},
    }
    r = simulate(parse_scene(doc))  # the arm swings under gravity with its tip sliding on the line
    assert np.ptp(r["q"][:, 0]) > 0.1
    violation = np.abs(r["tip"][:, 2] - z_s)
    # Baumgarte keeps the violation at the integration error instead of letting it grow (6e-8 m without)
    assert violation.max() < 1e-8
    assert violation[-100:].max() <= 2 * violation[:100].max() + 1e-9


def test_bounce_separates_and_recontacts_on_a_massless_surface():
    # dropped on a stiff, lightly damped Kelvin–Voigt surface: it rebounds, flies and lands again
    r = simulate(axis_scene({"model": "c", "k": 1e5, "b": 50.0}, q0=0.95, v0=1.0, duration=0.6,
                            gravity=(0, 0, -9.81), solver={"rtol": 1e-9, "atol": 1e-12}))
    kinds = [e["kind"] for e in r.events if e["kind"] in ("touch", "separate")]
    assert kinds[:4] == ["touch", "separate", "touch", "separate"]
    free = r["contact.tip.touching"] == 0
    assert r["contact.tip.gap"][free].min() >= -1e-9  # no penetration while flying
    assert r["contact.tip.F_n"].min() >= -1e-6  # the surface never pulls


def test_case1_two_sided_chains_energy_budget_closes():
    """Kinetic + spring + gravity energy changes by drive work minus damper dissipation."""
    chain = {"environment": [{"k": 1e4, "b": 10.0}, {"m": 10.0}, {"k": 1e4, "b": 10.0}],
             "robot": [{"k": 1e4, "b": 10.0}, {"m": 10.0}, {"k": 1e4, "b": 10.0}]}
    robot = Robot.load("arm2r_cart", gravity_compensation=0.7)
    q0 = np.array([0.5, np.pi / 6])
    p = robot.frame_position(q0, "tip")
    doc = {
        "duration": 1.0,
        "solver": {"rtol": 1e-11, "atol": 1e-13, "output_rate": 500.0, "record_energy": True},
        "robot": {"urdf": "arm2r_cart", "gravity_compensation": 0.7, "q0": q0.tolist(), "v0": [0.1, -0.2]},
        "body": {"cart": {"mass": 100.0, "axis": [1, 0, 0], "velocity0": 0.25,
                          "servo": {"velocity": 0.25, "gain": 500.0}}},
        "contact": {"tip": {"body": "cart", "point": p.tolist(), "bonded": True,
                            "normal": {"direction": [0, 0, 1], **chain},
                            "tangent": {"model": "chain", "directions": [[1, 0, 0]], **chain}}},
        "controller": {"kind": "joint_pd", "kp": 2000.0, "kd": 100.0},
        "phase": [{"name": "hold", "reference": {"space": "joint", "start": q0.tolist()}}],
    }
    r = simulate(parse_scene(doc))
    kinetic = np.array([robot.kinetic_energy(q, v) for q, v in zip(r["q"], r["v"], strict=True)])
    kinetic += 0.5 * 100.0 * r["body.cart.v"] ** 2
    kinetic += sum(0.5 * 10.0 * r[k] ** 2 for k in r.channels if k.startswith("mass.") and k.endswith(".v"))
    springs = sum(0.5 * 1e4 * r[k] ** 2 for k in r.channels if k.startswith("stage.") and k.endswith(".x"))
    gravity = np.array([robot.potential_energy(q) for q in r["q"]])
    energy = kinetic + springs + gravity
    budget = r["energy.work"] - r["energy.dissipated"]
    scale = np.max(np.abs(r["energy.work"])) + np.max(np.abs(r["energy.dissipated"]))
    assert np.ptp(springs) > 1e-3  # the chains really work
    assert np.max(np.abs((energy - energy[0]) - budget)) <= 1e-6 * scale


def test_error_falls_with_tolerance_at_first_order_in_rtol():
    short = {"duration": 0.5, "solver.output_rate": 200.0}
    ref = simulate("b1", {**short, "solver.rtol": 1e-12, "solver.atol": 1e-14})
    errors = []
    for rtol in (1e-5, 1e-7, 1e-9):
        r = simulate("b1", {**short, "solver.rtol": rtol, "solver.atol": rtol * 1e-2})
        errors.append(np.max(np.abs(r["contact.tip.F_n"] - ref["contact.tip.F_n"])))
    slopes = np.diff(np.log10(errors)) / -2.0  # decades of error per decade of rtol
    assert errors[0] > errors[1] > errors[2]
    assert np.all((slopes > 0.6) & (slopes < 1.5)), (errors, slopes)


def test_a_tip_starting_inside_the_surface():
    """Inside a rigid surface: an error naming the contact and the gap. Inside a compliant one (model c):
    a sanity warning, and the run starts pressed, F_n = k d at rest (issue 16: such warnings are not fatal)."""
    with pytest.raises(SceneError, match=r"contact.tip: expected a start with the tip on or above the rigid surface"):
        simulate(axis_scene({"model": "rigid"}, q0=1.1, v0=0.0, duration=0.1))
    with pytest.warns(SanityWarning, match="m inside the surface"):
        r = simulate(axis_scene({"model": "c", "k": 1e5, "b": 1.0}, q0=1.1, v0=0.0, duration=0.1))
    depth = SURFACE_Z - r["tip"][0, 2]  # [m]
    assert depth > 1e-3 and r["contact.tip.touching"][0] == 1.0
    assert r["contact.tip.F_n"][0] == pytest.approx(1e5 * depth, rel=1e-9)  # [N]


def test_hunt_crossley_stage_settles_at_its_static_deflection_and_never_pulls():
    k, n, F = 1e7, 1.5, 100.0  # [N/m^1.5], exponent, push [N]
    stage = {"k": k, "b": 1e9, "law": "hunt_crossley", "exponent": n}  # b x^n ẋ: near-critical damping here
    r = simulate(axis_scene({"model": "chain", "environment": [stage]}, q0=1.0, v0=0.0, duration=0.5, push=F,
                            solver={"rtol": 1e-10, "atol": 1e-13}))
    assert r["q"][-1, 0] - 1.0 == pytest.approx((F / k) ** (1.0 / n), rel=1e-6)  # k xⁿ = F
    assert r["contact.tip.F_n"][-1] == pytest.approx(F, rel=1e-6)
    assert r["contact.tip.F_n"].min() >= 0.0


def _two_sided_junction_run(k1: float, b1: float, k2: float, b2: float, F: float):
    """The axis tip on a massless two-sided chain, body -[k1, b1]- junction -[k2, b2]- tip, pushed by F [N]."""
    normal = {"environment": [{"k": k1, "b": b1}], "robot": [{"k": k2, "b": b2}]}
    return simulate(axis_scene(normal, q0=1.0, v0=0.0, duration=0.05, push=F))


@pytest.mark.parametrize("b2", [20.0, 50.0])  # τ2 = τ1 = 1e-4 s (algebraic junction), or 2.5e-4 s (a state)
def test_two_sided_massless_chain_matches_matrix_exponential(b2):
    """The junction where the two sides' stages meet balances them, F1 = k1 d_j + b1 ḋ_j = F2 =
    k2 (d − d_j) + b2 (ḋ − ḋ_j) (d, d_j: tip and junction displacements into the body [m]). With one
    time constant b/k on both sides it is computed as the algebraic point where the springs balance
    (no state): the same motion as the first-order state it is with different time constants."""
    k1, b1, k2, F = 1e5, 10.0, 2e5, 100.0
    r = _two_sided_junction_run(k1, b1, k2, b2, F)
    assert r["contact.tip.touching"].min() == 1.0 and not r.impacts
    m = AXIS_MASS
    # X = [d, ḋ, d_j]: ḋ_j from the balance, m d̈ = F − F2
    jd = np.array([k2, b2, -(k1 + k2)]) / (b1 + b2)  # ḋ_j = jd · X
    A = np.array([[0.0, 1.0, 0.0], -(np.array([k2, b2, -k2]) - b2 * jd) / m, jd])
    X = linear_response(A, np.array([0.0, F / m, 0.0]), np.zeros(3), r.t)
    d = r["q"][:, 0] - 1.0
    assert np.max(np.abs(d - X[:, 0])) <= 1e-8 * np.max(np.abs(X[:, 0]))
    F1 = k1 * X[:, 2] + b1 * (A[2] @ X.T)
    assert np.max(np.abs(r["contact.tip.F_n"] - F1)) <= 1e-7 * np.max(np.abs(F1))
    assert np.max(np.abs(r["stage.tip.n.env1.x"] - X[:, 2])) <= 1e-8 * np.max(np.abs(X[:, 2]))


def test_a_junction_is_algebraic_only_with_one_time_constant():
    """chain.balanced: linear stages of one b/k (b = 0 included) keep a junction balanced; others do not."""
    from contactdyn.model.chain import ChainStage, balanced

    def stage(k, b, law="linear"):
        return ChainStage(0, 1, k, b, law)

    assert balanced([stage(1e5, 10.0), stage(2e5, 20.0)])
    assert balanced([stage(1e5, 0.0), stage(3e4, 0.0)])
    assert not balanced([stage(1e5, 10.0), stage(2e5, 50.0)])
    assert not balanced([stage(1e5, 10.0), stage(1e5, 10.0, "hunt_crossley")])
