"""Dynamic control laws (A7, A10, hybrid) through DC motors: the transients they prescribe, exactly."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from contactdyn import Robot, SceneError, parse_scene, simulate
from contactdyn.laws.trajectory import Move, Ramp, Reference
from contactdyn.model.system import System

# case 2's writer and motors (sec. 5.2): N = 160 for speed, N* = 65.12 for torque
CASE2 = {"kind": "dc_motor", "R": 0.272, "C_M": 0.061, "J": 0.000452, "N": 160.0, "N_star": 65.12}
CASE3 = {"kind": "dc_motor", "R": 0.175, "C_M": 0.0575, "J": 7.9e-4, "N": 50.0, "wheel_radius": 0.15}
Q0 = np.array([0.3, 1.2])  # [rad] writer pose: tip at about (0.388, 0, 0.308)
KP, KV = 400.0, 40.0  # [1/s², 1/s]: η̈ = −K_p η − K_v η̇, a double root at −20 /s
KF = 20.0  # [1/s]


def tip0() -> np.ndarray:
    return Robot.load("writer2r").frame_position(Q0, "tip")


def critically_damped(eta0: np.ndarray, t: np.ndarray) -> np.ndarray:
    """η(t) of η̈ = −400 η − 40 η̇ from (η0, 0)."""
    return np.outer((1.0 + 20.0 * t) * np.exp(-20.0 * t), eta0)


def writer_doc(controller: dict, phase: dict, *, contact: dict | None = None, duration: float = 0.5,
               rtol: float = 1e-10) -> dict:
    doc = {"duration": duration, "solver": {"rtol": rtol, "atol": rtol * 1e-2, "output_rate": 500.0},
           "robot": {"urdf": "writer2r", "q0": Q0.tolist(), "drive": CASE2},  # gravity on
           "controller": controller, "phase": [{"name": "main", **phase}]}
    if contact is not None:
        doc["contact"] = {"c": contact}
    return doc


# ---- A7 ------------------------------------------------------------------------------------------
def test_position_law_in_joint_space_makes_the_error_obey_P():
    start, delta = np.array([0.35, 1.1]), np.array([0.2, -0.3])
    ref = {"space": "joint", "start": start.tolist(),
           "moves": [{"kind": "trapezoid", "delta": delta.tolist(), "duration": 0.4, "start": 0.05}]}
    ctl = {"kind": "position_dynamic", "space": "joint", "kp": KP, "kv": KV}
    r = simulate(parse_scene(writer_doc(ctl, {"reference": ref})))
    reference = Reference(start, (Move(delta, 0.05, 0.4, "trapezoid"),))
    eta = r["q"] - np.array([reference.at(t)[0] for t in r.t])
    assert np.max(np.abs(eta - critically_damped(Q0 - start, r.t))) <= 1e-6 * np.max(np.abs(Q0 - start))
    assert np.max(np.abs(r["u"])) > 1.0  # through the motors, not around them


@pytest.mark.parametrize("wall", [None, {"model": "c", "k": 1e4, "b": 10.0},
                                  {"model": "b", "k": 1e4, "b": 10.0, "m": 2.0, "bonded": True}])
def test_position_law_in_task_space_makes_the_error_obey_P_even_in_contact(wall):
    """The measured contact force is cancelled: also a bond's force, which only the linear solve knows."""
    p0 = tip0()
    start = p0 + np.array([0.002, 0.0, -0.008])
    ref = {"space": "task", "start": start.tolist(),
           "moves": [{"kind": "trapezoid", "delta": [0.004, 0.0, 0.05], "duration": 0.4, "start": 0.05}]}
    contact = None
    if wall is not None:  # a wall at the tip, normal −x; the reference pushes 2–6 mm into it
        bonded = wall.pop("bonded", False)
        contact = {"point": p0.tolist(), "bonded": bonded, "normal": {"direction": [-1, 0, 0], **wall}}
    ctl = {"kind": "position_dynamic", "space": "task", "kp": KP, "kv": KV}
    r = simulate(parse_scene(writer_doc(ctl, {"reference": ref}, contact=contact)))
    eta = r["tip"] - r["tip_ref"]
    assert np.max(np.abs(eta - critically_damped(p0 - start, r.t))) <= 1e-6 * np.max(np.abs(p0 - start))
    if wall is not None:
        assert r["contact.c.F_n"].max() > 20.0  # the wall really pushes back


