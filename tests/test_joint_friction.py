"""Joint damping and Coulomb joint friction with true stick (contactdyn.model.joint_friction): a stuck joint is
held exactly, breaks away where its holding torque reaches the static limit, slides with the kinetic one and
sticks again at rest; the closed forms of a ramp, a hold and a pendulum."""

from __future__ import annotations

import math
from collections import Counter
from itertools import pairwise

import numpy as np
import pytest
from scipy.optimize import brentq

from contactdyn import simulate
from contactdyn.errors import SceneError
from contactdyn.model.friction import SLIP_ALARM
from contactdyn.model.system import System
from contactdyn.scene.scene_file import parse_scene

M, L, G = 2.0, 0.5, 9.81  #: point mass [kg] on a massless rod [m], gravity [m/s²]
MGL = M * G * L  #: [N·m] the pendulum's largest gravity torque
EVENT_TOL = 1e-9  #: [s] events located at rtol 1e-10, atol 1e-12

LINK = """  <joint name="{name}" type="{kind}"><parent link="{parent}"/><child link="{child}"/><axis xyz="0 1 0"/>
    {origin}<dynamics damping="{damping}" friction="{friction}"/>{limit}</joint>
  <link name="{child}"><inertial><origin xyz="0 0 {z}"/><mass value="{m}"/>
    <inertia ixx="0" iyy="0" izz="0" ixy="0" ixz="0" iyz="0"/></inertial></link>
"""


def arm(tmp_path, links: int = 1, damping: float = 0.0, friction: float = 0.0, limits: float | None = None) -> str:
    """A planar chain of ``links`` point masses M on massless rods L (joints about y, θ = 0 hanging down) as a URDF
    with the given <dynamics> on every joint (and position limits ±``limits`` [rad]: revolute joints); its path."""
    kind, limit = ("continuous", "") if limits is None else \
        ("revolute", f'<limit lower="{-limits}" upper="{limits}" effort="0" velocity="0"/>')
    body = "".join(LINK.format(name=f"j{k + 1}", kind=kind, parent="base" if k == 0 else f"link{k}",
                               child=f"link{k + 1}", origin="" if k == 0 else f'<origin xyz="0 0 {-L}"/>',
                               damping=damping, friction=friction, limit=limit, z=-L, m=M) for k in range(links))
    tip = f'  <joint name="tip_joint" type="fixed"><parent link="link{links}"/><child link="tip"/>' \
          f'<origin xyz="0 0 {-L}"/></joint>\n  <link name="tip"/>\n'
    path = tmp_path / f"arm{links}.urdf"
    path.write_text(f'<?xml version="1.0"?>\n<robot name="arm">\n  <link name="base"/>\n{body}{tip}</robot>\n')
    return str(path)


def scene(urdf: str, q0: list[float], duration: float, controller: dict | None = None, gravity: bool = True,
          **robot) -> dict:
    return {"duration": duration, "solver": {"rtol": 1e-10, "atol": 1e-12, "output_rate": 1000.0},
            "robot": {"urdf": urdf, "q0": q0, "gravity": [0.0, 0.0, -G if gravity else 0.0], **robot},
            "controller": controller or {"kind": "joint_pd", "kp": [0.0], "kd": [0.0]}}


def events(r, kind: str) -> list[dict]:
    return [e for e in r.events if e["kind"] == kind]


