"""Joint limits (contactdyn.model.limits): a position limit is a unilateral constraint located, impacted
plastically, held while the joint presses and released when its torque vanishes."""

from __future__ import annotations

import math
import re
from pathlib import Path

import numpy as np
import pytest
from scipy.special import ellipk, ellipkinc

from contactdyn import simulate
from contactdyn.errors import SceneError
from contactdyn.model.impact import limit_impact
from contactdyn.model.paths import PIPELINE
from contactdyn.model.system import System
from contactdyn.robot.robot import Robot
from contactdyn.scene.scene_file import parse_scene

M, L, G = 2.0, 0.5, 9.81  #: point mass [kg] on a massless rod [m], gravity [m/s²]
LOWER, UPPER, THETA0 = 1.0, 3.0, 2.5  #: [rad] limits; start at rest near the top

PENDULUM = f"""<?xml version="1.0"?>
<robot name="pendulum">
  <link name="base"/>
  <joint name="swing" type="revolute"><parent link="base"/><child link="bob"/><axis xyz="0 1 0"/>
    <limit lower="{LOWER}" upper="{UPPER}" effort="{{effort}}" velocity="{{velocity}}"/></joint>
  <link name="bob"><inertial><origin xyz="0 0 {-L}"/><mass value="{M}"/>
    <inertia ixx="0" iyy="0" izz="0" ixy="0" ixz="0" iyz="0"/></inertial></link>
  <joint name="tip_joint" type="fixed"><parent link="bob"/><child link="tip"/><origin xyz="0 0 {-L}"/></joint>
  <link name="tip"/>
</robot>
"""


def pendulum(tmp_path, effort: float = 0.0, velocity: float = 0.0, **robot):
    path = tmp_path / "pendulum.urdf"
    path.write_text(PENDULUM.format(effort=effort, velocity=velocity))
    doc = {"duration": 1.2, "solver": {"rtol": 1e-10, "atol": 1e-12, "output_rate": 500.0},
           "robot": {"urdf": str(path), "q0": [THETA0], **robot}}
    return parse_scene(doc)


def impact_time() -> float:
    """Released at rest from θ0, the pendulum (θ̈ = −g/l sin θ) reaches θ1 after
    √(l/g)·[K(k) − F(φ1, k)], k = sin(θ0/2), sin φ1 = sin(θ1/2)/k (elliptic integrals)."""
    k = math.sin(THETA0 / 2)
    phi = math.asin(math.sin(LOWER / 2) / k)
    return math.sqrt(L / G) * (ellipk(k * k) - ellipkinc(phi, k * k))


def test_pendulum_falls_onto_its_limit_closed_form(tmp_path):
    r = simulate(pendulum(tmp_path))
    hits = [e for e in r.events if e["kind"] == "limit"]
    assert len(hits) == 1 and hits[0]["joint"] == "swing" and hits[0]["side"] == "lower"
    assert hits[0]["t"] == pytest.approx(impact_time(), abs=1e-9)  # [s]
    v_hit = -math.sqrt(2 * G / L * (math.cos(LOWER) - math.cos(THETA0)))  # [rad/s] energy conservation
    assert hits[0]["velocity_before"] == pytest.approx(v_hit, rel=1e-8)
    assert hits[0]["impulse"] == pytest.approx(-M * L * L * v_hit, rel=1e-8)  # plastic: all momentum taken
    assert not [e for e in r.events if e["kind"] == "release"]  # gravity keeps it pressing
    assert r.stats["compiled_modes"] == 2  # free, then pressing: compiled
    after = r.t > hits[0]["t"] + 1e-3
    # the velocity is zeroed and stays so: what remains is the solver's absolute tolerance (atol 1e-12 per
    # step, over ~400 steps) and the Baumgarte return from the event's 1e-13 rad overshoot
    np.testing.assert_allclose(r["v"][after, 0], 0.0, atol=1e-10)
    np.testing.assert_allclose(r["q"][after, 0], LOWER, atol=1e-12)
    assert np.all(r["limit.side"][after, 0] == 1.0) and np.all(r["limit.side"][~(r.t >= hits[0]["t"]), 0] == 0.0)
    # the holding torque is the gravity torque m g l sin(θ1)
    np.testing.assert_allclose(r["limit.torque"][after, 0], M * G * L * math.sin(LOWER), rtol=0, atol=1e-9)
    np.testing.assert_allclose(r["limit.torque"][r.t < hits[0]["t"], 0], 0.0)