def test_position_law_with_force_reference_presses_the_static_depth():
    """force_reference: along the normal the reference is the depth F_d/k the environment needs."""
    p0 = tip0()
    contact = {"point": p0.tolist(), "normal": {"direction": [0, 0, 1], "model": "c", "k": 1e4, "b": 50.0}}
    ctl = {"kind": "position_dynamic", "force_reference": True}
    phase = {"reference": {"start": p0.tolist(), "moves": []},
             "force": [{"contact": "c", "value": 50.0, "duration": 0.1}]}
    r = simulate(parse_scene(writer_doc(ctl, phase, contact=contact, duration=0.8)))
    assert r["contact.c.F_n"][-1] == pytest.approx(50.0, rel=1e-4)
    assert p0[2] - r["tip"][-1, 2] == pytest.approx(50.0 / 1e4, rel=1e-4)


# ---- A10 on case 3's axis ---------------------------------------------------------------------------
def axis_doc(normal: dict, force: dict, *, bonded: bool, nominal: dict | None = None, duration: float = 0.5,
             drive: dict = CASE3, **options) -> dict:
    ctl = {"kind": "force_dynamic", "kf": KF, **({"nominal": nominal} if nominal else {}), **options}
    return {"duration": duration, "solver": {"rtol": 1e-10, "atol": 1e-12, "output_rate": 1000.0},
            "robot": {"urdf": "cylindrical3", "active_joints": ["q3"], "gravity": [0, 0, 0], "q0": [1.0],
                      "drive": drive},
            "contact": {"tip": {"point": [1.0, 0.0, 0.2], "bonded": bonded,
                                "normal": {"direction": [0, 0, 1], **normal}}},
            "controller": ctl, "phase": [{"name": "press", "force": [{"contact": "tip", **force}]}]}


def test_force_law_with_exact_model_b_makes_F_equal_the_target():
    """Model (b): F = m s̈ + b ṡ + k s is algebraic in s̈, so F = F_d + ∫Q(μ) = F_d from the start."""
    ramp = {"value": 100.0, "kind": "linear", "duration": 0.1}  # case 3: 0 → 100 N in 0.1 s
    r = simulate(parse_scene(axis_doc({"model": "b", "k": 1e5, "b": 0.5, "m": 10.0}, ramp, bonded=True)))
    assert np.max(np.abs(r["contact.tip.F_n"] - r["contact.tip.F_d"])) <= 1e-6 * 100.0
    # the depth is then the surface's own, barely damped oscillator driven by F_d: m s̈ + b ṡ + k s = F_d(t)
    m, b, k = 10.0, 0.5, 1e5
    ramp_at = Ramp(100.0, 0.0, 0.1, "linear").at
    env = solve_ivp(lambda t, y: [y[1], (ramp_at(t)[0] - b * y[1] - k * y[0]) / m], (0.0, r.t[-1]), [0.0, 0.0],
                    t_eval=r.t, rtol=1e-12, atol=1e-15, method="DOP853", max_step=1e-3)
    depth = r["q"][:, 0] - 1.0
    assert np.max(np.abs(depth - env.y[0])) <= 1e-6 * np.max(np.abs(env.y[0]))
    assert np.ptp(depth[r.t > 0.3]) > 0.1 * 100.0 / k  # still ringing: A10 fixes F, not the position


def test_force_law_as_written_settles_the_force_through_the_integral_only():
    """A10 as written (τ = H q̈* + h − Jᵀ F*, F* = F_d + ∫Q): on a damped massless surface (c),
    F = k s + b ṡ, the gap e = F − F* obeys ė = −(b/m_r) e (m_r: link + reflected rotor, the
    rigid gear makes the model exact) and μ = e + ∫Q, ż = −K_F μ: from e(0) = μ(0) = −F_d,
    μ(t) = −F_d e^(−βt) + F_d K_F (e^(−βt) − e^(−K_F t)) / (K_F − β), β = b/m_r."""
    doc = axis_doc({"model": "c", "k": 1e5, "b": 1e3}, {"value": 100.0, "kind": "step"}, bonded=False)
    system = System(parse_scene(doc))
    system.robot.update(np.array([1.0]), np.zeros(1))
    beta = 1e3 / system.mass_matrix()[0, 0]  # [1/s]; m_r = 50 kg + N²J/r² = 137.8 kg
    r = simulate(parse_scene(doc))
    mu = r["contact.tip.F_n"] - 100.0
    closed = -100.0 * np.exp(-beta * r.t) + 100.0 * KF * (np.exp(-beta * r.t) - np.exp(-KF * r.t)) / (KF - beta)
    assert np.max(np.abs(mu - closed)) <= 1e-6 * 100.0
    assert np.max(np.abs(mu + 100.0 * np.exp(-KF * r.t))) > 10.0  # not the measured-force law's transient