def test_a_growing_load_breaks_the_joint_away_at_the_static_limit(tmp_path):
    """No gravity; a joint PD of stiffness k with a reference moving at a constant rate: while the joint is stuck
    its torque is k·δ·t/T exactly, so it breaks away at t = τ_s T / (k δ); then the friction is the kinetic one."""
    k, delta, T, tau_s, tau_k = 100.0, 0.1, 1.0, 2.0, 1.2  # [N·m/rad], [rad], [s], [N·m], [N·m]
    ctl = {"kind": "joint_pd", "kp": [k], "kd": [0.0]}
    doc = scene(arm(tmp_path), [0.3], 0.3, ctl, gravity=False,
                joint={"j1": {"friction_static": tau_s, "friction_kinetic": tau_k}})
    doc["phase"] = [{"name": "ramp", "reference": {"space": "joint", "moves": [
        {"kind": "constant_velocity", "delta": [delta], "duration": T}]}}]
    r = simulate(parse_scene(doc))
    (slip,) = events(r, "joint_slip")
    t_break = tau_s * T / (k * delta)
    assert slip["name"] == "j1" and slip["t"] == pytest.approx(t_break, abs=EVENT_TOL)
    assert slip["torque"] == pytest.approx(-tau_s, rel=1e-9)  # the holding torque opposes the load
    before, after = r.t < t_break, (r.t > t_break) & (r.t < t_break + 0.03)
    assert np.all(r["v"][before, 0] == 0.0) and np.all(r["q"][before, 0] == 0.3)  # held exactly
    np.testing.assert_allclose(r["joint_friction"][before, 0], -k * delta * r.t[before] / T, rtol=0, atol=1e-12)
    assert np.all(r["joint_stuck"][before, 0] == 1.0) and np.all(r["joint_stuck"][after, 0] == 0.0)
    assert np.all(r["v"][after, 0] > 0.0)  # it slides along the load, against −τ_k
    np.testing.assert_array_equal(r["joint_friction"][after, 0], -tau_k)  # static 2.0 drops to kinetic 1.2
    assert r.stats["compiled_modes"] >= 2


@pytest.fixture
def sine_torque():
    """A controller ``sine_torque`` registered for the test: τ = A sin(π t) [N·m] on the one joint, of time alone."""
    from contactdyn.laws.controllers.base import CONTROLLERS, Controller, register

    class SineTorque(Controller):
        name = "sine_torque"
        amplitude = 2.1  #: [N·m]

        def command(self, inp):
            return np.full(1, self.amplitude * math.sin(math.pi * inp.t)), None

    register(SineTorque)
    yield SineTorque
    CONTROLLERS.pop(SineTorque.name, None)


@pytest.mark.parametrize("compiled", [True, False])
def test_a_held_state_does_not_hide_a_load_that_passes_the_static_limit(tmp_path, sine_torque, compiled):
    """No gravity, the one joint stuck: the state does not move, so nothing in it asks the steps to stay short
    (before its impulse state ∫τ_f dt: 7 steps in 1 s, the joint held at 2.1 N·m > τ_s, no event).
    The load A sin(πt) passes τ_s = 2 N·m at t = asin(τ_s/A)/π: the joint breaks away there, never held beyond τ_s,
    on both paths."""
    tau_s, amplitude = 2.0, sine_torque.amplitude
    doc = scene(arm(tmp_path), [0.0], 1.0, {"kind": "sine_torque"}, gravity=False, joint={"j1": {"friction": tau_s}})
    r = simulate(parse_scene(doc), compiled=compiled)
    slip = events(r, "joint_slip")[0]
    assert slip["t"] == pytest.approx(math.asin(tau_s / amplitude) / math.pi, abs=EVENT_TOL)
    stuck = r["joint_stuck"][:, 0] == 1.0
    assert np.abs(r["joint_friction"][stuck, 0]).max() <= tau_s * (1.0 + 1e-12)
    assert not any(e["kind"] == "joint_slip_check" for e in r.events)