def test_ignored_limits_let_the_pendulum_swing_through(tmp_path):
    r = simulate(pendulum(tmp_path, joint_limits="ignore"))
    assert not [e for e in r.events if e["kind"] == "limit"] and "limit.torque" not in r.channels
    assert r["q"][:, 0].min() < 0.0  # it swings through the bottom


def test_velocity_and_effort_limits_are_reported(tmp_path, capsys):
    from contactdyn.cli import main

    r = simulate(pendulum(tmp_path, velocity=1.0, joint_limits="ignore"))
    report = r.stats["limits"]["velocity.swing"]
    over = np.flatnonzero(np.abs(r["v"][:, 0]) > 1.0)
    assert report["samples"] == len(over) and report["first_t"] == r.t[over[0]] and report["limit"] == 1.0
    assert "effort.swing" not in r.stats["limits"]  # effort 0: none given
    assert len(r.meta["limit_warnings"]) == 1 and "'swing' exceeds its velocity limit 1" in r.meta["limit_warnings"][0]
    scene = tmp_path / "p.toml"
    scene.write_text(f'duration = 0.5\n[robot]\nurdf = "{tmp_path / "pendulum.urdf"}"\nq0 = [{THETA0}]\n')
    assert main(["run", str(scene)]) == 0
    out, err = capsys.readouterr()
    assert "warning: joint 'swing' exceeds its velocity limit 1 [rad/s] in " in err
    assert re.search(r"joint limit t = 0\.45\d+ s: swing stops at its lower limit, impulse [\d.]+ N·m·s\n", out), out


def test_start_outside_the_limits_is_a_clear_error(tmp_path):
    with pytest.raises(SceneError, match=r"robot.q0: expected a start posture within the joint limits \(joint 'swing' "
                                         r"in \[1, 3\] rad; .*found '0.5 rad'"):
        simulate(pendulum(tmp_path, q0=[0.5]))


# ---- an arm that runs into a limit mid-task: tests/scenes/panda_joint_limit.toml ----------------------
UPPER4 = -0.0698  #: [rad] the Panda's joint 4 upper limit (example-robot-data)
#: a joint-space move without contacts (so not among the shipped scenes, which all have a contact task)
PANDA_LIMIT = str(Path(__file__).parent / "scenes" / "panda_joint_limit.toml")


@pytest.fixture(scope="module")
def panda_run():
    return simulate(PANDA_LIMIT, {"duration": 1.8})


def test_arm_stops_at_the_limit_presses_and_is_released(panda_run):
    r = panda_run
    kinds = [(e["kind"], e["name"]) for e in r.events if e["kind"] != "phase"]
    assert kinds == [("limit", "panda_joint4"), ("release", "panda_joint4")]
    assert {row["path"] for row in r.stats["paths"].values()} == {PIPELINE}  # the pressing segment's row too
    hit, release = (e["t"] for e in r.events if e["kind"] in ("limit", "release"))
    assert 0.5 < hit < 1.0 < 1.5 < release  # hit on the way out, released on the way back
    q4 = r["q"][:, 3]
    assert q4.max() <= UPPER4 + 1e-9  # [rad] never past the limit (event overshoot 1e-13, Baumgarte)
    pressing = (r.t > hit) & (r.t < release)
    np.testing.assert_allclose(q4[pressing], UPPER4, atol=1e-9)
    assert np.all(r["limit.side"][pressing, 3] == -1.0) and np.all(r["limit.side"][~pressing, 3] == 0.0)
    torque = r["limit.torque"][pressing, 3]
    assert np.all(torque <= 1e-9) and torque.min() < -50.0  # [N·m] an upper limit only pushes down, hard here
    assert abs(torque[-1]) < 0.05 * abs(torque.min())  # it fades to zero at the release
    assert q4[r.t > release + 0.05].max() < UPPER4 - 1e-3  # and the joint leaves the limit