def test_force_law_cancelling_the_measured_force_drives_the_error_at_the_rate_Q_prescribes():
    """cancel = "measured" (τ = H q̈* + h − Jᵀ F): model (c) with damping, relative degree one,
    μ̇ = −K_F μ from μ(0) = −F_d."""
    r = simulate(parse_scene(axis_doc({"model": "c", "k": 1e5, "b": 1e3}, {"value": 100.0, "kind": "step"},
                                      bonded=False, cancel="measured")))
    mu = r["contact.tip.F_n"] - 100.0
    assert np.max(np.abs(mu + 100.0 * np.exp(-KF * r.t))) <= 1e-6 * 100.0


@pytest.mark.parametrize("cancel", ["target", "measured"])
def test_force_law_link_inertia_reading_takes_the_rotor_out_of_H(cancel):
    """inertia = "link": the law multiplies by the link's 50 kg, not the rigid model's 137.8 kg.
    On model (c) with a massless nominal and the measured form, the robot then reaches only
    m_link/m_r of the commanded acceleration, so μ no longer follows e^(−K_F t); with the exact
    H it does (previous test). Both forms still settle F at F_d."""
    doc = axis_doc({"model": "c", "k": 1e5, "b": 1e3}, {"value": 100.0, "kind": "step"}, bonded=False,
                   cancel=cancel, inertia="link", duration=1.0)
    r = simulate(parse_scene(doc))
    mu = r["contact.tip.F_n"] - 100.0
    assert np.max(np.abs(mu + 100.0 * np.exp(-KF * r.t))) > 1.0
    assert abs(mu[-1]) < 1e-3 * 100.0


def test_force_law_with_a_mismatched_environment_completes_and_reports_its_errors():
    """Fig. 19's robustness study: the controller believes case 3's (b) surface, the true one is soft."""
    believed = {"k": 1e5, "b": 0.5, "m": 10.0}
    true = {"model": "b", "k": 1e3, "b": 0.0, "m": 5.0}  # m′ = 5 kg, k = 1e3 N/m, b = 0 (sec. 5.3)
    r = simulate(parse_scene(axis_doc(true, {"value": 100.0, "kind": "linear", "duration": 0.1}, bonded=True,
                                      nominal=believed, duration=1.0)))
    F, depth = r["contact.tip.F_n"], r["q"][:, 0] - 1.0
    force_error = F[-1] - 100.0  # [N]
    position_error = depth[-1] - 100.0 / believed["k"]  # [m] against the depth the model predicts
    print(f"\nmismatched A10 at t = 1 s: force error {force_error:.2f} N, position error {1e3 * position_error:.1f} mm,"
          f" min F {F.min():.2f} N")
    assert np.all(np.isfinite(F)) and r.t[-1] == pytest.approx(1.0)
    # the loop m̂ s⃛ + (b̂ + K_F m) s̈ + (k̂ + K_F b) ṡ + K_F k s = K_F F_d is stable but its slow pole is
    # ≈ −K_F k / k̂ = −0.2 /s: after 1 s the force is still far below F_d and the tip 17 mm deeper than predicted
    assert -100.0 < force_error < -50.0
    assert position_error > 0.01
    assert F[-1] > F[r.t >= 0.5][0] > F[r.t >= 0.3][0]  # the integral pulls F up