def test_a_joint_loaded_below_its_limit_never_creeps(tmp_path):
    """A double pendulum whose shoulder holds (τ_s above any load the swinging elbow gives it) for the whole run:
    the shoulder's velocity stays exactly 0 (no creep), its holding torque balances the load."""
    q0 = [0.4, 1.2]  # [rad]
    doc = scene(arm(tmp_path, 2), q0, 1.0, {"kind": "joint_pd", "kp": [0.0, 0.0], "kd": [0.0, 0.0]},
                joint={"j1": {"friction": 100.0}})
    r = simulate(parse_scene(doc))
    creep = float(np.abs(r["v"][:, 0]).max())  # [rad/s]
    print(f"largest |q̇| of the stuck shoulder: {creep:.3g} rad/s")
    assert creep < 1e-12  # roundoff of the solve (q̈₁ ~ 1e-16 of the elbow's), pulled back by the row's ω q̇₁
    assert float(np.abs(r["q"][:, 0] - q0[0]).max()) < 1e-14 and np.all(r["joint_stuck"][:, 0] == 1.0)
    assert not events(r, "joint_slip") and not events(r, "joint_stick")
    assert np.ptp(r["q"][:, 1]) > 1.0  # the elbow swings
    assert np.all(r["joint_stuck"][:, 1] == 0.0) and np.all(r["joint_friction"][:, 1] == 0.0)  # no friction there
    # the shoulder's holding torque = its whole load: the elbow's reaction and both masses' gravity (checked on the
    # robot's own H and h at a few samples: λ₁ = −(f₁ − H₁₂ q̈₂) with q̈₁ = 0)
    system = System(parse_scene(doc))
    for k in (0, 333, 999):
        system.robot.update(r["q"][k], r["v"][k])
        H, h = system.robot.H, system.robot.h
        qdd2 = -h[1] / H[1, 1]  # the elbow swings freely on a fixed shoulder
        assert r["joint_friction"][k, 0] == pytest.approx(h[0] + H[0, 1] * qdd2, rel=1e-9, abs=1e-12)


def pendulum_stop(theta0: float, tau_s: float, tau_k: float) -> tuple[float, int]:
    """Where a pendulum released at rest from θ0 with dry joint friction stops, and after how many half swings.

    A half swing from rest at θ_k (moving towards −sign θ_k, the friction torque ±τ_k constant) conserves
    U = −m g l cos θ − τ_k θ sign(θ_k): its turning point θ_{k+1} is the other root of m g l (cos θ_{k+1} − cos θ_k)
    = τ_k |θ_k − θ_{k+1}|, beyond U's minimum at θ_e = sign(θ_k) asin(τ_k / m g l). It stops at the first turning
    point where the static limit holds gravity, |m g l sin θ| ≤ τ_s."""
    theta, swings = theta0, 0
    while abs(MGL * math.sin(theta)) > tau_s:
        s = math.copysign(1.0, theta)
        a = abs(theta)
        theta_e = math.asin(tau_k / MGL)
        turning = brentq(lambda th, a=a: MGL * (math.cos(th) - math.cos(a)) - tau_k * (a - th), -a, theta_e,
                         xtol=1e-15)
        theta, swings = s * turning, swings + 1
    return theta, swings


def test_pendulum_with_dry_joint_friction_stops_at_the_closed_form_angle(tmp_path):
    theta0, tau_s, tau_k = 1.0, 2.0, 1.5  # [rad], [N·m], [N·m]
    doc = scene(arm(tmp_path), [theta0], 3.0, joint={"j1": {"friction_static": tau_s, "friction_kinetic": tau_k}})
    r = simulate(parse_scene(doc))
    theta_stop, swings = pendulum_stop(theta0, tau_s, tau_k)
    assert swings == 3  # the parameters' case: two reversals, then it sticks
    assert [e["kind"] for e in r.events] == ["joint_slip"] + ["joint_reverse"] * (swings - 1) + ["joint_stick"]
    t_stick = r.events[-1]["t"]
    assert r.events[0]["t"] == 0.0  # gravity beyond the static limit at the start: it slides at once
    stuck = r.t >= t_stick
    assert np.all(r["v"][stuck, 0] == 0.0) and np.all(r["joint_stuck"][stuck, 0] == 1.0)
    assert r["q"][-1, 0] == pytest.approx(theta_stop, abs=1e-9)  # [rad]
    assert r["joint_friction"][-1, 0] == pytest.approx(MGL * math.sin(theta_stop), rel=1e-9)  # holds gravity