def test_without_enforcement_the_joint_passes_its_limit():
    r = simulate(PANDA_LIMIT, {"duration": 1.0, "robot.joint_limits": "ignore"})
    assert r["q"][:, 3].max() > 0.2 and not [e for e in r.events if e["kind"] == "limit"]


# ---- a limit impact while a contact slides: friction impulses through the one impact map ------------------------
SLOPE = math.radians(30.0)  #: [rad] the plane's tilt about y
N_SLOPE = np.array([math.sin(SLOPE), 0.0, math.cos(SLOPE)])  #: its normal
T_SLOPE = np.array([[math.cos(SLOPE), 0.0, -math.sin(SLOPE)], [0.0, 1.0, 0.0]])  #: down-slope, sideways
MU_SLOPE = 0.3


def slope_scene(v_tip: np.ndarray, duration: float = 0.2, mu: float = MU_SLOPE, normal=N_SLOPE, tangents=T_SLOPE,
                bonded: bool = True, **solver):
    """cylindrical3 (base turn, radial slide q2 in [-0.5, 0.5] m, lift) at q = (0.3 rad, 0.5 m, 1 m): its radial
    slide on its upper limit, its tip sliding at v_tip [m/s] on a rigid 30° slope with μ (2-D)."""
    robot = Robot.load("cylindrical3")
    q0 = np.array([0.3, 0.5, 1.0])
    J = robot.frame_jacobian(q0, "tip")[:3]
    doc = {"duration": duration, "solver": {"rtol": 1e-10, "atol": 1e-12, **solver},
           "robot": {"urdf": "cylindrical3", "q0": q0.tolist(), "v0": np.linalg.solve(J, v_tip).tolist()},
           "contact": {"slope": {"point": robot.frame_position(q0, "tip").tolist(),
                                 "normal": {"direction": normal.tolist()}, "bonded": bonded,
                                 "tangent": {"model": "friction", "directions": tangents.tolist(), "mu": mu}}},
           "controller": {"kind": "joint_pd", "kp": 0.0, "kd": 0.0}}
    return parse_scene(doc), robot, q0, J


def assert_momentum_balance(M: np.ndarray, J: np.ndarray, imp, limit: float) -> None:
    """M ΔQ̇ = Jᵀ(n Λ_n + Tᵀ Λ_t) + e₂ Λ_limit: the slope's and the radial slide's limit impulses [N·s] take it all."""
    dv = imp.v_after - imp.v_before
    balance = M @ dv - J.T @ (N_SLOPE * imp.normal_impulse + T_SLOPE.T @ imp.friction_impulse)
    np.testing.assert_allclose(balance, [0.0, limit, 0.0], rtol=0, atol=1e-10 * np.abs(M @ dv).max())