# ---- hybrid: position along the surface, force along its normal (case 2) -----------------------------
def hybrid_doc(nominal: dict | None = None, friction: float | None = None, cancel: str = "target") -> dict:
    p0 = tip0()
    contact = {"point": [0.0, 0.0, float(p0[2])], "bonded": True,  # the paper under the tip: case 2's (b) surface
               "normal": {"direction": [0, 0, 1], "model": "b", "k": 1e5, "b": 1.0, "m": 10.0}}
    if friction is not None:
        contact["tangent"] = {"model": "friction", "directions": [[1, 0, 0]], "mu": friction}
    ctl = {"kind": "hybrid", "kp": KP, "kv": KV, "kf": KF, "cancel": cancel,
           **({"nominal": nominal} if nominal else {})}
    phase = {"reference": {"start": p0.tolist(), "moves": [{"kind": "trapezoid", "delta": [-0.1, 0.0, 0.0],
                                                             "duration": 0.8, "accel_fraction": 0.2}]},
             "force": [{"contact": "c", "value": 100.0, "duration": 0.1}]}  # case 2: 100 N after 0.1 s
    doc = writer_doc(ctl, phase, contact=contact, duration=1.0, rtol=1e-9)
    doc["solver"]["output_rate"] = 200.0
    return doc


@pytest.mark.parametrize(("nominal", "cancel"), [(None, "target"), (None, "measured"),
                                                 ({"k": 1.2e5, "b": 1.0, "m": 10.0}, "measured")])
def test_hybrid_law_holds_100_N_while_tracking_a_tangential_path(nominal, cancel):
    r = simulate(parse_scene(hybrid_doc(nominal, cancel=cancel)))
    F = r["contact.c.F_n"]
    after = r.t > (0.1 if nominal is None else 0.7)  # the ramp, plus the integral's transient if mismatched
    assert np.max(np.abs(F[after] - 100.0)) <= 1.0  # 1 %
    x_err = r["tip"][:, 0] - r["tip_ref"][:, 0]
    assert np.max(np.abs(x_err)) <= 1e-8  # tangential error obeys P from η = 0: stays 0
    assert r["tip"][-1, 0] - r["tip"][0, 0] == pytest.approx(-0.1, abs=1e-8)


def test_hybrid_law_as_written_lets_a_nominal_mismatch_reach_the_tangent():
    """A10 as written pushes with F* = F_d + ∫Q, not the measured F: with a 20 % too stiff nominal
    F ≠ F* in the transient, and Jᵀ n (F − F*) moves the 2R arm's tip along x too (its inertia
    couples the directions), whereas cancelling the measured force keeps x_err at 0 (test above)."""
    r = simulate(parse_scene(hybrid_doc({"k": 1.2e5, "b": 1.0, "m": 10.0}, cancel="target")))
    F = r["contact.c.F_n"]
    assert np.max(np.abs(F[r.t > 0.7] - 100.0)) <= 1.0
    x_err = r["tip"][:, 0] - r["tip_ref"][:, 0]
    assert 1e-5 < np.max(np.abs(x_err)) < 5e-3  # [m]: disturbed, not lost


def test_hybrid_law_cancels_sliding_friction_too():
    """μ = 0.4: the friction force is measured (tilted bond column) and cancelled like the normal force."""
    r = simulate(parse_scene(hybrid_doc(friction=0.4)))
    assert np.max(np.abs(r["contact.c.F_f"][r.t > 0.1, 0])) == pytest.approx(40.0, rel=1e-6)
    assert np.max(np.abs(r["tip"][:, 0] - r["tip_ref"][:, 0])) <= 1e-8
    assert np.max(np.abs(r["contact.c.F_n"][r.t > 0.1] - 100.0)) <= 1e-6


def test_folded_forces_stay_consistent_when_voltages_clip():
    """A7 against a bonded (b) wall with a voltage limit: applied torque = eq. 51 at the clipped voltage."""
    p0 = tip0()
    contact = {"point": p0.tolist(), "bonded": True,
               "normal": {"direction": [-1, 0, 0], "model": "b", "k": 1e4, "b": 10.0, "m": 2.0}}
    ref = {"space": "task", "start": (p0 + [0.01, 0.0, -0.03]).tolist(), "moves": []}
    doc = writer_doc({"kind": "position_dynamic", "kp": KP, "kv": KV}, {"reference": ref}, contact=contact,
                     duration=0.3)
    u_max = 4.0
    doc["robot"]["drive"] = {**CASE2, "u_max": u_max}
    r = simulate(parse_scene(doc))
    u, v, tau = r["u"], r["v"], r["tau"]
    assert np.max(np.abs(u)) == pytest.approx(u_max) and np.mean(np.abs(u) == u_max) > 0.05
    nt, ns = CASE2["N_star"], CASE2["N"]
    expected = nt * CASE2["C_M"] / CASE2["R"] * (u - CASE2["C_M"] * ns * v)
    assert np.max(np.abs(tau - expected)) <= 1e-9 * np.max(np.abs(expected))
    free = np.abs(u) < u_max
    assert np.allclose(tau[free], r["tau_cmd"][free], rtol=1e-9, atol=1e-9)
    # once no joint clips, the error obeys P again: compare the late error with its own transient
    late = r.t > 0.25
    assert np.all(free[late]) and np.max(np.abs(r["tip"][late] - r["tip_ref"][late])) < 2e-3


