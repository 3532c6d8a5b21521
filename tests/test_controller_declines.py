"""Controllers the pipeline once declined (pack._controller_unsupported) run on it: A7 in joint space (its own
compiled kind), a user's law of the ABI outputting voltages, a user's law reading a joint-space reference, and
operational space bound with its set-points in another order than the phase's. Per case, the pipeline's compiled ẋ
against the interpreted call's (``run_agreement.interpreted_evaluate``) at a few states; whole runs on the compiled
call against the same runs interpreted (``LivePipelines.use = False``)."""

from __future__ import annotations

import sys
import warnings
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "benchmarks"))
from pipeline_proto import _scene, _touch, case, states  # noqa: E402
from run_agreement import interpreted_evaluate  # noqa: E402

from contactdyn import simulate  # noqa: E402
from contactdyn.laws import Controller, Param  # noqa: E402
from contactdyn.laws.controllers import CONTROLLERS  # noqa: E402
from contactdyn.model.paths import INTERPRETED, PIPELINE, LivePipelines  # noqa: E402
from contactdyn.model.pipeline.pack import unsupported  # noqa: E402
from contactdyn.model.pipeline.pipeline import Pipeline  # noqa: E402

RTOL = 1e-9  #: ‖ẋ − ẋ_interpreted‖∞ ≤ RTOL ‖ẋ_interpreted‖∞ (measured 0: bit for bit)


class JointVoltagePD(Controller):
    """A user's voltage law on a joint-space reference: u = K_u (q_d − q) + D_u (q̇_d − q̇) [V] per joint."""

    name = "joint_voltage_pd_decline_test"
    outputs = "voltage"
    reads_orientation = False
    params = (Param("gain", "V/rad", "K_u", 60.0), Param("damping", "V·s/rad", "D_u", 3.0))

    def command(self, inp):
        c = self.config
        return c.gain * (inp.x_d - inp.q) + c.damping * (inp.v_d - inp.v), None


class JointSpring(Controller):
    """A user's torque law on a joint-space reference: τ = K (q_d − q) + D (q̇_d − q̇) + H q̈_d [N·m]."""

    name = "joint_spring_decline_test"
    reads_orientation = False
    params = (Param("stiffness", "N·m/rad", "K", 300.0), Param("damping", "N·m·s/rad", "D", 20.0))

    def command(self, inp):
        c = self.config
        return c.stiffness * (inp.x_d - inp.q) + c.damping * (inp.v_d - inp.v) + inp.H @ inp.a_d, None


@pytest.fixture(scope="module", autouse=True)
def registered():
    """The two user laws registered for this module's scenes, the registry as it was after."""
    saved = dict(CONTROLLERS)
    CONTROLLERS.update({cls.name: cls for cls in (JointVoltagePD, JointSpring)})
    yield
    CONTROLLERS.clear()
    CONTROLLERS.update(saved)


def _joint_reference(doc: dict, delta: list[float], duration: float = 1.0) -> None:
    """Every phase tracking a joint-space trapezoid from where it starts (the phases' own controllers dropped)."""
    for phase in doc["phase"]:
        phase.pop("controller", None)
        phase["reference"] = {"space": "joint", "moves": [{"kind": "trapezoid", "delta": delta,
                                                           "duration": duration}]}


def _a7_joint(inertia: str = "model", reference: bool = True):
    """A7 in joint space (per-joint K_p), on a joint trapezoid (``reference``) or none (−K_v q̇)."""
    def edit(doc: dict) -> None:
        doc["controller"] = {"kind": "position_dynamic", "space": "joint", "kp": [400.0, 300.0], "kv": 40.0,
                             "inertia": inertia}
        _joint_reference(doc, [0.1, -0.05])
        if not reference:
            for phase in doc["phase"]:
                del phase["reference"]
    return edit


def _law(name: str):
    def edit(doc: dict) -> None:
        doc["controller"] = {"kind": name}
        _joint_reference(doc, [0.1, -0.05])
    return edit


