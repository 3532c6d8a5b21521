"""Joint limits (contactdyn.limits): a position limit is a unilateral constraint located, impacted
plastically, held while the joint presses and released when its torque vanishes."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from scipy.special import ellipk, ellipkinc

from contactdyn import simulate
from contactdyn.errors import SceneError
from contactdyn.scene import parse_scene

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
    assert r.stats["fallback_modes"] == {} and r.stats["compiled_modes"] == 2  # free, then pressing: compiled
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
    assert "warning: joint 'swing' exceeds its velocity limit" in capsys.readouterr().err


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
    assert r.stats["fallback_modes"] == {}  # the pressing segment too: its row is on the compiled path
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