@pytest.mark.parametrize("compiled", [True, False])
def test_a_load_exactly_at_the_static_limit_holds(tmp_path, compiled):
    """|m g l sin θ| = τ_s exactly (τ_k = τ_s / 2): the joint holds for the whole run, as |load| ≤ τ_s says (before:
    its joint_slip value, exactly 0 at both ends of the first step, counted as a fall through zero and the joint swung
    away); 1e-9 more load breaks it away at once."""
    theta0 = 0.3
    tau_s = MGL * math.sin(theta0)
    for load, held in ((1.0, True), (1.0 + 1e-9, False)):
        doc = scene(arm(tmp_path), [theta0], 0.3, joint={"j1": {"friction_static": tau_s / load,
                                                                 "friction_kinetic": 0.5 * tau_s / load}})
        r = simulate(parse_scene(doc), compiled=compiled)
        if held:
            assert not r.events and np.all(r["q"][:, 0] == theta0) and np.all(r["v"][:, 0] == 0.0)
            np.testing.assert_allclose(r["joint_friction"][:, 0], tau_s, rtol=1e-12)  # the whole load held
        else:
            assert [(e["kind"], e["t"]) for e in r.events] == [("joint_slip", 0.0)] and r["q"][-1, 0] < theta0


@pytest.mark.parametrize("compiled", [True, False])
def test_an_impact_that_reverses_a_sliding_joint_lets_it_slide_back(tmp_path, compiled):
    """No gravity; the shoulder slides (+) with 0.5 N·m of dry friction, the elbow strikes its lower limit: the plastic
    impact (the shoulder free in it: a bounded friction takes no impulse) reverses the shoulder, which slides back
    (joint_reverse at the impact's instant) and keeps the kinetic energy the impact left it, less its friction's work:
    the energy audit balances. Before, it kept its old slide's sign, its joint_stick fired 3e-14 s later and zeroed
    ~2 rad/s: 4.4 J gone, the audit's residual 4.4 J."""
    free = {"kind": "joint_pd", "kp": [0.0, 0.0], "kd": [0.0, 0.0]}
    doc = scene(arm(tmp_path, 2, limits=1.0), [0.0, -0.9], 0.05, free, gravity=False, v0=[0.3, -6.0],
                joint={"j1": {"friction": 0.5}})
    doc["solver"]["record_energy"] = True
    r = simulate(parse_scene(doc), compiled=compiled)
    hit = r.events[0]
    assert [(e["kind"], e["name"]) for e in r.events] == [("limit", "j2"), ("release", "j2"), ("joint_reverse", "j1")]
    assert all(e["t"] == hit["t"] for e in r.events)
    after = r.t > hit["t"]
    assert np.all(r["v"][after, 0] < -1.0)  # [rad/s] the shoulder slides back the whole run
    np.testing.assert_array_equal(r["joint_friction"][after, 0], 0.5)  # against its slide
    audit = r.meta["checks"]["energy_residual"]
    assert audit["value"] < audit["tol"]  # [J] what the impact and the friction took, and nothing more


def test_a_stuck_joints_leftover_velocity_is_set_to_exactly_zero(tmp_path):
    """A stuck joint whose velocity is within STICK_TOL (an impact's round-off) is at rest exactly after the joint
    modes are settled (before: zeroed on a copy that was dropped)."""
    run, x, modes, phase, _ = _stuck_shoulder(tmp_path)
    system = run.system
    x = x.copy()
    x[system.nQ] = 5e-14  # [rad/s] within STICK_TOL
    x_after, _, phase_after = run.transitions.settle_joints(0.0, x, modes, phase)
    assert x_after[system.nQ] == 0.0 and phase_after.joint_modes == phase.joint_modes and not run.events


