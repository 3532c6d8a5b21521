"""Every scene of sims/ and benchmarks/hard/ both ways (issue 29, item 1): its first 0.2 s on the compiled call and
on the same call interpreted (the pipeline's own functions run as Python, :mod:`contactdyn.numerics.twins`): the
same source both ways, so the same channels and events to the bit (held to 1e-9 relative, the issue's bound); and
on the compiled call against the readable model (``LivePipelines.use = False``: every mode on System.evaluate), the
same channels and events.

The two paths take the same steps (the compiled DOP853 steps are scipy's core's arithmetic) on right-hand sides
equal to rounding; the step control amplifies that rounding up to a fraction of the run's tolerance (3.6e-9 of
b1_force_loop's stage force at its rtol 1e-8), so the runs are compared at rtol 1e-11: each channel within 1e-9 of
its largest value, plus 1e-10 (SI units) for channels that are zero in exact arithmetic (a tangential stage at
rest: 1e-15 m and 1e-11 N of rounding, measured). The two stiff scenes (``auto`` takes Radau: 47 s at rtol 1e-11)
run at their own tolerances and are held to the Newton iterations' tolerance: two roundings of the same right-hand
side and finite-difference Jacobian converge to solutions up to ~20× the scene's rtol·|x| + atol apart in a stiff
stage's rate (measured: fast_mass 18×, stiff 3×), so ≤ 50× that.
"""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
import pytest

from contactdyn.hybrid.loop import HybridRun
from contactdyn.model.paths import INTERPRETED, PIPELINE, READABLE, LivePipelines
from contactdyn.model.system import System
from contactdyn.scene.scene_file import load_scene
from contactdyn.simulate import run_system

ROOT = Path(__file__).resolve().parent.parent
#: scenes whose every mode the compiled call declines (pack.unsupported), with its reason: nothing to compare (none
#: now: a free body, drop_box, runs compiled in either chart)
READABLE_ONLY: dict[str, str] = {}
SCENES = sorted(str(p.relative_to(ROOT)) for folder in ("sims", "benchmarks/hard")
                for p in (ROOT / folder).glob("*.toml") if str(p.relative_to(ROOT)) not in READABLE_ONLY)
DURATION = 0.2  #: [s] of each scene
RTOL, FLOOR = 1e-9, 1e-10  #: explicit runs: relative to each channel's largest value, plus an absolute floor
NEWTON = 50.0  #: runs with Radau segments: this many times the scene's rtol·|value| + atol
EVENT_ATOL = 1e-9  #: [s] the events' times (measured ≤ 1.3e-13 s)
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


@pytest.mark.parametrize("scene", SCENES, ids=lambda s: Path(s).stem)
def test_a_scene_runs_the_same_on_the_compiled_call_and_on_the_readable_model(scene, monkeypatch):
    fast, readable = _run(scene, True, monkeypatch), _run(scene, False, monkeypatch)
    assert {row["path"] for row in fast.stats["paths"].values()} == {PIPELINE}
    assert {row["path"] for row in readable.stats["paths"].values()} == {READABLE}
    implicit = scene in STIFF
    assert implicit == ("Radau" in fast.stats.get("segments_by_method", {}))
    rtol, atol = fast.stats["rtol"], fast.stats["atol"]
    assert set(fast.channels) == set(readable.channels)
    for key, ref in readable.channels.items():
        ref, got = np.asarray(ref, float), np.asarray(fast.channels[key], float)
        assert np.array_equal(np.isnan(got), np.isnan(ref)), key
        if not ref.size or np.all(np.isnan(ref)):
            continue
        scale = float(np.nanmax(np.abs(ref)))
        allowed = NEWTON * (rtol * scale + atol) if implicit else RTOL * scale + FLOOR
        assert float(np.nanmax(np.abs(got - ref))) <= allowed, key
    assert [(e["kind"], e.get("name")) for e in fast.events] == [(e["kind"], e.get("name")) for e in readable.events]
    np.testing.assert_allclose([e["t"] for e in fast.events], [e["t"] for e in readable.events], rtol=0,
                               atol=EVENT_ATOL)
