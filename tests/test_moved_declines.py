"""Modes the compiled call used to decline, now packed (issue 29: the readable model's assembly had to become
deletable), each against the interpreted call (the same call run as its twins, ``run_agreement.interpreted_evaluate``):
ẋ at a few states of the mode, and a short whole run whose every mode takes the compiled call, its channels and
events the interpreted run's.

- A force-reading law with a turning surface: the lever's face (a surface on an articulated body's frame) and the
  tilting tray (a surface on a robot frame, a body's point on it), under examples/force_law.py's force PI law
  (τ = Jᵀ f − ½ τ_c): the turning contact's rows reach a body's coordinates, so they enter the measured contact
  torque τ_c and the fold (τ = τ₀ + B λ) probes them. Its set-point is on a second, fixed contact (a force
  set-point on a turning contact is a SceneError).
- A reference carried by an articulated body: a cart (prismatic along x) carrying a pendulum, the tool's
  reference riding the cart's coordinate (x_d = axis · Q_cart + reference, its acceleration folded as M's column
  of that coordinate, which the cart shares with the pendulum in H_b). A scene cannot name such a body yet
  (``reference.body``: a SceneError), so the tests set the phase's reference body on the parsed scene.
- Two 2-D slides launching from rest at once: the UR5's pencil on the table and its wrist on a wall, the compiled
  launch nesting the later contact's Newton inside each trial of the earlier one's (as the readable model did).
"""

from __future__ import annotations

import tomllib
import warnings
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from run_agreement import assert_runs_agree, interpreted_evaluate

from contactdyn import parse_scene, simulate
from contactdyn.hybrid.pipeline_mode import PipelineMode, mode_runner
from contactdyn.model.friction import launching
from contactdyn.model.paths import LivePipelines
from contactdyn.model.pipeline.pack import CARRIER, READS_FORCES, unsupported
from contactdyn.model.pipeline.pipeline import Pipeline
from contactdyn.scene.user_laws import import_scene_modules
from contactdyn.simulate import prepare

ROOT = Path(__file__).resolve().parents[1]
RTOL = 1e-9  #: each component of ẋ to RTOL × (1 + its largest magnitude over the states)
FORCE_PI = {"kind": "force_pi", "stiffness": 1e4, "damping": 300.0, "damping_n": 50.0, "ki": 20.0, "cancel": 0.5}


def _doc(path: str) -> dict:
    return tomllib.loads((ROOT / path).read_text())


def _parse(doc: dict, path: str):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # (the sanity notes: force_pi's set-point, a surface starting pressed)
        return parse_scene(doc, file=str(ROOT / path))


def _force_pi(doc: dict, floor: dict, duration: float) -> dict:
    """The scene under the force PI law (examples/force_law.py) with a Kelvin–Voigt contact ``floor`` at the tip
    carrying its 20 N set-point."""
    import_scene_modules(["force_law"], str(ROOT / "examples" / "force_pi_press.toml"))
    doc["imports"], doc["duration"], doc["controller"] = ["force_law"], duration, dict(FORCE_PI)
    doc["solver"]["record_energy"] = False
    doc["contact"]["floor"] = {"normal": {"direction": [0.0, 0.0, 1.0], "model": "c", "k": 1e5, "b": 100.0},
                               **floor}
    doc["phase"][0]["force"] = [{"contact": "floor", "value": 20.0, "kind": "step"}]
    return doc


def lever_pi(duration: float = 0.3):
    """sims/lever.toml (its face turns with the bar) under force PI, the tool on a floor 1 mm into it (μ 0.2)."""
    floor = {"frame": "tip", "point": [0.0, 0.0, 0.201],
             "tangent": {"model": "friction", "directions": [[1.0, 0.0, 0.0]], "mu": 0.2}}
    return _parse(_force_pi(_doc("sims/lever.toml"), floor, duration), "sims/lever.toml")