def test_damping_from_the_urdf_decays_a_free_swing(tmp_path):
    """The URDF's damping alone: a small free swing (θ0 = 1e-3 rad) is the damped oscillator of the linearized
    pendulum, θ = θ0 e^(−βt) (cos ω_d t + β/ω_d sin ω_d t) with β = b / (2 m l²), ω_d² = g/l − β² (the nonlinearity
    ~θ0²/16 of the frequency: < 1e-9 rad over the run); the run says it used the URDF's value;
    ``joint_friction = "ignore"`` drops it."""
    b, theta0 = 0.2, 1e-3  # [N·m·s/rad], [rad]
    doc = scene(arm(tmp_path, damping=b), [theta0], 2.0)
    r = simulate(parse_scene(doc))
    assert r.meta["joint_friction"] == {"j1": {"damping": b, "friction_static": 0.0, "friction_kinetic": 0.0,
                                               "source": "urdf", "unit": "N·m"}}
    np.testing.assert_allclose(r["joint_friction"][:, 0], -b * r["v"][:, 0], rtol=1e-12, atol=1e-15)
    beta = b / (2 * M * L * L)
    w = math.sqrt(G / L - beta * beta)
    closed = theta0 * np.exp(-beta * r.t) * (np.cos(w * r.t) + beta / w * np.sin(w * r.t))
    np.testing.assert_allclose(r["q"][:, 0], closed, rtol=0, atol=2e-9)
    assert not events(r, "joint_slip") and "joint_stuck" in r.channels
    ignored = simulate(parse_scene({**doc, "robot": {**doc["robot"], "joint_friction": "ignore"}}))
    assert ignored.meta["joint_friction"] == {} and "joint_friction" not in ignored.channels


@pytest.mark.parametrize("joint, expected, key", [
    ({"elbow": {"damping": 1.0}}, "an active joint of the robot (j1)", "robot.joint.elbow"),
    ({"j1": {"damping": -1.0}}, "a number >= 0", "robot.joint.j1.damping"),
    ({"j1": {"friction": math.nan}}, "a finite number", "robot.joint.j1.friction"),
    ({"j1": {"friction_static": 1.0, "friction_kinetic": 2.0}}, "a kinetic friction <= friction_static",
     "robot.joint.j1.friction_kinetic"),
    ({"j1": {"friction": 1.0, "friction_static": 1.0}}, "friction alone", "robot.joint.j1.friction"),
    ({"j1": {"friction_kinetic": 1.0}}, "a static limit", "robot.joint.j1.friction_static"),
])
def test_bad_joint_friction_names_the_key_and_the_file(tmp_path, joint, expected, key):
    path = tmp_path / "bad.toml"
    doc = scene(arm(tmp_path), [0.0], 0.1, joint=joint)
    with pytest.raises(SceneError) as info:
        System(parse_scene(doc, file=str(path)))
    assert info.value.key == key and expected in info.value.expected and str(path) in str(info.value)


@pytest.mark.parametrize("damping, friction, attribute", [(0.0, -1.0, "friction"), (1e300, 0.0, "damping"),
                                                          (0.0, 1e20, "friction")])
def test_a_urdfs_bad_dynamics_names_the_joint_and_the_attribute(tmp_path, damping, friction, attribute):
    """Negative or absurd <dynamics> values: our message naming the joint (not Pinocchio's min/max_dry_friction),
    bounded as the scene's own joint keys are; also where the scene ignores the URDF's values."""
    urdf = arm(tmp_path, damping=damping, friction=friction)
    for ignore in ({}, {"joint_friction": "ignore"}):
        with pytest.raises(SceneError) as info:
            System(parse_scene(scene(urdf, [0.0], 0.1, **ignore)))
        message = str(info.value)
        assert info.value.key == "robot.urdf" and urdf in message
        assert f"joint 'j1' <dynamics>: {attribute}=" in message and "expected a number >= 0 and <= 1e+12" in message


def test_a_misspelt_joint_key_is_matched_to_every_key_the_table_knows(tmp_path):
    """``friction`` and ``friction_kinetic`` are only looked for (read when present): the message still knows them."""
    doc = scene(arm(tmp_path), [0.0], 0.1, joint={"j1": {"frction": 1.0}})
    with pytest.raises(SceneError) as info:
        parse_scene(doc)
    message = str(info.value)
    assert info.value.key == "robot.joint.j1.frction" and "did you mean 'friction'?" in message
    assert "damping, friction, friction_kinetic, friction_static" in message