@pytest.mark.parametrize("sideways", [0.5, 0.0, 0.35])  # [m/s] the slip's sideways part before the impact
def test_a_limit_impact_takes_the_sliding_contacts_friction_impulse_momentum_balance(sideways):
    """The radial slide hits its upper limit while the tip slides: M ΔQ̇ = Jᵀ(n Λ_n + Tᵀ Λ_t) + e₂ Λ_limit
    with |Λ_t| = μ Λ_n, the radial slide and the normal velocity zero after. At 0.5 and 0 m/s sideways the
    tip slides on, Λ_t = −μ Λ_n d (d the slip's direction before); at 0.35 m/s sliding on would reverse the
    slip, so the impact jams (eqs 30–31), holding needs more than the cone, and it slides where that pushes."""
    scene, robot, q, J = slope_scene(T_SLOPE[0] + sideways * T_SLOPE[1])
    system = System(scene)
    x, modes = system.initial_state()
    x_after, imp, limit = limit_impact(system, 0.0, x, modes, ((1, -1),))
    M = robot.mass_matrix(q)
    assert_momentum_balance(M, J, imp, limit)
    assert imp.contact == "slope" and not imp.jammed
    assert np.linalg.norm(imp.friction_impulse) == pytest.approx(MU_SLOPE * imp.normal_impulse, rel=1e-12)
    d = imp.slip_before / np.linalg.norm(imp.slip_before)
    cosine = float(-imp.friction_impulse @ d) / np.linalg.norm(imp.friction_impulse)
    turned = math.degrees(math.acos(min(1.0, max(-1.0, cosine))))  # a cosine may round just past 1
    if sideways == 0.35:
        assert turned > 1.0  # (1.7°) not against the slip before: where the jammed impulse pushed
    else:
        np.testing.assert_allclose(imp.friction_impulse, -MU_SLOPE * imp.normal_impulse * d, rtol=1e-12)
    assert imp.normal_impulse > 10.0 and limit < -50.0  # [N·s] the slope and the limit both push back, hard
    assert abs(imp.v_after[1]) < 1e-12 and abs(N_SLOPE @ J @ imp.v_after) < 1e-12  # stopped, still on the plane
    assert imp.energy_loss == pytest.approx(0.5 * (imp.v_before @ M @ imp.v_before - imp.v_after @ M @ imp.v_after))
    assert imp.energy_loss > 0.0 and np.array_equal(x_after[3:6], imp.v_after)  # x = [Q, Q̇, y], nQ = 3


def test_a_limit_impact_holds_a_sticking_contact_only_inside_its_cone():
    """The same arm with its tip stuck (mode) at the limit impact: held through its stick rows the tip would need
    a friction impulse ~50 N·s on a normal impulse of ~0 (at μ = 1e6 the jammed solve's Λ_n is 6e-5 N·s): far
    outside the cone even at μ = 5, so the impact slides it where that impulse pushes, |Λ_t| = μ Λ_n, with the
    momentum balanced (issue 27: the stick rows used to take any impulse, no cone test at an impact)."""
    scene, robot, q, J = slope_scene(T_SLOPE[0] + 0.5 * T_SLOPE[1], mu=5.0)
    system = System(scene)
    x, modes = system.initial_state()
    _, imp, limit = limit_impact(system, 0.0, x, [modes[0].with_(stuck=True)], ((1, -1),))
    assert_momentum_balance(robot.mass_matrix(q), J, imp, limit)
    assert imp.contact == "slope" and not imp.jammed and imp.normal_impulse > 0.0
    assert np.linalg.norm(imp.friction_impulse) == pytest.approx(5.0 * imp.normal_impulse, rel=1e-12)
    assert abs(imp.v_after[1]) < 1e-12 and abs(N_SLOPE @ J @ imp.v_after) < 1e-12  # stopped, still on the plane


#: a slope leaning the other way, and up it (outward) and sideways: stopping the radial slide lifts the tip off it
N_AWAY = np.array([-math.sin(SLOPE), 0.0, math.cos(SLOPE)])
T_AWAY = np.array([[math.cos(SLOPE), 0.0, math.sin(SLOPE)], [0.0, 1.0, 0.0]])