def tray_pi(duration: float = 0.3):
    """sims/tilt_tray.toml (its surface turns with the robot's tray frame), the part 5 cm off the axis, under force
    PI (a task reference at the tray's origin; the set-point on a Kelvin–Voigt contact at it)."""
    doc = _force_pi(_doc("sims/tilt_tray.toml"), {"frame": "tray", "point": [0.0, 0.0, 0.0]}, duration)
    doc["body"]["part"]["position0"] = [0.05, 0.0]
    doc["phase"][0]["reference"] = {"start": [0.0, 0.0, 0.0]}
    return _parse(doc, "sims/tilt_tray.toml")


def _touching(scene, stuck: bool):
    """(system, every contact touching, stuck or sliding, phase, t [s], x0)."""
    system, modes, phase, x0 = prepare(scene)
    modes = [m.with_(touching=True, stuck=stuck, offsets=tuple(0.0 for _ in c.tangent_chains))
             for c, m in zip(system.contacts, modes, strict=True)]
    return system, modes, phase, phase.t_start + 0.0123, x0


def _states(x0: np.ndarray, count: int = 4) -> list[np.ndarray]:
    rng = np.random.default_rng(5)
    return [x0.copy(), *(x0 + 1e-3 * (1.0 + np.abs(x0)) * rng.normal(size=x0.size) for _ in range(count - 1))]


def _assert_rates_agree(pipe, system, modes, phase, t, xs) -> np.ndarray:
    """The pipeline's ẋ is the interpreted call's at each state (RTOL per component); the interpreted ẋ's."""
    refs = np.array([interpreted_evaluate(system, t, x, modes, phase).xdot for x in xs])
    got = np.array([pipe.rhs(t, x.copy()) for x in xs])
    assert pipe.failed_calls == 0  # (every call answered: each ẋ is the pipeline's own)
    scale = 1.0 + np.abs(refs).max(axis=0)
    worst = float((np.abs(got - refs) / scale).max())
    assert worst <= RTOL, worst
    return refs


def _both_ways(scene_of, monkeypatch):
    fast = simulate(scene_of())
    monkeypatch.setattr(LivePipelines, "use", False)
    return fast, simulate(scene_of())


# ---- a force-reading law with a turning surface ------------------------------------------------------------------

@pytest.mark.parametrize("scene_of", [lever_pi, tray_pi], ids=["lever_face", "tilting_tray"])
@pytest.mark.parametrize("stuck", [False, True], ids=["sliding", "stuck"])
def test_a_force_reading_law_with_a_turning_surface_runs_compiled_with_the_interpreted_rates(scene_of, stuck):
    """ẋ the interpreted call's; and the fold is what makes it so: without B the rates are off (the turning
    contact's rows reach a body, so the law reads their force through τ_c)."""
    system, modes, phase, t, x0 = _touching(scene_of(), stuck)
    assert any(c.turning for c in system.contacts) and phase.controller.uses_forces
    assert unsupported(system, modes, phase) == ""
    pipe = Pipeline(system, modes, phase)
    xs = _states(x0)
    refs = _assert_rates_agree(pipe, system, modes, phase, t, xs)
    pipe.packed.ints[READS_FORCES] = 0  # (no fold: the law reads the forces before the solve)
    unfolded = np.array([pipe.rhs(t, x.copy()) for x in xs])
    assert float(np.abs(unfolded - refs).max()) > 1e-6 * float(np.abs(refs).max())


def test_a_sampled_force_law_measures_a_turning_contact_on_the_compiled_call_as_the_interpreted_call():
    """The lever under force PI sampled at 1 kHz: the measured forces and τ_c (the rows of the turning face reach
    the bar) off the compiled call are the interpreted call's."""
    scene = lever_pi()
    doc = dict(scene.document)
    doc["controller"] = {**doc["controller"], "sample_rate": 1000.0}
    system, modes, phase, t, x0 = _touching(_parse(doc, "sims/lever.toml"), stuck=False)
    assert unsupported(system, modes, phase) == ""
    mode, twin = PipelineMode(Pipeline(system, modes, phase)), mode_runner(system, compiled=False)(modes, phase)
    assert twin.interpreted
    for x in _states(x0, 3):
        got, ref = mode.measurement(t, x), twin.measurement(t, x)
        scale = 1.0 + float(np.abs(ref.tau_contact).max())
        np.testing.assert_allclose(got.tau_contact, ref.tau_contact, rtol=0, atol=1e-12 * scale)
        for c in system.contacts:
            assert got.normal_force[c.name] == pytest.approx(ref.normal_force[c.name], abs=1e-12 * scale)
    assert np.any(ref.tau_contact != 0.0)


