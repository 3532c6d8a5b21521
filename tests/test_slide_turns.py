"""A 2-D slide's ``turn`` events reuse its compiled mode: the reference direction r is data of the call."""

from __future__ import annotations

import copy
import math

import numpy as np
import pytest
from run_agreement import interpreted_evaluate

from contactdyn import parse_scene
from contactdyn.model import paths
from contactdyn.model.contact import ContactMode, structure
from contactdyn.model.pipeline.pipeline import Pipeline
from contactdyn.model.system import System
from contactdyn.simulate import run_system

M, G = 2.0, 9.81  #: [kg], [m/s²] the point mass and gravity
MU, PUSH, FREQ = 0.4, 10.0, 1.0  #: friction coefficient, push amplitude [N], push frequency [Hz]
COMPLIANT = {"model": "chain", "environment": [{"k": 1e6, "b": 2e3}]}  #: ground without a constraint row


def circle(normal: dict | None = None) -> dict:
    """A point mass pushed by P (cos ωt, sin ωt) on the ground: steady circular sliding, a turn every 60°."""
    w = 2 * math.pi * FREQ
    alpha = math.acos(MU * M * G / PUSH)
    s = PUSH * math.sin(alpha) / (M * w)  # [m/s] the steady speed (tests/test_friction.py)
    return {"name": "circle", "duration": 1.5, "solver": {"rtol": 1e-10, "atol": 1e-12, "output_rate": 200.0},
            "robot": {"urdf": "point_mass_xyz", "q0": [0.0, 0.0, 0.0], "v0": [s * math.cos(alpha),
                                                                              -s * math.sin(alpha), 0.0]},
            "contact": {"ground": {"point": [0.0, 0.0, 0.0], "normal": {"direction": [0.0, 0.0, 1.0], **(normal or {})},
                                   "tangent": {"model": "friction", "mu_s": MU, "mu_k": MU,
                                               "directions": [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]}}},
            "controller": {"kind": "task_force", "amplitude": [PUSH, PUSH, 0.0], "frequency": FREQ,
                           "phase": [math.pi / 2, 0.0, 0.0]}}


def test_every_turn_of_the_circle_runs_on_one_compiled_mode_and_gives_what_one_per_direction_gave(monkeypatch):
    doc = circle()
    reused = run_system(System(parse_scene(copy.deepcopy(doc))))
    turns = [e for e in reused.events if e["kind"] == "turn"]
    assert len(turns) >= 8 and len(turns) == len(reused.events)
    assert reused.stats["compiled_modes"] == 1  # one sliding mode, every direction
    assert {row["path"] for row in reused.stats["paths"].values()} == {paths.PIPELINE}
    monkeypatch.setattr(paths, "structure", tuple)  # a mode packed per reference direction
    per_direction = run_system(System(parse_scene(copy.deepcopy(doc))))
    assert per_direction.stats["compiled_modes"] == len(turns) + 1
    assert [e["t"] for e in per_direction.events] == pytest.approx([e["t"] for e in turns], rel=1e-12)
    for key in ("q", "v", "contact.ground.F_f", "contact.ground.v_slip", "contact.ground.F_n"):
        scale = float(np.abs(per_direction[key]).max())
        np.testing.assert_allclose(reused[key], per_direction[key], rtol=0, atol=1e-12 * scale)


@pytest.mark.parametrize("normal", [None, COMPLIANT], ids=["rigid", "compliant"])
def test_a_mode_reused_after_a_turn_equals_the_interpreted_call_at_the_new_direction(normal):
    """Rigid ground: d enters the KKT matrix (the normal row's column tilt); compliant: the Coulomb force.
    At rest and at a slip perpendicular to the new r (inside the stick band along it) the force follows r: the
    reused compiled mode's ẋ is the interpreted call's, packed at the new direction (interpreted_evaluate)."""
    system = System(parse_scene(circle(normal)))
    x0, _ = system.initial_state()
    phase = system.start_phase(0, 0.0, x0, None)
    before, after = [ContactMode(touching=True, slip=(1.0, 0.0))], [ContactMode(touching=True, slip=(0.0, 1.0))]
    plan = Pipeline(system, before, phase)
    plan.use(after)
    assert plan.modes == after
    nQ = system.nQ
    states = []
    for v in ([0.0, 0.0, 0.0], [0.3, 0.0, 0.0], [0.2, 0.5, 0.0]):  # at rest; across r; ahead of r
        x = x0.copy()
        x[2] = -M * G / COMPLIANT["environment"][0]["k"]  # [m] pressed in: the compliant ground bears the weight
        x[nQ:nQ + 3] = v
        states.append(x)
    t = 0.37
    for x in states:
        ref = interpreted_evaluate(system, t, x, after, phase).xdot
        got = plan.rhs(t, x.copy())
        assert np.abs(got - ref).max() <= 1e-10 * (1.0 + np.abs(ref).max())
    old = interpreted_evaluate(system, t, states[0], before, phase).xdot  # the direction does matter there
    assert np.abs(old - plan.rhs(t, states[0].copy())).max() > 1e-3


def test_a_compiled_mode_refuses_modes_of_another_structure():
    system = System(parse_scene(circle()))
    x0, _ = system.initial_state()
    phase = system.start_phase(0, 0.0, x0, None)
    sliding = [ContactMode(touching=True, slip=(1.0, 0.0))]
    plan = Pipeline(system, sliding, phase)
    assert structure([ContactMode(touching=True, slip=(0.6, 0.8))]) == structure(sliding)
    assert structure([ContactMode(touching=True, stuck=True, slip=(1.0, 0.0))]) != structure(sliding)
    with pytest.raises(ValueError, match="its own structure"):
        plan.use([ContactMode(touching=True, stuck=True, slip=(1.0, 0.0))])


def test_a_slide_is_at_its_stop_only_moving_along_r_at_the_bands_edge():
    """transitions._at_stop: a slide (not from rest) whose speed along r is within BAND_EDGE of the stick band v_ε
    and which moves along r (v·r ≥ ½|v|) is at its stop; one that moves across r (a turn: its speed along r ~0 while
    |v| is large), one still above the edge, and a slide from rest are not."""
    from contactdyn.hybrid.events import BAND_EDGE
    from contactdyn.hybrid.transitions import _at_stop

    band, r = 1e-9, (0.6, 0.8)
    mode = ContactMode(touching=True, slip=r)

    def at_stop(m, vt):
        return _at_stop(m, float(vt @ np.asarray(r)), float(np.linalg.norm(vt)), band)

    at_edge = band * (1.0 + 0.5 * BAND_EDGE) * np.array([0.6, 0.8]) + 0.4 * band * np.array([0.8, -0.6])
    assert at_stop(mode, at_edge)
    assert not at_stop(mode, at_edge * (1.0 + 2.0 * BAND_EDGE))  # (above the edge: its stop is ahead)
    assert not at_stop(mode, np.array([0.8, -0.6]))  # (1 m/s across r: a turn, not a stop)
    assert not at_stop(ContactMode(touching=True, slip=r, from_rest=True), at_edge)
