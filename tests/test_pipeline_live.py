"""The one pipeline runs every mode it packs (contactdyn.model.paths.LivePipelines): a user's laws by address.

Each run is compared with the same run interpreted (``LivePipelines.use = False``: every mode on the same call run
as its Python twins): outputs within 1e-9 relative, the same events at the same times, the paths table naming it.
"""

from __future__ import annotations

import copy
import sys
import tomllib
import warnings
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent))
from test_compiled_path import axis_scene  # noqa: E402

from contactdyn import parse_scene, simulate  # noqa: E402
from contactdyn.model.paths import INTERPRETED, PIPELINE, LivePipelines  # noqa: E402

CUBIC = Path(__file__).resolve().parent.parent / "examples" / "cubic_press.toml"
#: a Hunt–Crossley stage soft enough in damping that the falling axis bounces off (a separation on the pipeline)
HUNT_CROSSLEY = {"model": "chain", "environment": [{"k": 1e7, "b": 1e5, "law": "hunt_crossley", "exponent": 1.5}]}


@pytest.fixture(autouse=True)
def registry(fresh_user_imports):
    """The cubic example imports the user's module; each test leaves the registries as they were (conftest)."""
    yield
    sys.modules.pop("cubic_stage", None)


def cubic_scene():
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return parse_scene(copy.deepcopy(tomllib.loads(CUBIC.read_text())), file=str(CUBIC))


def both_ways(scene, monkeypatch):
    """(the run with the one pipeline compiled, the same run interpreted)."""
    live = simulate(scene)
    monkeypatch.setattr(LivePipelines, "use", False)
    interpreted = simulate(scene)
    monkeypatch.setattr(LivePipelines, "use", True)
    return live, interpreted


def assert_same_run(live, interpreted, channels, event_atol: float = 1e-12) -> None:
    for channel in channels:
        scale = np.abs(interpreted[channel]).max()
        assert np.abs(live[channel] - interpreted[channel]).max() <= 1e-9 * scale, channel
    assert [(e["kind"], e.get("contact")) for e in live.events] == \
        [(e["kind"], e.get("contact")) for e in interpreted.events]
    np.testing.assert_allclose([e["t"] for e in live.events], [e["t"] for e in interpreted.events], rtol=0,
                               atol=event_atol)


def test_the_cubic_stage_runs_on_the_pipeline_as_interpreted(monkeypatch):
    live, interpreted = both_ways(cubic_scene(), monkeypatch)
    assert {label: (row["path"], row["why"]) for label, row in live.stats["paths"].items()} == \
        {"press: tip touching": (PIPELINE, "")}
    assert [row["path"] for row in interpreted.stats["paths"].values()] == [INTERPRETED]
    assert_same_run(live, interpreted, ("q", "v", "tau", "contact.tip.F_n", "stage.tip.n.env1.x"))
    assert live.stats["rhs_evals"] > 100


def test_a_hunt_crossley_bounce_runs_on_the_pipeline_and_separates_at_the_same_time(monkeypatch):
    live, interpreted = both_ways(axis_scene(HUNT_CROSSLEY, duration=0.1), monkeypatch)
    assert [e["kind"] for e in live.events] == ["touch", "separate"]  # the separation: on the pipeline's mode
    assert live.stats["paths"]["main: tip touching"] == {"path": PIPELINE, "why": "", "segments": 1}
    assert live.stats["paths"]["main: tip free"]["path"] == PIPELINE
    # Hunt–Crossley's force is 0 from x = 0 on: ``separate`` fires at the first step end there; the interpreted run
    # takes the same steps (hybrid.steps' twins), so the same step ends (measured bitwise the same here; the bound
    # is the one the run on the readable model, with scipy's core steps, needed: 5.8e-8 s apart)
    assert_same_run(live, interpreted, ("q", "v", "contact.tip.F_n"), event_atol=1e-6)


def test_a_stuck_contact_runs_on_the_pipeline_its_slip_watch_reading_the_pipeline(monkeypatch):
    """A stuck contact's slip watch reads the pipeline's event values (its stick force, at every stage): the same run
    as interpreted."""
    doc = tomllib.loads(CUBIC.read_text())
    doc["contact"]["tip"]["tangent"] = {"model": "friction", "directions": [[1.0, 0.0, 0.0]], "mu_s": 0.9,
                                        "mu_k": 0.8}
    doc["duration"] = 0.05
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        live, interpreted = both_ways(parse_scene(doc, file=str(CUBIC)), monkeypatch)
    paths = {label: row["path"] for label, row in live.stats["paths"].items()}
    assert paths["press: tip stuck"] == PIPELINE, paths
    assert {row["path"] for row in interpreted.stats["paths"].values()} == {INTERPRETED}
    assert_same_run(live, interpreted, ("q", "v", "tau", "contact.tip.F_n", "contact.tip.F_f"))


def test_an_energy_audit_runs_on_the_pipeline_and_balances(monkeypatch):
    """B1 with the audit, joint and viscous friction, for 50 ms: every mode on the
    pipeline, the audit's work and dissipation as in the interpreted run, the energy residual as small."""
    path = Path(__file__).resolve().parent.parent / "sims" / "b1.toml"
    doc = tomllib.loads(path.read_text())
    doc["duration"] = 0.05
    doc["solver"]["record_energy"] = True
    doc["contact"]["tip"]["tangent"]["viscous"] = 5.0
    doc["robot"]["joint"] = {"q1": {"damping": 0.5, "friction_static": 3.0, "friction_kinetic": 2.0}}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        scene = parse_scene(doc, file=str(path))
    live, interpreted = both_ways(scene, monkeypatch)
    assert {row["path"] for row in live.stats["paths"].values()} == {PIPELINE}
    assert_same_run(live, interpreted, ("q", "v", "tau", "contact.tip.F_n", "energy.work", "energy.dissipated"))
    assert live["energy.dissipated"][-1] > 0.1  # [J] friction and damping took some
    residual = [r.meta["checks"]["energy_residual"]["value"] for r in (live, interpreted)]
    assert residual[0] <= 1e-6 * live["energy.work"].max() and residual[0] == pytest.approx(residual[1], abs=1e-9)