def test_the_lever_under_a_force_reading_law_runs_compiled_and_the_interpreted_run_agrees(monkeypatch):
    """0.3 s: the tool sticks then slides on the floor, strikes the bar's face and slides along it; every mode on
    the compiled call, the run the interpreted one's."""
    fast, interpreted = _both_ways(lever_pi, monkeypatch)
    assert fast.stats["singular_solves"] == 0
    assert any(e["kind"] == "touch" and e["name"] == "push" for e in fast.events)
    assert_runs_agree(fast, interpreted)


# ---- a reference carried by an articulated body ------------------------------------------------------------------

CART_PENDULUM = """<?xml version="1.0"?>
<robot name="cart_pendulum">
  <link name="base"/>
  <joint name="slide" type="prismatic"><parent link="base"/><child link="cart"/>
    <origin xyz="0 0 0.6" rpy="0 0 0"/><axis xyz="1 0 0"/>
    <limit lower="-10.0" upper="10.0" effort="1e4" velocity="100.0"/></joint>
  <link name="cart"><inertial><origin xyz="0 0 0" rpy="0 0 0"/><mass value="2.0"/>
    <inertia ixx="0.01" ixy="0" ixz="0" iyy="0.01" iyz="0" izz="0.01"/></inertial></link>
  <joint name="pivot" type="revolute"><parent link="cart"/><child link="bar"/>
    <origin xyz="0 0 0" rpy="0 0 0"/><axis xyz="0 1 0"/>
    <limit lower="-3.0" upper="3.0" effort="1e4" velocity="100.0"/></joint>
  <link name="bar"><inertial><origin xyz="0 0 -0.25" rpy="0 0 0"/><mass value="1.0"/>
    <inertia ixx="0.0208333333333333" ixy="0" ixz="0" iyy="0.0208333333333333" iyz="0" izz="1e-6"/></inertial>
  </link>
</robot>
"""  #: a 2 kg cart 0.6 m up on a slide along x [m], the lever's 1 kg, 0.5 m bar hanging from it on a pivot [rad]
OPERATIONAL = {"kind": "operational_space", "axes": [[1.0, 0.0, 0.0], [0.0, 0.0, 1.0]], "kp": 1e4, "kd": 300.0}
POSITION_DYNAMIC = {"kind": "position_dynamic", "kp": 400.0, "kv": 40.0}


@pytest.fixture(scope="module")
def cart_urdf(tmp_path_factory) -> str:
    path = tmp_path_factory.mktemp("cart") / "cart_pendulum.urdf"
    path.write_text(CART_PENDULUM)
    return str(path)


def cart_carried(urdf: str, controller: dict, duration: float = 0.3):
    """sims/lever.toml with the bar hanging from a cart (``urdf``), under ``controller``, the tool's reference
    riding the cart (set on the parsed scene: the reader refuses a body with revolute joints)."""
    doc = _doc("sims/lever.toml")
    doc["body"]["lever"] = {"urdf": urdf, "position0": [0.0, 0.0]}
    doc["controller"], doc["duration"] = dict(controller), duration
    scene = _parse(doc, "sims/lever.toml")
    phase = scene.phases[0]
    return replace(scene, phases=(replace(phase, reference=replace(phase.reference, body="lever")),))


