"""A free body (issue 32; ``sims/drop_box.toml``): a 1 kg box 0.1 × 0.2 × 0.3 m (``sims/free_box.urdf``, its frame at
its centre along its principal axes) whose root link has six coordinates of the system, nq = nv: x, y, z [m] of its
centre, then its ZYX Euler angles yaw, pitch, roll [rad] (R = Rz(yaw) Ry(pitch) Rx(roll)). Closed forms: thrown
free, its centre follows p0 + v0 t + g t²/2, its rotational energy ½ ωᵀ I ω and its angular momentum in the world
R I Rᵀ ω stay constant (a spin about a principal axis; about the intermediate axis, perturbed, too: the flip is
allowed); dropped flat on a table, its four corners touch at once: one plastic impact (m v / 4 each, the loss
½ m v²), then it rests on them, m g / 4 each (the least-squares minimum norm), as when started resting flat. Pitch
at ±90° (the parametrization's singularity) stops a run with one message; bad inputs are one SceneError each.
"""

from __future__ import annotations

import numpy as np
import pytest
from test_lever import FREE_FLYER

from contactdyn import load_scene, parse_scene, simulate
from contactdyn.errors import SceneError, SimulationError
from contactdyn.model.system import System

pytestmark = pytest.mark.filterwarnings("ignore:.*the scene has no contacts")

G, M = 9.81, 1.0  #: [m/s²], [kg]
I_BODY = np.diag([M * (0.2**2 + 0.3**2), M * (0.1**2 + 0.3**2), M * (0.1**2 + 0.2**2)]) / 12  #: [kg·m²]
AXES = ("x", "y", "z", "yaw", "pitch", "roll")


def _rot(axis: int, a: float) -> np.ndarray:
    c, s = np.cos(a), np.sin(a)
    i, j = [(1, 2), (2, 0), (0, 1)][axis]
    R = np.eye(3)
    R[i, i], R[i, j], R[j, i], R[j, j] = c, -s, s, c
    return R


def _R(yaw: float, pitch: float, roll: float) -> np.ndarray:
    """Rz(yaw) Ry(pitch) Rx(roll)."""
    return _rot(2, yaw) @ _rot(1, pitch) @ _rot(0, roll)


def _E(yaw: float, pitch: float) -> np.ndarray:
    """ω (world) = E [yaw', pitch', roll'] [rad/s]: the three axes the Euler angles turn about, in the world."""
    Rz = _rot(2, yaw)
    return np.column_stack([[0.0, 0.0, 1.0], Rz[:, 1], Rz @ _rot(1, pitch)[:, 0]])


def _doc(**edits):
    scene = load_scene("drop_box")
    doc = {k: (dict(v) if isinstance(v, dict) else v) for k, v in scene.document.items()}
    doc.update(edits)
    return doc, scene.file


def _thrown(p0, v0, angles, omega, duration):
    """A run of the box thrown from p0 [m] at v0 [m/s], its angles [rad], turning at ω [rad/s] (world), no contact."""
    doc, file = _doc(duration=duration, contact={})
    rates = np.linalg.solve(_E(*angles[:2]), omega)
    body = {**doc["body"]["box"], "position0": [*p0, *angles], "velocity0": [*v0, *rates]}
    return simulate(parse_scene({**doc, "body": {"box": body}}, None, file))


def _spin(r):
    """Per sample: (½ ωᵀ I_w ω [J], R I Rᵀ ω [kg·m²/s]) from the channels."""
    q = np.column_stack([r[f"body.box.{a}.x"] for a in AXES])
    v = np.column_stack([r[f"body.box.{a}.v"] for a in AXES])
    energy, momentum = [], []
    for qi, vi in zip(q, v, strict=True):
        R = _R(*qi[3:])
        w = _E(*qi[3:5]) @ vi[3:]
        Iw = R @ I_BODY @ R.T
        energy.append(0.5 * w @ Iw @ w)
        momentum.append(Iw @ w)
    return np.array(energy), np.array(momentum)


def test_thrown_spinning_about_a_principal_axis_its_centre_falls_and_its_spin_is_kept():
    p0, v0, angles = np.array([0.1, -0.2, 1.0]), np.array([0.5, 0.3, 2.0]), np.array([0.3, 0.2, -0.4])
    omega = 8.0 * _R(*angles)[:, 2]  # [rad/s] about the box's z axis (its smallest inertia)
    r = _thrown(p0, v0, angles, omega, 0.8)
    t = r["t"]
    centre = np.column_stack([r[f"body.box.{a}.x"] for a in "xyz"])
    np.testing.assert_allclose(centre, p0 + np.outer(t, v0) + 0.5 * np.outer(t**2, [0, 0, -G]), rtol=0, atol=1e-9)
    energy, momentum = _spin(r)
    np.testing.assert_allclose(energy, energy[0], rtol=0, atol=1e-9)
    np.testing.assert_allclose(momentum, np.broadcast_to(momentum[0], momentum.shape), rtol=0, atol=1e-9)
    np.testing.assert_allclose(momentum[0], I_BODY[2, 2] * omega, rtol=1e-12, atol=1e-15)
    residual = r.meta["checks"]["energy_residual"]
    assert residual["value"] <= residual["tol"], residual


