"""A whole run on the one pipeline (every mode compiled) agrees with the same run interpreted
(``LivePipelines.use = False``: every mode on the same call run as its Python twins): motors, elastic drives,
force-reading laws, a reference carried by a body, a 2-D slide launching from rest, a contact on another frame than
the tip."""

from __future__ import annotations

import numpy as np
import pytest

from contactdyn import parse_scene
from contactdyn.hybrid.loop import HybridRun
from contactdyn.model.paths import INTERPRETED, PIPELINE, LivePipelines
from contactdyn.model.pipeline.pack import N_FRAMES
from contactdyn.model.system import System
from contactdyn.scene.scene_file import load_scene
from contactdyn.simulate import run_system

TIGHT = {"solver.rtol": 1e-11, "solver.atol": 1e-13}  # (kept from the runs on the readable model, which differed by
# round-off: at the scenes' own tolerances a clip or a touch without an event shifted the step sequence)
#: each channel of the two runs, relative to its largest magnitude (the bound of the runs on the readable model,
#: kept): the interpreted run runs the same functions, measured bit for bit the compiled run's over this file's runs
RUN_RTOL = 1e-8


def _paths(result) -> set[str]:
    return {row["path"] for row in result.stats["paths"].values()}


def _both(scene, monkeypatch, overrides: dict | None = None):
    """(the run on the one pipeline compiled, the same run interpreted), each checked to be on its path."""
    make = (lambda: System(load_scene(scene, {**TIGHT, **overrides}))) if isinstance(scene, str) else \
        (lambda: System(parse_scene(scene)))
    compiled = run_system(make())
    with monkeypatch.context() as patch:
        patch.setattr(LivePipelines, "use", False)
        interpreted = run_system(make())
    assert _paths(compiled) == {PIPELINE}
    assert compiled.stats["compiled_modes"] >= 1
    assert _paths(interpreted) == {INTERPRETED}
    assert [(e["kind"], e.get("contact")) for e in compiled.events] == \
        [(e["kind"], e.get("contact")) for e in interpreted.events]
    return compiled, interpreted


def _close(compiled, interpreted, keys) -> None:
    for key in keys:
        a, b = compiled[key], interpreted[key]
        np.testing.assert_allclose(a, b, rtol=0, atol=RUN_RTOL * max(float(np.abs(b).max()), 1e-300), err_msg=key)


@pytest.mark.parametrize("u_max", [None, 4.0])  # None: the scene's own; 4 V: clips while the writer accelerates
def test_dc_motors_through_rigid_gears(u_max, monkeypatch):
    overrides = {"duration": 0.3} if u_max is None else {"duration": 0.3, "robot.drive.u_max": u_max}
    compiled, interpreted = _both("case2_writer_motors", monkeypatch, overrides)
    if u_max is not None:
        assert np.any(np.abs(interpreted["u"]) >= u_max)  # the clipping branch ran
    _close(compiled, interpreted, ("q", "v", "tau", "u"))


def test_an_elastic_transmission(monkeypatch):
    compiled, interpreted = _both("case3_a_position", monkeypatch, {"duration": 0.4})  # the approach, in free flight
    assert compiled.stats["compiled_modes"] == 1
    theta = next(k for k in compiled.channels if k.endswith(".theta"))
    _close(compiled, interpreted, ("q", "v", "tau", "u", theta))


def test_a_force_phase_through_an_elastic_transmission(monkeypatch):
    compiled, interpreted = _both("case3_b_force", monkeypatch, {"duration": 1.5})  # touch and press at 1.407 s
    assert compiled.stats["compiled_modes"] >= 2
    _close(compiled, interpreted, ("q", "tau", "u", "contact.tip.F_n"))


def test_a_reference_carried_by_a_body(monkeypatch):
    compiled, interpreted = _both("case1_cart", monkeypatch, {"duration": 1.1})  # the push rides on the cart from 1.0 s
    assert compiled.stats["compiled_modes"] >= 3
    _close(compiled, interpreted, ("q", "tau", "u", "body.cart.x", "contact.tip.F_n"))


def test_a_launch_from_rest(monkeypatch):
    """cylindrical3 pushed at 45° on a table until it breaks away (test_friction's anisotropic arm): the launch
    direction solved in the pipeline's compiled call is the interpreted call's."""
    doc = {"name": "cyl", "duration": 0.6, "solver": {"rtol": 1e-10, "atol": 1e-12, "output_rate": 1000.0},
           "robot": {"urdf": "cylindrical3", "q0": [0.0, 0.0, 1.0]},
           "contact": {"table": {"point": [0.0, 0.0, 0.2], "normal": {"direction": [0.0, 0.0, 1.0]},
                                 "tangent": {"model": "friction", "directions": [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]],
                                             "mu_s": 0.5, "mu_k": 0.3}}},
           "controller": {"kind": "task_force", "rate": [500.0 / np.sqrt(2), 500.0 / np.sqrt(2), 0.0]}}
    compiled, interpreted = _both(doc, monkeypatch)
    assert [e["kind"] for e in compiled.events] == ["stick", "slip"]
    assert compiled.stats["segments_by_method"]["LSODA"] == 1  # the launch segment
    _close(compiled, interpreted, ("q", "v", "contact.table.F_f", "contact.table.v_slip"))


@pytest.mark.parametrize("scene, duration", [("b1", 0.3), ("case2_writer_motors", 1.0)])
def test_a_contact_on_another_frame_than_the_tip(scene, duration, monkeypatch):
    """The contact on link2's frame, the controller on the tip's: the pipeline packs two frames, on B1 and on the
    writer's task PD through its DC motors; the run is the interpreted run's."""
    overrides = {**TIGHT, "duration": duration, "contact.tip.frame": "link2"}
    run = HybridRun(System(load_scene(scene, overrides)))
    run.run(0.0)
    assert {int(mode.pipe.packed.ints[N_FRAMES]) for mode in run.pipelines.pipes.values()} == {2}
    compiled, interpreted = _both(scene, monkeypatch, {"duration": duration, "contact.tip.frame": "link2"})
    _close(compiled, interpreted, ("q", "v", "contact.tip.F_n"))