@pytest.mark.parametrize("controller", [OPERATIONAL, POSITION_DYNAMIC], ids=["operational_space", "A7"])
@pytest.mark.parametrize("touching", [False, True], ids=["apart", "sliding"])
def test_a_reference_carried_by_an_articulated_body_runs_compiled_with_the_interpreted_rates(cart_urdf, controller,
                                                                                           touching):
    """ẋ the interpreted call's; and the carrier is what makes it so: without it the rates are off."""
    system, modes, phase, x0 = prepare(cart_carried(cart_urdf, controller))
    modes = [m.with_(touching=touching) for m in modes]
    body = system.articulated["lever"]
    assert phase.carrier is not None and phase.carrier[0] == body.first and len(body.indices) == 2
    assert unsupported(system, modes, phase) == ""
    pipe, t, xs = Pipeline(system, modes, phase), phase.t_start + 0.0123, _states(x0)
    refs = _assert_rates_agree(pipe, system, modes, phase, t, xs)
    pipe.packed.ints[CARRIER] = -1  # (the reference no longer rides: neither its position nor its acceleration)
    fixed = np.array([pipe.rhs(t, x.copy()) for x in xs])
    assert float(np.abs(fixed - refs).max()) > 1e-6 * float(np.abs(refs).max())


def test_a_reference_carried_by_a_cart_with_a_pendulum_runs_compiled_and_the_interpreted_run_agrees(cart_urdf,
                                                                                                  monkeypatch):
    """0.3 s under operational space: the tool strikes the bar, sticks, then slides along it, the cart pushed
    along; every mode on the compiled call, the run the interpreted one's."""
    fast, interpreted = _both_ways(lambda: cart_carried(cart_urdf, OPERATIONAL), monkeypatch)
    assert fast.stats["singular_solves"] == 0
    assert [(e["kind"], e["name"]) for e in fast.events] == [("touch", "push"), ("slip", "push")]
    assert float(np.abs(fast["body.lever.slide.x"]).max()) > 1e-4  # [m] the cart moves, and the reference with it
    assert_runs_agree(fast, interpreted)


# ---- two 2-D slides launching from rest at once ------------------------------------------------------------------

UR5 = "sims/case2_writer_ur5.toml"


def _ur5_doc() -> dict:
    """The UR5 writer under task PD holding its pencil (benchmarks/pipeline_proto.py's ``_tool_pd``)."""
    doc = _doc(UR5)
    ctl = doc["controller"]
    doc["controller"] = {"kind": "task_pd", "kp": ctl["kp"], "kd": ctl["kd"], "axes": ctl["axes"],
                         "tool_axis": ctl["tool_axis"], "tool_target": ctl["tool_target"], "ko": 5.0, "do": 0.5,
                         "kd_normal": ctl["kd_normal"], "feedforward": "gravity"}
    line = {"kind": "trapezoid", "delta": [-0.03, 0.0, 0.0], "duration": 4.0, "accel_fraction": 0.2}
    doc["phase"][1]["reference"] = {"moves": [line]}
    return doc


def ur5_wall(mu_pencil: float = 0.4, mu_wall: float = 0.5, duration: float = 4.5):
    """The UR5 writer whose wrist_1_link also presses a wall 5 mm deep at its start pose (normal world x,
    Kelvin–Voigt 1e4 N/m: 50 N), 2-D friction on both contacts (μ as given)."""
    system, _, _, x0 = prepare(_parse(_ur5_doc(), UR5))
    p = system.robot.frame_position(x0[:system.nv], system.robot.frame_id("wrist_1_link"))
    doc = _ur5_doc()
    doc["duration"] = duration
    doc["contact"]["pencil"]["tangent"]["mu"] = mu_pencil
    doc["contact"]["wall"] = {"frame": "wrist_1_link", "point": (p + [5e-3, 0.0, 0.0]).tolist(),
                              "normal": {"direction": [1.0, 0.0, 0.0], "model": "c", "k": 1e4, "b": 10.0},
                              "tangent": {"model": "friction", "directions": [[0.0, -1.0, 0.0], [0.0, 0.0, -1.0]],
                                          "mu": mu_wall}}
    return _parse(doc, UR5)


def _launched_along(system, x: np.ndarray, xdot: np.ndarray, i: int) -> np.ndarray:
    """The direction contact i launched along at rest (x's velocities 0): where its tip accelerates,
    d = a_t / |a_t| (a_t: the tangents' J Q̈; a converged Newton's d has a_t(d) ∥ d ahead)."""
    nQ, nv, c = system.nQ, system.nv, system.contacts[i]
    system.robot.update(x[:nv], x[nQ:nQ + nv])
    kin = system.kinematics(c, x)
    a_t = np.asarray(kin.tangents) @ (kin.J @ xdot[nQ:nQ + nv])
    return a_t / np.linalg.norm(a_t)