def test_the_compiled_call_is_the_interpreted_call_in_every_joint_mode(tmp_path):
    """Damping on both joints, the shoulder stuck (a row) and the elbow sliding (−s τ_k): the compiled call's
    right-hand side, its event values and its output samples equal the interpreted call's (interpreted_evaluate,
    interpreted_samples)."""
    from dataclasses import replace

    from run_agreement import interpreted_evaluate, interpreted_samples

    from contactdyn.hybrid.pipeline_mode import PipelineMode
    from contactdyn.model.pipeline.pipeline import Pipeline

    doc = scene(arm(tmp_path, 2, damping=0.05), [0.4, 1.2], 1.0, {"kind": "joint_pd", "kp": [0.0], "kd": [0.0]},
                joint={"j1": {"damping": 0.1, "friction_static": 50.0, "friction_kinetic": 30.0},
                       "j2": {"damping": 0.05, "friction": 0.5}})
    system = System(parse_scene(doc))
    x, modes = system.initial_state()
    rng = np.random.default_rng(3)
    for joint_modes in (((0, 0), (1, 1)), ((0, -1), (1, 0)), ((0, 1), (1, -1))):
        phase = replace(system.start_phase(0, 0.0, x, None), joint_modes=joint_modes)
        plan = PipelineMode(Pipeline(system, modes, phase))
        X = x + 0.1 * rng.normal(size=(5, system.n))
        ts = np.linspace(0.1, 0.5, 5)
        for t, state in zip(ts, X, strict=True):
            ev = interpreted_evaluate(system, t, state, modes, phase)
            np.testing.assert_allclose(plan.rhs(t, state.copy()), ev.xdot, rtol=1e-12, atol=1e-12)
            assert plan.joint_hold(t, state) == pytest.approx(ev.joint_hold, rel=1e-12)
        fast, slow = plan.samples(ts, X), interpreted_samples(system, ts, X, modes, phase)
        np.testing.assert_allclose(fast.joint_friction, slow.joint_friction, rtol=1e-12, atol=1e-12)
        stuck = [i for i, m in joint_modes if m == 0]
        sliding = [(i, m) for i, m in joint_modes if m != 0]
        for i, m in sliding:  # damping and the kinetic friction, against the slide
            kinetic = 30.0 if i == 0 else 0.5
            np.testing.assert_allclose(slow.joint_friction[:, i], -(0.1 if i == 0 else 0.05) * X[:, system.nQ + i]
                                       - m * kinetic, rtol=1e-12)
        assert set(plan.pipe.packed.held) == set(stuck)


def test_a_storm_of_one_joints_events_is_said_to_be_that_joints_not_a_contacts():
    """The storm guard's words follow its events: a joint's slip checks name the joint and a divergence; a contact's
    (or a mix) keep the contact's chatter."""
    from contactdyn.hybrid.events import _storm_cause

    check, slip = {"t": 0.2, "kind": "joint_slip_check", "name": "q2"}, {"t": 0.2, "kind": "joint_slip", "name": "q2"}
    joint = [check] * 4 + [slip]
    said = _storm_cause(joint)
    assert "joint q2" in said and "diverged" in said and "contact" not in said
    mixed = joint + [{"t": 0.2, "kind": "slip_check", "name": "tip"}]
    assert "the contact chatters" in _storm_cause(mixed) and "redundant" not in _storm_cause(mixed)
    said = _storm_cause(mixed, singular=3)  # (all joints stuck, the tool stuck: the KKT system over-constrained)
    assert "3 of the decisions met redundant holds" in said and 'robot.joint_friction = "ignore"' in said


def test_the_stick_or_reverse_decision_reads_the_trials_holding_torque(tmp_path, monkeypatch):
    """The decision's holding torque (LastEvaluation.joint_hold: one plain call of the stuck trial) is the whole
    Evaluation's; where that call has no answer the Evaluation's is read, which says why."""
    from dataclasses import replace

    from contactdyn.errors import SimulationError
    from contactdyn.hybrid.pipeline_mode import PipelineMode
    from contactdyn.hybrid.transitions import LastEvaluation

    doc = scene(arm(tmp_path, 2, damping=0.05), [0.4, 1.2], 1.0, {"kind": "joint_pd", "kp": [0.0], "kd": [0.0]},
                joint={"j1": {"friction_static": 50.0, "friction_kinetic": 30.0}, "j2": {"friction": 0.5}})
    system = System(parse_scene(doc))
    x, modes = system.initial_state()
    trial = replace(system.start_phase(0, 0.0, x, None), joint_modes=((0, 0), (1, 0)))
    last = LastEvaluation(system)
    x = x.copy()
    x[system.nQ:system.nQ + 2] = 0.0
    hold = last.joint_hold(0.2, x, modes, trial)
    want = LastEvaluation(system)(0.2, x, modes, trial).joint_hold
    assert set(hold) == {0, 1} and hold == want and abs(hold[0]) > 1.0  # gravity loads the shoulder
    monkeypatch.setattr(PipelineMode, "values", lambda self, t, x_: np.full(4, np.nan))  # a call without an answer
    monkeypatch.setattr(PipelineMode, "evaluation", lambda self, t, x_: (_ for _ in ()).throw(
        SimulationError("no finite answer")))
    with pytest.raises(SimulationError, match="no finite answer"):
        LastEvaluation(system).joint_hold(0.3, x, modes, trial)


