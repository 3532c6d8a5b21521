"""A contact and a joint at rest decided together (contactdyn.hybrid.at_rest): where deciding each dry-friction
item on its own left a mode the next instant contradicts, one consistent mode for both, and no event storm.

The scenes are benchmarks/hard's stick-slip, bounce and singular pose with dry friction on the arm's joints. Deciding
the tip and a joint one at a time, each run stopped on an event storm (stick:tip, joint_reverse:q2, slip:tip,
joint_stick:q2 at one instant, 50 times in < 1e-9 s), or reversed a joint at once after its start (singular); with
both joints, a stick decided at the cone's very edge fired its slip at once (the search's sticks are inside the cone
by its slack)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from contactdyn import simulate
from contactdyn.hybrid import at_rest

HARD = Path(__file__).resolve().parent.parent / "benchmarks" / "hard"
MU_S = {"stickslip": 0.5, "bounce": 0.4, "singular": 0.2}  #: the scenes' static friction coefficients
CASES = {  # (scene, overrides, duration [s]: past the instant of the old storm, τ_s [N·m] per joint)
    "stickslip, 0.5 N·m on q2": ("stickslip", {"robot.joint.q2.friction": 0.5}, 0.4, (0.0, 0.5)),
    "stickslip, 0.5 N·m on q1 and q2": ("stickslip", {"robot.joint.q1.friction": 0.5,
                                                      "robot.joint.q2.friction": 0.5}, 1.7, (0.5, 0.5)),
    "stickslip, 2/1 N·m on q2, 500 Hz": ("stickslip", {"robot.joint.q2.friction_static": 2.0,
                                                       "robot.joint.q2.friction_kinetic": 1.0,
                                                       "controller.sample_rate": 500.0}, 0.45, (0.0, 2.0)),
    "singular, 0.5 N·m on q1 and q2": ("singular", {"robot.joint.q1.friction": 0.5,
                                                    "robot.joint.q2.friction": 0.5}, 1.0, (0.5, 0.5)),
    "bounce, 2/1 N·m on q2, 500 Hz": ("bounce", {"robot.joint.q2.friction_static": 2.0,
                                                 "robot.joint.q2.friction_kinetic": 1.0,
                                                 "controller.sample_rate": 500.0}, 0.2, (0.0, 2.0)),
}


def _run(case: str):
    name, overrides, duration, _ = CASES[case]
    return simulate(str(HARD / f"{name}.toml"), {**overrides, "duration": duration})


@pytest.mark.parametrize("case", list(CASES))
def test_a_contact_and_a_joint_at_rest_get_one_mode_that_holds_past_the_instant(case):
    r = _run(case)
    assert r.stats["decided_together"] >= 1
    assert r.meta["check_warnings"] == []
    instants = np.unique([e["t"] for e in r.events if e["name"] in ("tip", "q1", "q2")])
    assert np.diff(instants).min() > 1e-9  # [s] (solver.storm_window) each instant's decisions hold: no chatter
    # Coulomb's cone wherever the tip is stuck, the elbow's static limit wherever it is stuck
    stuck = r["contact.tip.stuck"] > 0.5
    F_f, F_n = np.abs(r["contact.tip.F_f"][stuck]).ravel(), r["contact.tip.F_n"][stuck]
    assert np.all(F_f <= MU_S[CASES[case][0]] * F_n * (1.0 + 1e-6) + 1e-9)
    for j, tau_s in enumerate(CASES[case][3]):
        held = r["joint_stuck"][:, j] > 0.5
        assert np.all(np.abs(r["joint_friction"][held, j]) <= tau_s * (1.0 + 1e-9))


def test_the_search_runs_only_where_the_one_at_a_time_mode_is_contradicted(monkeypatch):
    """Each search starts from a mode with an item at rest that contradicts it (a slide decelerating through rest, or
    a stick beyond its limit) and ends in one where every item at rest is consistent: each slide from rest
    accelerates along its slide."""
    seen = []
    search = at_rest.consistent_at_rest

    def spy(system, runner, t, x, modes, phase):
        out = search(system, runner, t, x, modes, phase)
        if out[3]:
            seen.append((system, runner, t, (x, modes, phase), out[:3]))
        return out

    monkeypatch.setattr(at_rest, "consistent_at_rest", spy)
    _run("stickslip, 0.5 N·m on q2")
    assert seen
    for system, runner, t, before, after in seen:
        for (x, modes, phase), expected in ((before, False), (after, True)):
            nQ = system.nQ
            system.robot.update(x[:system.nv], x[nQ:nQ + system.nv])
            system.update_bodies(x)
            probe = at_rest._Probe(runner(modes, phase), t, x)
            joints = at_rest._joints_at_rest(system, probe, phase)
            contacts = at_rest._contacts_at_rest(system, probe, modes, at_rest._touching_with_friction(system, modes))
            assert joints
            assert at_rest._consistent(system, probe, modes, phase, contacts, joints) is expected
        x, modes, phase = after
        probe = at_rest._Probe(runner(modes, phase), t, x)
        for i, m in phase.joint_modes:  # a slide from rest leaves rest along its slide
            if m != 0:
                assert m * probe.xdot[system.nQ + i] > 0.0
