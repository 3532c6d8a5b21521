"""Every scene of sims/ and benchmarks/hard/ both ways (issue 29, item 1): its first 0.2 s on the compiled call and
on the same call interpreted (the pipeline's own functions run as Python, :mod:`contactdyn.numerics.twins`): the
same source both ways, so the same channels, events and steps to the bit (held to 1e-9 relative, the issue's
bound). A run with ``LivePipelines.use = False`` (or ``compiled=False``) is such an interpreted run: there is no
other model a run takes.

The explicit scenes run at rtol 1e-11 (the step control would amplify any rounding between the two up to a fraction
of the run's tolerance); the two stiff scenes (``auto`` takes Radau: 47 s at rtol 1e-11) at their own tolerances.
"""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
import pytest

from contactdyn.hybrid.loop import HybridRun
from contactdyn.model.paths import INTERPRETED, PIPELINE, LivePipelines
from contactdyn.model.system import System
from contactdyn.scene.scene_file import load_scene
from contactdyn.simulate import run_system

ROOT = Path(__file__).resolve().parent.parent
SCENES = sorted(str(p.relative_to(ROOT)) for folder in ("sims", "benchmarks/hard")
                for p in (ROOT / folder).glob("*.toml"))
DURATION = 0.2  #: [s] of each scene
RTOL = 1e-9  #: relative to each channel's largest value (the events' times too)
TIGHT = {"solver.rtol": 1e-11, "solver.atol": 1e-13}  #: rounding amplified by the step control shrinks with it
STIFF = {"benchmarks/hard/stiff.toml", "benchmarks/hard/fast_mass.toml"}  #: at their own tolerances (Radau)


def _run(scene: str, compiled: bool, monkeypatch, interpreted: bool = False):
    monkeypatch.setattr(LivePipelines, "use", compiled)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        settings = {"duration": DURATION, **({} if scene in STIFF else TIGHT)}
        system = System(load_scene(ROOT / scene, settings))
        return HybridRun(system, interpreted=interpreted).run(0.0) if interpreted else run_system(system)


@pytest.mark.parametrize("scene", SCENES, ids=lambda s: Path(s).stem)
def test_a_scene_runs_the_same_compiled_and_interpreted(scene, monkeypatch):
    fast, slow = _run(scene, True, monkeypatch), _run(scene, True, monkeypatch, interpreted=True)
    assert {row["path"] for row in fast.stats["paths"].values()} == {PIPELINE}
    assert {row["path"] for row in slow.stats["paths"].values()} == {INTERPRETED}
    assert set(fast.channels) == set(slow.channels)
    for key, ref in slow.channels.items():
        ref, got = np.asarray(ref, float), np.asarray(fast.channels[key], float)
        assert np.array_equal(np.isnan(got), np.isnan(ref)), key
        if ref.size and not np.all(np.isnan(ref)):
            assert float(np.nanmax(np.abs(got - ref))) <= RTOL * float(np.nanmax(np.abs(ref))), key
    assert [(e["kind"], e.get("name")) for e in fast.events] == [(e["kind"], e.get("name")) for e in slow.events]
    np.testing.assert_allclose([e["t"] for e in fast.events], [e["t"] for e in slow.events], rtol=RTOL, atol=0)
    assert fast.stats["steps"] == slow.stats["steps"]