def _stuck_shoulder(tmp_path):
    """A 2-link arm hanging at rest off the vertical, its shoulder held by 100 N·m of dry friction (gravity loads it by
    less), the elbow free: its run, x, modes, phase, and q̈₁ [rad/s²] if the shoulder slid forwards from there
    (M q̈ = −g − τ_k e₁ at rest, from the robot's M and g)."""
    from contactdyn.hybrid.loop import HybridRun

    doc = scene(arm(tmp_path, 2), [0.4, 1.2], 0.2, {"kind": "joint_pd", "kp": [0.0, 0.0], "kd": [0.0, 0.0]},
                joint={"j1": {"friction": 100.0}})
    system = System(parse_scene(doc))
    x, modes = system.initial_state()
    phase = system.start_phase(0, 0.0, x, None)
    assert (0, 0) in phase.joint_modes  # the shoulder stuck
    q = x[:2]
    a = np.linalg.solve(system.robot.mass_matrix(q), -system.robot.gravity_torque(q) - np.array([100, 0]))
    return HybridRun(system), x, modes, phase, float(a[0])


@pytest.mark.parametrize("share, held", [(0.81, True), (1.21, False)])
def test_a_stuck_joint_holds_an_impacts_residual_speed_whose_slide_the_integration_cannot_resolve(tmp_path, share,
                                                                                                  held):
    """A stuck joint an impact sets moving at v slides (its friction takes no impulse), unless it would stop within a
    travel v²/(2|q̈|) ≤ atol: then it holds, its residual speed projected away by an impulse on its own row (the free
    elbow's momentum kept). Below and above the closed form's threshold v* = √(2|q̈| atol)."""
    run, x, modes, phase, a = _stuck_shoulder(tmp_path)
    v = math.sqrt(share * 2.0 * abs(a) * 1e-12)  # [rad/s] the shoulder's residual speed: the travel is share × atol
    system, nQ = run.system, run.system.nQ
    x = x.copy()
    x[nQ] = v
    x_after, _, phase_after = run.transitions.settle_joints(0.0, x, modes, phase)
    if not held:
        assert [(e["kind"], e["name"]) for e in run.events] == [("joint_slip", "j1")]
        assert (0, 1) in phase_after.joint_modes and x_after[nQ] == v
        return
    assert not run.events and phase_after.joint_modes == phase.joint_modes and x_after[nQ] == 0.0
    M = system.robot.mass_matrix(x[:2])
    impulse = M @ (x_after[nQ:nQ + 2] - x[nQ:nQ + 2])  # [N·m·s] on the shoulder's row alone
    assert impulse[0] * v < 0.0 and abs(impulse[1]) <= 1e-12 * abs(impulse[0])