@pytest.mark.parametrize("sideways", [0.5, 0.0])  # [m/s]
def test_a_limit_impact_lets_go_of_its_contact_where_holding_it_would_pull(sideways):
    """The radial slide hits its upper limit while the tip slides up a slope leaning away (not bonded): the stop lifts
    the tip off it, so the contact takes no impulse and lets go, and the limit alone stops the slide: M ΔQ̇ = e₂ Λ,
    Λ = −q̇₂⁻ / (M⁻¹)₂₂. Before, a limit impact's own contact was never let go: it pulled the tip onto the slope
    (Λ_n = −36 N·s at 0.5 m/s sideways) and its friction impulse, −μ Λ_n d, pushed the tip along its slip."""
    scene, robot, q, J = slope_scene(T_AWAY[0] + sideways * T_AWAY[1], normal=N_AWAY, tangents=T_AWAY, bonded=False)
    system = System(scene)
    x, modes = system.initial_state()
    assert modes[0].touching and not modes[0].stuck
    x_after, imp, limit = limit_impact(system, 0.0, x, modes, ((1, -1),))
    M_inv = np.linalg.inv(robot.mass_matrix(q))
    assert imp.separated == ("slope",) and imp.normal_impulse == 0.0 and not np.any(imp.friction_impulse)
    assert limit == pytest.approx(-imp.v_before[1] / M_inv[1, 1], rel=1e-12) and limit < -10.0
    np.testing.assert_allclose(imp.v_after, imp.v_before + M_inv[:, 1] * limit, rtol=0, atol=1e-12)
    assert abs(imp.v_after[1]) < 1e-12 and N_AWAY @ J @ imp.v_after > 0.1  # [m/s] stopped; off the slope


def test_a_run_records_the_limit_impact_with_the_contacts_friction_impulse():
    """From 0.35 m the radial slide runs into its limit while the tip slides down the slope under gravity."""
    scene, *_ = slope_scene(T_SLOPE[0] + 0.5 * T_SLOPE[1])
    r = simulate(scene, {"robot.q0": [0.3, 0.35, 1.0 - 0.15 * math.tan(SLOPE) * math.cos(0.3)], "duration": 0.25})
    (hit,) = [e for e in r.events if e["kind"] == "limit"]
    (imp,) = r.impacts
    assert imp["joint"] == "q2" == hit["joint"] and imp["contact"] == "slope" and imp["t"] == hit["t"]
    assert imp["limit_impulse"] == hit["impulse"] < 0.0
    assert np.linalg.norm(imp["friction_impulse"]) == pytest.approx(MU_SLOPE * imp["normal_impulse"], rel=1e-12)
    after = r.t > hit["t"] + 1e-3
    np.testing.assert_allclose(r["q"][after, 1], 0.5, atol=1e-9)  # [m] held on its limit


@pytest.fixture
def brief_pull():
    """A controller ``brief_pull`` registered for the test: τ = 1 − 1.002 sin(π (t − shift)) [N·m] from ``shift`` on
    (1 N·m before): it presses on the upper limit but for 81 ms, when it pulls away."""
    from contactdyn.laws.controllers.base import CONTROLLERS, Controller, register

    class BriefPull(Controller):
        name = "brief_pull"
        shift = 0.0  #: [s]

        def command(self, inp):
            t = inp.t - self.shift
            return np.full(1, 1.0 - 1.002 * math.sin(math.pi * t) if t > 0.0 else 1.0), None

    register(BriefPull)
    yield BriefPull
    CONTROLLERS.pop(BriefPull.name, None)


@pytest.mark.parametrize("shift", [0.11, 0.23])
@pytest.mark.parametrize("compiled", [True, False])
def test_a_held_state_does_not_hide_a_brief_pull_off_the_limit(tmp_path, brief_pull, shift, compiled):
    """No gravity, the joint pressing on its upper limit from the start (nothing moves: the steps grow to most of the
    run, 14 of them): a pull of 81 ms between two stages releases it at the closed-form instant, found on the step's
    dense output (before: no release, the joint held on its limit by a limit torque that pulled), and it strikes the
    limit again."""
    brief_pull.shift = shift
    doc = pendulum(tmp_path).document
    doc.update(duration=1.2, controller={"kind": "brief_pull"})
    doc["robot"] = {**doc["robot"], "q0": [UPPER], "gravity": [0.0, 0.0, 0.0]}
    r = simulate(parse_scene(doc), compiled=compiled)
    kinds = [(e["kind"], e.get("side")) for e in r.events]
    assert kinds == [("release", None), ("limit", "upper")], kinds
    assert r.events[0]["t"] == pytest.approx(shift + math.asin(1.0 / 1.002) / math.pi, abs=1e-9)