# ---- scene errors ----------------------------------------------------------------------------------
def _error(doc: dict) -> SceneError:
    with pytest.raises(SceneError) as info:
        System(parse_scene(doc))
    return info.value


def test_controller_configuration_errors_name_the_key():
    force = {"value": 100.0}
    doc = axis_doc({"model": "b", "k": 1e5, "b": 0.5, "m": 10.0}, force, bonded=True)
    doc["phase"][0].pop("force")
    assert _error(doc).key == "phase[0].force"
    doc = axis_doc({"model": "a", "m": 10.0, "k_ext": 1e5, "k_int": 1e5}, force, bonded=False)
    assert _error(doc).key == "controller.nominal"  # (a) has no exact single-mass equivalent
    doc = axis_doc({"model": "b", "k": 1e5, "b": 0.5, "m": 10.0}, force, bonded=True, nominal={"k": 1e5})
    err = _error(doc)
    assert err.key == "controller.nominal.m" and "b > 0" in str(err)
    doc = axis_doc({"model": "b", "k": 1e5, "b": 0.5, "m": 10.0}, force, bonded=True)
    doc["controller"]["kp"] = 10.0  # a pure force law has no position gains
    assert _error(doc).key == "controller.kp"
    bad_axes = hybrid_doc()
    bad_axes["controller"]["axes"] = [[1.0, 0.0, 0.1]]
    err = _error(bad_axes)
    assert err.key == "controller.axes" and "orthogonal" in str(err)
    no_ref = hybrid_doc()
    no_ref["phase"][0].pop("reference")
    assert _error(no_ref).key == "phase[0].reference"
    gains = writer_doc({"kind": "position_dynamic", "space": "joint", "kp": [1.0, 2.0, 3.0]},
                       {"reference": {"space": "joint", "start": Q0.tolist(), "moves": []}})
    assert _error(gains).key == "controller.kp"
    task_gains = writer_doc({"kind": "position_dynamic", "space": "task", "kp": [1.0, 2.0]},
                            {"reference": {"start": tip0().tolist(), "moves": []}})
    err = _error(task_gains)  # (a SceneError naming the key, not numpy's broadcast error)
    assert err.key == "controller.kp" and "one gain or 3" in str(err)
    space = writer_doc({"kind": "position_dynamic", "space": "joint"},
                       {"reference": {"space": "task", "start": tip0().tolist(), "moves": []}})
    assert _error(space).key == "phase[0].reference.space"


@pytest.mark.parametrize("scene", ["b1_force_loop", "case1_cart", "case3_a_force", "case3_a_position",
                                   "force_loop_real_cell"])
def test_the_built_in_force_reading_laws_are_affine_in_the_forces_they_read(scene):
    """position_dynamic, force_dynamic and hybrid declare uses_forces: at each phase's sample input their command is
    finite and passes the check that refuses a user's law not affine in the forces it reads (the system runs it on the
    users' laws; the package's are affine by their construction)."""
    from contactdyn.laws.controllers.sampled import SampledController
    from contactdyn.laws.failures import checked_affine_in_forces
    from contactdyn.model.evaluation import sample_input
    from contactdyn.scene.scene_file import load_scene

    system = System(load_scene(scene))
    tried = []
    for spec, ctl in zip(system.scene.phases, system.controllers, strict=True):
        law = ctl.inner if isinstance(ctl, SampledController) else ctl
        if law.uses_forces:
            inp = sample_input(system, spec, law)
            assert np.all(np.isfinite(law.command(inp)[0])), law.name
            checked_affine_in_forces(law, inp)
            tried.append(law.name)
    assert tried