def test_a_hold_whose_rounding_exceeds_a_tight_band_still_breaks_away_where_it_reaches_its_limit():
    """Case 3's axis at 0.05 N of friction: its holding force is a difference of ~1e2 N terms through a 1e5 N/m
    surface and a 6e5 N/m drive, so it moves in steps of ~1.7e-10 N (3e-9 τ_s). Each located slip is within
    SLIP_ALARM of τ_s (a band of 1e-9 τ_s took every one as a false alarm, 10,000 of them at one instant), and stick
    and slip alternate to the run's end."""
    r = simulate("sims/case3_b_force.toml", {"robot.joint.q3.friction": 0.05})
    assert r.t[-1] == pytest.approx(5.0)
    held = [e for e in r.events if e["kind"] in ("joint_stick", "joint_slip") and e["t"] > 2.0]
    assert len(held) >= 10 and r.stats["slip_false_alarms"] == 0
    assert all(a["kind"] != b["kind"] for a, b in pairwise(held))  # (alternate)
    for e in held:
        if e["kind"] == "joint_slip":
            assert abs(e["torque"]) == pytest.approx(0.05, rel=SLIP_ALARM)
        else:
            assert abs(e["torque"]) < 0.05


def test_a_joint_that_breaks_away_where_static_equals_kinetic_is_not_stuck_again_at_once():
    """B1 on a 1e8 N/m surface with 4 N·m on both joints (static = kinetic): q1's load rises through 4 N·m at
    ~7e3 N·m/s, its hold rounded to ~1.6e-9 N·m. At the slip its slide from rest decelerates by that rounding alone;
    the decision at rest reads the joint's acceleration against the largest of the call (the solve's normwise
    rounding), not against its own ~0: it slides on (before, it stuck again and slipped 50 times at one instant)."""
    r = simulate("benchmarks/hard/stiff.toml", {"robot.joint.q1.friction": 4.0, "robot.joint.q2.friction": 4.0})
    assert r.t[-1] == pytest.approx(2.0)
    q1 = [e for e in r.events if e["name"] == "q1" and e["kind"] in ("joint_stick", "joint_slip")]
    slips = [e for e in q1 if e["kind"] == "joint_slip"]
    assert len(slips) >= 2 and all(abs(e["torque"]) == pytest.approx(4.0, rel=SLIP_ALARM) for e in slips)
    assert all(b["t"] > a["t"] for a, b in pairwise(q1))  # (no stick at a slip's own instant)


def test_a_2d_slide_at_its_stop_band_is_decided_at_rest_after_a_holds_check_located_there():
    """The 5-DOF writer with 4 N·m on every joint: the pencil's slide comes to rest with v̂ 35° from its reference r,
    and at v_t · r = v_ε its force turns from v̂ to r, which moves the stuck joints' holds by ~2 N·m. The holds'
    checks located there (false alarms: the located holds are inside τ_s) left the slide on its stop, and the next
    step's checks fired first again, 50 times at one instant. The decision after the check stops the slide there."""
    r = simulate("sims/case2_writer5dof.toml", {f"robot.joint.q{k}.friction": 4.0 for k in range(1, 6)})
    assert r.t[-1] == pytest.approx(4.5)
    checks = Counter(e["t"] for e in r.events if e["kind"] == "joint_slip_check")
    assert max(checks.values()) <= 2  # (a check, not a storm, at any one instant)
    stuck = [e for e in r.events if e["kind"] == "stick" and e["name"] == "pencil"]
    assert any(e["t"] in checks for e in stuck)  # (decided at rest where a check was located)


def test_a_run_whose_last_check_lands_a_few_roundings_before_its_end_ends_there():
    """The UR5 writer with 1 N·m on every joint: a joint's check (a false alarm) is located 3.6e-15 s before the run's
    4.5 s, 8 roundings of t. The segment left to integrate is shorter than the integrators' floor, and its first
    step's stages saw the same alarm again: 50 checks at one instant. A segment that would end within min_span of its
    start at the run's end is not integrated: the run ends there, its output to 4.5 s."""
    from contactdyn.laws.trajectory import min_span

    joints = simulate("case2_writer_ur5", {"duration": 1e-3}).meta["joints"]
    r = simulate("case2_writer_ur5", {f"robot.joint.{j}.friction": 1.0 for j in joints})
    assert r.t[-1] == 4.5 and np.all(np.isfinite(r["q"][-1]))
    last = r.events[-1]
    assert 0.0 < 4.5 - last["t"] <= min_span(4.5)
    assert sum(e["t"] == last["t"] for e in r.events) < 5  # (not a storm at that instant)