@pytest.mark.parametrize("compiled", [True, False])
@pytest.mark.parametrize("friction", [0.0, 0.5])
def test_a_joint_at_rest_on_its_limit_presses_from_the_start_with_no_impact(tmp_path, friction, compiled):
    """A joint that starts at rest exactly on its limit, its load pushing into it (gravity, the pendulum at its lower
    limit; a dry joint too): pressing from t = 0, no event, its velocity exactly 0 and its limit torque the gravity
    torque m g l sin θ (before: a `limit` event and a plastic impact at ~3e-7 s after it moved 1e-13 rad past, and a
    dry joint's `joint_slip` at 0). The same start pulled away from the limit (at the upper one, gravity pulls it
    off) is free at once, with no event either."""
    for q0, side in ((LOWER, 1.0), (UPPER, 0.0)):
        doc = pendulum(tmp_path).document
        doc.update(duration=0.3)
        doc["robot"] = {**doc["robot"], "q0": [q0], "joint": {"swing": {"friction": friction}}}
        r = simulate(parse_scene(doc), compiled=compiled)
        if side:
            assert r.events == [], r.events
            assert np.all(r["limit.side"][:, 0] == side) and np.all(r["v"][:, 0] == 0.0)
            np.testing.assert_allclose(r["limit.torque"][:, 0], M * G * L * math.sin(LOWER), rtol=1e-12)
        else:  # (the upper limit: 3 rad, gravity swings it down; with friction it breaks away at once)
            assert [e["kind"] for e in r.events if e["kind"] != "joint_slip" or e["t"] > 0.0] == [], r.events
            assert np.all(r["limit.side"][:, 0] == 0.0) and r["q"][-1, 0] < UPPER - 0.01


@pytest.mark.parametrize("compiled", [True, False])
def test_a_joint_with_dry_friction_leaves_its_limit_from_rest(tmp_path, brief_pull, compiled):
    """The brief pull with dry friction on the joint (τ_s = 1e-3 N·m): at the release (the limit torque through zero)
    the joint's friction holds it from rest, its velocity exactly 0, until the pull reaches τ_s, where it breaks away
    (closed forms: 1 − 1.002 sin(π (t − shift)) = 0, then = −τ_s). Before, the limit row's drift (~1e-12 rad/s) made
    it slip at the release and stick again 5e-10 s later."""
    brief_pull.shift, tau_s = 0.11, 1e-3
    doc = pendulum(tmp_path).document
    doc.update(duration=0.62, controller={"kind": "brief_pull"})
    doc["solver"] = {**doc["solver"], "output_rate": 5000.0}
    doc["robot"] = {**doc["robot"], "q0": [UPPER], "gravity": [0.0, 0.0, 0.0], "joint": {"swing": {"friction": tau_s}}}
    r = simulate(parse_scene(doc), compiled=compiled)
    later = [(e["kind"], e["t"]) for e in r.events if e["t"] > 0.5]
    assert [kind for kind, _ in later] == ["release", "joint_slip"], later
    (_, release), (_, slip) = later
    assert release == pytest.approx(0.11 + math.asin(1.0 / 1.002) / math.pi, abs=1e-9)
    assert slip == pytest.approx(0.11 + math.asin((1.0 + tau_s) / 1.002) / math.pi, abs=1e-9)
    held = (r.t > release) & (r.t < slip)
    assert held.sum() > 20
    assert np.all(r["v"][held, 0] == 0.0) and np.ptp(r["q"][held, 0]) == 0.0  # at rest, exactly
    assert np.all(r["joint_stuck"][held, 0] == 1.0) and np.all(r["limit.side"][held, 0] == 0.0)
    assert np.all(np.abs(r["joint_friction"][held, 0]) <= tau_s)  # the pull held within the static limit
    assert r["v"][r.t > slip + 1e-3, 0].max() < 0.0  # then it slides off the upper limit