def test_spinning_about_the_intermediate_axis_it_flips_and_keeps_its_energy_and_momentum():
    angles = np.array([0.0, 0.0, np.pi / 2])  # the box's y axis (its intermediate inertia) up: world z
    R0 = _R(*angles)
    omega = R0 @ np.array([0.05, 10.0, 0.0])  # [rad/s] about y, a small perturbation about x
    r = _thrown([0.0, 0.0, 1.0], [0.0, 0.0, 0.0], angles, omega, 2.0)
    energy, momentum = _spin(r)
    np.testing.assert_allclose(energy, energy[0], rtol=0, atol=1e-9)
    np.testing.assert_allclose(momentum, np.broadcast_to(momentum[0], momentum.shape), rtol=0, atol=1e-9)
    y_up = [(_R(*q) @ [0, 1, 0])[2] for q in np.column_stack([r[f"body.box.{a}.x"] for a in AXES[3:]])]
    assert min(y_up) < -0.9  # it flipped: its y axis turned down


def test_dropped_flat_the_impact_is_plastic_and_it_rests_on_the_table():
    """Its four corners touch at once (one impact holds them all, transitions.CO_TOUCH): each takes m v / 4, the
    loss ½ m v², the box stops dead; at rest the four carry m g / 4 each (the minimum norm)."""
    r = simulate("drop_box")
    v = np.sqrt(2 * G * 0.1)  # [m/s] after the 0.1 m fall
    hit, *others = r.impacts  # the located corner's impact, then each corner that touched with it
    assert [o["contact"] for o in others] == ["c2", "c3", "c4"] and {o["with"] for o in others} == {"c1"}
    for o in others:  # each its own share of the one impact
        assert o["t"] == hit["t"] and o["normal_impulse"] == pytest.approx(M * v / 4, abs=1e-9)
    assert hit["t"] == pytest.approx(np.sqrt(2 * 0.1 / G), abs=1e-9)
    assert hit["normal_impulse"] == pytest.approx(M * v / 4, abs=1e-9)
    assert hit["energy_loss"] == pytest.approx(0.5 * M * v**2, abs=1e-9)
    assert np.abs(hit["v_after"]).max() < 1e-9  # the box stops dead
    assert [e["name"] for e in r.events if e["kind"] == "touch"] == ["c1", "c2", "c3", "c4"]
    after = r["t"] > hit["t"]
    assert np.abs(r["body.box.z.v"][after]).max() < 1e-9
    np.testing.assert_allclose(r["body.box.z.x"][after], 0.15, rtol=0, atol=1e-9)
    for k in range(1, 5):
        assert r[f"contact.c{k}.touching"][after].all()
        np.testing.assert_allclose(r[f"contact.c{k}.F_n"][after], M * G / 4, rtol=0, atol=1e-9)
    residual = r.meta["checks"]["energy_residual"]
    assert residual["value"] <= residual["tol"], residual


def test_resting_flat_each_corner_carries_a_quarter_of_its_weight():
    doc, file = _doc(duration=0.1)
    body = {**doc["body"]["box"], "position0": [0.0, 0.0, 0.15, 0.0, 0.0, 0.0]}
    r = simulate(parse_scene({**doc, "body": {"box": body}}, None, file))
    for k in range(1, 5):
        assert r[f"contact.c{k}.touching"].all()
        np.testing.assert_allclose(r[f"contact.c{k}.F_n"], M * G / 4, rtol=0, atol=1e-9)
    np.testing.assert_allclose(r["body.box.z.x"], 0.15, rtol=0, atol=1e-12)


def test_near_pitch_90_degrees_the_run_stops_with_the_parametrization_s_reason():
    doc, file = _doc(duration=0.1, contact={})
    body = {**doc["body"]["box"], "position0": [0.0, 0.0, 1.0, 0.0, np.pi / 2 - 1e-7, 0.0]}
    with pytest.raises(SimulationError, match="ZYX Euler angles are singular"):
        simulate(parse_scene({**doc, "body": {"box": body}}, None, file))


def test_a_spin_that_carries_the_pitch_across_90_degrees_stops_the_run_with_that_reason():
    """Spinning about its pitch axis at 5 rad/s from pitch 0, the box's pitch crosses 90° at ~0.31 s: whatever the
    steps, the run stops there with the parametrization's reason (not later, not silently)."""
    doc, file = _doc(duration=1.0, contact={})
    body = {**doc["body"]["box"], "position0": [0.0, 0.0, 1.0, 0.0, 0.0, 0.0],
            "velocity0": [0.0, 0.0, 0.0, 0.0, 5.0, 0.0]}
    with pytest.raises(SimulationError, match="pitch reached ±90°"):
        simulate(parse_scene({**doc, "body": {"box": body}}, None, file))