def _two_set_points(doc: dict) -> None:
    """case2_writer5dof's press with a second set-point, 2 N on a wall x = 0.5 m (its normal −x, apart), operational
    space controlling y only."""
    doc["contact"]["wall"] = {"point": [0.5, 0.0, 0.0], "normal": {"direction": [-1.0, 0.0, 0.0], "model": "c",
                                                                     "k": 1e4, "b": 10.0}}
    doc["controller"]["axes"] = [[0.0, 1.0, 0.0]]
    doc["phase"] = doc["phase"][:1]
    doc["phase"][0]["force"].append({"contact": "wall", "value": 2.0, "kind": "step"})


def _reordered(system, modes, phase, x0):
    """The operational law bound with its set-points in the reverse of the phase's order (its F_d and force
    directions both reversed: the same law)."""
    ctl = phase.controller
    axes, forced, *rest = ctl.constants
    ctl.force_keys, ctl.constants = ctl.force_keys[::-1], (axes, np.ascontiguousarray(forced[::-1]), *rest)
    assert ctl.force_keys != list(phase.forces)
    return modes, phase


#: case -> (scene, edit of its TOML, change of its first mode or None)
CASES = {
    "a7_joint_bonded": ("sims/b1.toml", _a7_joint(), None),  # the bonded surface's row folded through τ_c
    "a7_joint_no_reference": ("sims/b1.toml", _a7_joint(reference=False), None),
    "a7_joint_link_motors": ("sims/case2_writer_motors.toml", _a7_joint("link"), None),
    "a7_joint_link_motors_touch": ("sims/case2_writer_motors.toml", _a7_joint("link"), _touch()),
    "voltage_law_motors": ("sims/case2_writer_motors.toml", _law(JointVoltagePD.name), None),
    "voltage_law_motors_touch": ("sims/case2_writer_motors.toml", _law(JointVoltagePD.name), _touch()),
    "joint_reference_law": ("sims/b1.toml", _law(JointSpring.name), None),
    "operational_reordered": ("sims/case2_writer5dof.toml", _two_set_points, _reordered),
}


@pytest.mark.parametrize("name", list(CASES))
def test_the_pipeline_gives_the_interpreted_rates(name):
    system, modes, phase, t, x0 = case(name, CASES)
    assert unsupported(system, modes, phase) == ""
    pipe = Pipeline(system, modes, phase)
    for x in states(x0, 4):
        ref = interpreted_evaluate(system, t, x, modes, phase).xdot
        got = pipe.rhs(t, x)
        assert np.abs(got - ref).max() <= RTOL * np.abs(ref).max()
    assert pipe.failed_calls == 0


@pytest.mark.parametrize("name", ["a7_joint_link_motors", "voltage_law_motors"])
def test_a_run_takes_the_compiled_call_and_gives_the_interpreted_run(name, monkeypatch):
    """case2_writer_motors' approach and the start of its write (0.6 s): every mode on the compiled call (no
    reason), q, v and the drives' voltages the interpreted run's to 1e-9, the same events."""
    path, edit, _ = CASES[name]

    def scene():
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            return _scene(path, lambda doc: (edit(doc), doc.update(duration=0.6)))

    live = simulate(scene())
    monkeypatch.setattr(LivePipelines, "use", False)
    interpreted = simulate(scene())
    assert {(row["path"], row["why"]) for row in live.stats["paths"].values()} == {(PIPELINE, "")}
    assert {row["path"] for row in interpreted.stats["paths"].values()} == {INTERPRETED}
    for channel in ("q", "v", "tau", "tau_cmd", "u"):
        scale = np.abs(interpreted[channel]).max()
        assert np.abs(live[channel] - interpreted[channel]).max() <= 1e-9 * scale, channel
    assert [(e["kind"], e.get("contact")) for e in live.events] == \
        [(e["kind"], e.get("contact")) for e in interpreted.events]


def test_joint_pd_on_a_tip_reference_of_a_two_joint_robot_is_a_scene_error():
    """The decline 'joint_pd with a reference of 3 coordinates (2 joints)' is gone: the readable law raised a
    broadcast error there, the scene's bind now names the key."""
    from contactdyn.errors import SceneError
    from contactdyn.model.system import System

    def edit(doc: dict) -> None:
        doc["controller"] = {"kind": "joint_pd", "kp": 100.0, "kd": 10.0}

    with pytest.raises(SceneError, match=r"phase\[0\]\.reference\.space.*'joint' \(joint_pd tracks the 2 joints\)"):
        System(_scene("sims/b1.toml", edit))
