"""Runs that cannot silently do nothing (contactdyn.output.outcome, and sanity's reach check before a run)."""

from __future__ import annotations

import copy
import warnings

import pytest

from contactdyn import parse_scene, simulate
from contactdyn.output.metrics import metrics
from contactdyn.scene.sanity import SanityWarning


def hover(approach: float, phases: list[dict] | None = None) -> dict:
    """The point mass 0.1 m above a rigid ground, a task PD with gravity feedforward; phase[0] moves it down by
    ``approach`` [m] and ends at the touch, phase[1] presses 10 N."""
    return {
        "name": "hover", "duration": 0.6,
        "solver": {"output_rate": 500.0},
        "robot": {"urdf": "point_mass_xz", "q0": [0.0, 0.1]},
        "contact": {"ground": {"point": [0.0, 0.0, 0.0], "normal": {"direction": [0.0, 0.0, 1.0]}}},
        "controller": {"kind": "task_pd", "kp": 400.0, "kd": 40.0, "feedforward": "gravity"},
        "phase": phases or [
            {"name": "approach", "until": "touch:ground",
             "reference": {"moves": [{"kind": "trapezoid", "delta": [0.0, 0.0, -approach], "duration": 0.3}]}},
            {"name": "press", "controller": {"axes": [[1.0, 0.0, 0.0]]},
             "force": [{"contact": "ground", "value": 10.0, "duration": 0.05}]},
        ],
    }


def run(doc: dict):
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", SanityWarning)
        result = simulate(parse_scene(copy.deepcopy(doc)))
    issued = [str(w.message) for w in caught if issubclass(w.category, SanityWarning)]
    assert all(any(note in text for text in issued) for note in result.meta["warnings"])
    return result


def test_an_approach_that_stops_short_is_flagged_before_and_after_the_run():
    r = run(hover(0.05))
    notes = r.meta["warnings"]
    assert any("starts 0.1 m from the surface" in n and "no closer than 0.05 m" in n for n in notes)
    assert any("phase[0] (approach) ends at touch:ground, which never came" in n and "phase[1] (press) never "
               "started" in n for n in notes)
    assert any("contact 'ground' never touched, though force set-points name it" in n for n in notes)
    assert metrics(r)["warnings"] == len(notes) == 3
    assert r["contact.ground.F_n"].max() == 0.0


def test_an_approach_that_reaches_the_surface_is_not_flagged():
    r = run(hover(0.12))
    assert r.meta["warnings"] == []
    assert r["contact.ground.F_n"][-1] == pytest.approx(10.0, rel=1e-3)


def test_a_set_point_active_while_its_contact_is_off_in_that_phase_is_flagged():
    """phase[0] holds the tip 0.1 m up for 0.2 s with a set-point on the ground (never touching then);
    phase[1] brings it down onto the ground: only phase[0] is flagged."""
    phases = [{"name": "hold", "until": 0.2, "force": [{"contact": "ground", "value": 10.0, "kind": "step"}]},
              {"name": "descend", "reference": {"moves": [{"kind": "trapezoid", "delta": [0.0, 0.0, -0.12],
                                                           "duration": 0.2}]}}]
    r = run(hover(0.0, phases))
    notes = [n for n in r.meta["warnings"] if "was active" in n]
    assert notes == ["phase[0] (hold): the force set-point on contact 'ground' was active from 0 s to 0.2 s but "
                     "the contact never touched then: it applied nothing"]
    assert r["contact.ground.touching"][-1] == 1
    assert not any("never touched, though" in n for n in r.meta["warnings"])