def test_a_floating_joint_from_a_world_link_is_a_free_body_whose_joints_follow_its_six(tmp_path):
    """The lever tests' flyer (a world link, a floating joint, a box with a hinged flap): free = true gives seven
    coordinates, the hinge's after the six; thrown tumbling, its energy (Pinocchio's) and the audit are kept."""
    (tmp_path / "flyer.urdf").write_text(FREE_FLYER)
    doc, _ = _doc(contact={}, duration=0.5)
    body = {"urdf": str(tmp_path / "flyer.urdf"), "free": True, "position0": [0, 0, 1.0, 0.1, 0.2, 0.3, 0.4],
            "velocity0": [0.1, 0.0, 1.0, 1.0, -2.0, 3.0, 0.5]}
    system = System(parse_scene({**doc, "body": {"flyer": body}}, None, tmp_path / "scene.toml"))
    assert [name for name, _ in system.body_channels] == [f"flyer.{a}" for a in (*AXES, "hinge")]
    r = simulate(system.scene)
    flyer = system.articulated["flyer"]
    q = np.column_stack([r[f"body.flyer.{a}.x"] for a in (*AXES, "hinge")])
    v = np.column_stack([r[f"body.flyer.{a}.v"] for a in (*AXES, "hinge")])
    energy = [flyer.energy(qi, vi) for qi, vi in zip(q, v, strict=True)]
    np.testing.assert_allclose(energy, energy[0], rtol=0, atol=1e-9)
    assert np.ptp(q[:, 6]) > 0.01  # the flap swung
    residual = r.meta["checks"]["energy_residual"]
    assert residual["value"] <= residual["tol"], residual


def test_its_coordinates_are_named_and_its_frame_is_the_link_s():
    doc, file = _doc()
    system = System(parse_scene(doc, None, file))
    assert [name for name, _ in system.body_channels] == [f"box.{a}" for a in AXES]
    assert system.articulated["box"].nb == 6


@pytest.mark.parametrize("edit, key", [
    ({"servo": {"velocity": 0.1}}, "servo"),
    ({"drive": {"kind": "ideal"}}, "drive"),
    ({"free": True, "urdf": None}, "free"),
])
def test_bad_inputs_are_one_scene_error_each(edit, key):
    doc, file = _doc()
    body = {**doc["body"]["box"], **edit}
    body = {k: v for k, v in body.items() if v is not None}
    if key == "free":
        body["mass"] = 1.0
    with pytest.raises(SceneError, match=key):
        parse_scene({**doc, "body": {"box": body}}, None, file)


def test_a_reference_riding_on_a_free_body_is_one_scene_error():
    doc, file = _doc()
    phase = {"name": "ride", "reference": {"body": "box", "moves": [{"kind": "trapezoid", "delta": [0.1, 0, 0],
                                                                       "duration": 1.0}]}}
    with pytest.raises(SceneError, match="a free body"):
        parse_scene({**doc, "phase": [phase]}, None, file)


def test_a_phase_until_a_corner_touches_ends_when_it_touches_with_another():
    """``until = "touch:c3"``: c3 touches with c1 (one impact): the next phase starts there."""
    doc, file = _doc()
    doc["phase"] = [{**doc["phase"][0], "until": "touch:c3"}, {**doc["phase"][0], "name": "resting"}]
    r = simulate(parse_scene(doc, None, file))
    started = [e for e in r.events if e["kind"] == "phase"]
    assert [e["name"] for e in started] == ["resting"]
    assert started[0]["t"] == pytest.approx(np.sqrt(2 * 0.1 / G), abs=1e-9)


def test_corners_with_friction_are_located_one_at_a_time():
    """A corner with friction does not touch along with another (the impact law slides or jams the located contact
    only): each is located on its own, the box still stops falling, and the energy audit closes."""
    doc, file = _doc()
    doc["contact"] = {k: {**v, "tangent": {"model": "friction", "directions": [[1.0, 0.0, 0.0]], "mu": 0.3}}
                      for k, v in doc["contact"].items()}
    r = simulate(parse_scene(doc, None, file))
    assert all("with" not in hit for hit in r.impacts) and len(r.impacts) >= 1
    assert abs(r["body.box.z.v"][-1]) < 1e-9
    residual = r.meta["checks"]["energy_residual"]
    assert residual["value"] <= residual["tol"], residual


def test_the_command_line_names_each_corner_s_share_of_the_one_impact(tmp_path, capsys, monkeypatch):
    """`contactdyn run drop_box`: one line per corner of the landing, the co-touched ones naming the located one,
    impulses rounded."""
    from contactdyn.cli import EXIT_OK, main

    monkeypatch.chdir(tmp_path)
    assert main(["run", "drop_box", "--out", str(tmp_path / "run")]) == EXIT_OK
    lines = [line for line in capsys.readouterr().out.splitlines() if line.strip().startswith("impact")]
    assert len(lines) == 4 and "on c1:" in lines[0]
    assert all(f"on c{k} (touching with c1): FΔt = 0.350179 N·s, F_fΔt = [] N·s" in lines[k - 1] for k in (2, 3, 4))