def _sliding(system, modes, phase, t: float, x: np.ndarray, slips) -> np.ndarray:
    """ẋ with every contact sliding along ``slips`` (from_rest False: no launch), on the compiled call."""
    flat = [m.with_(slip=tuple(s), from_rest=False) for m, s in zip(modes, slips, strict=True)]
    return Pipeline(system, flat, phase).rhs(t, x.copy())


def _in_order(system, modes, phase, t: float, x: np.ndarray) -> np.ndarray:
    """ẋ with the directions found contact after contact (the order the compiled call launched in before nesting):
    the pencil's Newton with the wrist sliding along its r, then the wrist's with the pencil sliding along the
    direction found (each a launch of one contact on the compiled call)."""
    r_wall = modes[1].slip
    first = [modes[0], modes[1].with_(from_rest=False)]
    d_pencil = _launched_along(system, x, Pipeline(system, first, phase).rhs(t, x.copy()), 0)
    second = [modes[0].with_(slip=tuple(d_pencil), from_rest=False), modes[1]]
    assert np.abs(d_pencil - modes[0].slip).max() > 1e-3 and launching(second[1]) and r_wall == second[1].slip
    return Pipeline(system, second, phase).rhs(t, x.copy())


def test_two_slides_launching_at_once_run_compiled_with_the_interpreted_rates():
    """The pencil and the wrist on the wall, both sliding from rest (the robot at rest) along r = (1, 0) and
    (cos 60°, sin 60°): both Newtons converge off r at x0 (the pencil to (0.9996, 0.0281), the wrist to
    (0.4373, 0.8993): where each tip accelerates, and sliding along them gives the launched ẋ). The call nests them
    (each trial of the pencil's launches the wrist first): ẋ the interpreted call's at x0 and near it; launched in
    order instead, ẋ misses by ~1e-2 at x0."""
    system, modes, phase, x0 = prepare(ur5_wall())
    phase = system.start_phase(1, phase.t_start + 1.0, x0, phase)
    slips = ((1.0, 0.0), (0.5, float(np.sqrt(0.75))))
    modes = [m.with_(touching=True, stuck=False, from_rest=True, slip=s) for m, s in zip(modes, slips, strict=True)]
    assert sum(launching(m) for m in modes) == 2 and unsupported(system, modes, phase) == ""
    t, xs = phase.t_start + 0.0123, _states(x0)
    for x in xs:
        x[system.nQ:2 * system.nQ] = 0.0  # at rest: both inside the stick band
    refs = _assert_rates_agree(Pipeline(system, modes, phase), system, modes, phase, t, xs)
    found = [_launched_along(system, xs[0], refs[0], i) for i in range(2)]
    np.testing.assert_allclose(found, [[0.9996, 0.0281], [0.4373, 0.8993]], rtol=0, atol=1e-4)
    assert all(np.abs(np.subtract(f, s)).max() > 1e-2 for f, s in zip(found, slips, strict=True))
    along = _sliding(system, modes, phase, t, xs[0], found)
    assert float((np.abs(along - refs[0]) / (1.0 + np.abs(refs).max(axis=0))).max()) <= 1e-9
    in_order = _in_order(system, modes, phase, t, xs[0])
    assert float((np.abs(in_order - refs[0]) / (1.0 + np.abs(refs).max(axis=0))).max()) > 1e-4


def test_two_slides_launching_at_once_from_the_start_run_compiled_and_the_interpreted_run_agrees(monkeypatch):
    """μ 0.05 on both: at t = 0 neither can stick, both slide from rest (two launches in one mode) for 25 ms; the
    mode on the compiled call, the run the interpreted one's (the nested Newton the same functions either way)."""
    fast, interpreted = _both_ways(lambda: ur5_wall(0.05, 0.05, 0.025), monkeypatch)
    assert [(e["kind"], e["name"], e["t"]) for e in fast.events] == [("slip", "pencil", 0.0), ("slip", "wall", 0.0)]
    assert fast.stats["singular_solves"] == 0
    assert_runs_agree(fast, interpreted)
