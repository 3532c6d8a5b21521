"""A free body (issue 32; ``sims/drop_box.toml``): a 1 kg box 0.1 × 0.2 × 0.3 m (``sims/free_box.urdf``, its frame at
its centre along its principal axes) whose root link has six coordinates of the system, nq = nv: x, y, z [m] of its
centre, then its ZYX Euler angles yaw, pitch, roll [rad] (R = Rz(yaw) Ry(pitch) Rx(roll)). Closed forms: thrown
free, its centre follows p0 + v0 t + g t²/2, its rotational energy ½ ωᵀ I ω and its angular momentum in the world
R I Rᵀ ω stay constant (a spin about a principal axis; about the intermediate axis, perturbed, too: the flip is
allowed); dropped flat on a table, its four corners touch at once: one plastic impact (m v / 4 each, the loss
½ m v²), then it rests on them, m g / 4 each (the least-squares minimum norm), as when started resting flat.
Near pitch ±90° (chart A's singularity) the angles switch to chart B (R = Rz Ry Rx(b) · C,
:mod:`contactdyn.robot.free_chart`) and back: a tumble keeps its momentum, energy and parabola across the switches,
a switch keeps the pose and velocities, a landing after one closes its energy audit; bad inputs are one SceneError
each. Every mode runs on the compiled call (:mod:`contactdyn.model.pipeline`) in either chart: the body's chart-B
rows of the rigid-body table and its frames' chart-B placements are picked by the state's chart slot, the
interpreted call's rates to rounding.
"""

from __future__ import annotations

import numpy as np
import pytest
from run_agreement import interpreted_evaluate
from test_lever import FREE_FLYER

from contactdyn import load_scene, parse_scene, simulate
from contactdyn.errors import SceneError
from contactdyn.hybrid.loop import HybridRun
from contactdyn.hybrid.pipeline_mode import PipelineMode
from contactdyn.model.paths import INTERPRETED, PIPELINE, LivePipelines
from contactdyn.model.pipeline.pipeline import Pipeline, call
from contactdyn.model.system import System
from contactdyn.simulate import prepare

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


def _compiled(r) -> None:
    """Every mode of the run on the compiled call."""
    assert {row["path"] for row in r.stats["paths"].values()} == {PIPELINE}, r.stats["paths"]


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
    _compiled(r)
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


def _tumble(duration: float):
    """A box thrown tumbling (tilted, about its intermediate axis y, perturbed about x): its x and y axes each turn
    vertical in turn, so both charts' pitches pass ±90° (the switches go both ways)."""
    angles = np.array([0.3, 0.7, 1.0])
    omega = _R(*angles) @ np.array([3.0, 10.0, 0.1])  # [rad/s]
    return _thrown([0.0, 0.0, 1.0], [0.3, 0.0, 2.0], angles, omega, duration), omega


def test_a_tumbling_box_switches_charts_both_ways_and_keeps_its_momentum_energy_and_parabola():
    """Torque-free in free fall: R I Rᵀ ω and ½ ωᵀ R I Rᵀ ω stay (R from the recorded chart-A angles, ω its own
    channels) across every switch, to 1e-9 relative; its centre follows p0 + v0 t + g t²/2."""
    r, omega = _tumble(3.0)
    _compiled(r)
    switches = [e for e in r.events if e["kind"] == "chart"]
    assert {e["to"] for e in switches} == {"A", "B"} and len(switches) >= 4, switches
    assert abs(np.diff(r["body.box.chart"])).sum() >= 4
    pitch = r["body.box.pitch.x"]
    assert np.abs(np.cos(pitch)).min() < 0.2  # chart A's pitch came near ±90° (while B ran)
    t = r["t"]
    centre = np.column_stack([r[f"body.box.{a}.x"] for a in "xyz"])
    p0, v0 = np.array([0.0, 0.0, 1.0]), np.array([0.3, 0.0, 2.0])
    np.testing.assert_allclose(centre, p0 + np.outer(t, v0) + 0.5 * np.outer(t**2, [0, 0, -G]), rtol=0, atol=1e-9)
    w = np.column_stack([r[f"body.box.omega_{a}"] for a in "xyz"])
    np.testing.assert_allclose(w[0], omega, rtol=0, atol=1e-12)
    Rs = [_R(*a) for a in np.column_stack([r[f"body.box.{a}.x"] for a in AXES[3:]])]
    L = np.array([R @ I_BODY @ R.T @ wi for R, wi in zip(Rs, w, strict=True)])  # [kg·m²/s]
    E = 0.5 * np.einsum("ij,ij->i", w, L)  # [J]
    np.testing.assert_allclose(L, np.broadcast_to(L[0], L.shape), rtol=0, atol=1e-9 * np.linalg.norm(L[0]))
    np.testing.assert_allclose(E, E[0], rtol=1e-9, atol=0)
    residual = r.meta["checks"]["energy_residual"]
    assert residual["value"] <= residual["tol"], residual


def test_chart_a_s_angles_and_their_rates_describe_the_motion_in_either_chart():
    """The recorded yaw, pitch, roll are chart A's (from R while B runs): their rates give ω by chart A's
    E(yaw, pitch) wherever pitch keeps from ±90°."""
    r, _ = _tumble(1.5)
    a = np.column_stack([r[f"body.box.{k}.x"] for k in AXES[3:]])
    ad = np.column_stack([r[f"body.box.{k}.v"] for k in AXES[3:]])
    w = np.column_stack([r[f"body.box.omega_{k}"] for k in "xyz"])
    away = np.abs(np.cos(a[:, 1])) > 0.1
    assert r["body.box.chart"][away].any()
    for ai, adi, wi in zip(a[away], ad[away], w[away], strict=True):
        np.testing.assert_allclose(_E(*ai[:2]) @ adi, wi, rtol=0, atol=1e-9)


def test_a_switch_keeps_the_position_rotation_and_velocities():
    """Right before and right after a switch (either way): the box frame's position [m], rotation, velocity [m/s]
    and ω [rad/s] the same to 1e-12 (its own frame in each chart's model, the same id); a corner's too; the
    kinetic energy the same to rounding."""
    doc, file = _doc()
    system = System(parse_scene({**doc, "body": {"box": {**doc["body"]["box"]}}}, None, file))
    body, nQ = system.articulated["box"], system.nQ
    fid = body.robot.frame_id("box")
    assert body.robots[1].frame_id("box") == fid and body.robots[1].model.nframes == body.robots[0].model.nframes
    corner = np.array([0.05, 0.1, -0.15])
    rng = np.random.default_rng(3)
    for pitch in (1.0472, -1.0472, 0.3, 2.0):
        x = np.zeros(system.n)
        x[body.first:body.first + 6] = [*rng.normal(size=3), rng.uniform(-3, 3), pitch, rng.uniform(-3, 3)]
        x[nQ + body.first:nQ + body.first + 6] = rng.normal(size=6) * 3.0
        for chart in (0, 1):
            x[body.chart_index] = chart
            y = body.switched(x, nQ)
            assert body.chart_of(y) == 1 - chart
            seen = []
            for state in (x, y):
                body.update(state, nQ)
                ft = body.frame(fid)
                w = ft.angular_jacobian @ state[nQ + body.first:nQ + body.first + 6]
                p, v, _, _ = body.point(fid, corner)
                q_b, v_b = state[body.first:body.first + 6], state[nQ + body.first:nQ + body.first + 6]
                seen.append((ft.position, ft.rotation, ft.velocity, w, p, v,
                             body.energy(q_b, v_b, body.chart_of(state))))
            for before, after in zip(*seen, strict=True):
                np.testing.assert_allclose(after, before, rtol=1e-12, atol=1e-12)
            assert np.allclose(y[body.first:body.first + 3], x[body.first:body.first + 3], rtol=0, atol=0)


def test_a_start_near_pitch_90_degrees_runs_in_chart_b():
    """Started at pitch 90° − 1e-7 (chart A singular there), the box starts in chart B and falls freely."""
    doc, file = _doc(duration=0.1, contact={})
    body = {**doc["body"]["box"], "position0": [0.0, 0.0, 1.0, 0.2, np.pi / 2 - 1e-7, 0.1]}
    r = simulate(parse_scene({**doc, "body": {"box": body}}, None, file))
    assert (r["body.box.chart"] == 1).all()
    R0 = _R(0.2, np.pi / 2 - 1e-7, 0.1)
    for k in range(0, len(r["t"]), 5):
        R = _R(*(r[f"body.box.{a}.x"][k] for a in AXES[3:]))
        np.testing.assert_allclose(R, R0, rtol=0, atol=1e-9)
    np.testing.assert_allclose(r["body.box.z.x"], 1.0 - 0.5 * G * r["t"]**2, rtol=0, atol=1e-12)


def test_a_box_landing_after_a_tumble_through_pitch_90_degrees_closes_its_energy_audit():
    """Thrown spinning about its y axis, it turns past pitch 90° in the air (chart B) and lands on the corners of
    its top face (rigid, frictionless: plastic impacts), then rocks on the table: the run finishes, contacts on
    the box are located and its impacts taken in chart B, and its energy audit closes."""
    doc, file = _doc(duration=0.8)
    contacts = dict(doc["contact"])
    for k, (sx, sy) in enumerate(((1, 1), (-1, 1), (-1, -1), (1, -1)), start=5):  # the top face's corners
        contacts[f"c{k}"] = {**contacts["c1"], "frame_point": [0.05 * sx, 0.1 * sy, 0.15]}
    body = {**doc["body"]["box"], "position0": [0.0, 0.0, 0.5, 0.0, 0.9, 0.0],
            "velocity0": [0.0, 0.0, 0.0, 0.0, 4.0, 0.0]}
    r = simulate(parse_scene({**doc, "contact": contacts, "body": {"box": body}}, None, file))
    _compiled(r)
    kinds = [(e["kind"], e.get("to")) for e in r.events]
    assert ("chart", "B") in kinds and kinds.index(("chart", "B")) < kinds.index(("touch", None))
    assert r.impacts and all(h["t"] > next(e["t"] for e in r.events if e["kind"] == "chart") for h in r.impacts)
    on_b = r["body.box.chart"] == 1
    touching = np.column_stack([r[f"contact.c{k}.touching"] for k in range(1, 9)]).any(axis=1)
    assert (on_b & touching).any()
    residual = r.meta["checks"]["energy_residual"]
    assert residual["value"] <= residual["tol"], residual


@pytest.mark.parametrize("touching", [False, True])
def test_the_compiled_call_gives_the_interpreted_call_s_rates_in_either_chart(touching):
    """The drop_box mode packed once, called at random poses and velocities in chart A and in chart B (the box's
    rows of the rigid-body table and its corners' placements turned by free_chart.C): the interpreted call's ẋ to
    1e-12 relative; read in the other chart's table it would be far off."""
    system, modes, phase, x = prepare(load_scene("drop_box"))
    modes = [m.with_(touching=touching) for m in modes]
    body, nQ = system.articulated["box"], system.nQ
    p = Pipeline(system, modes, phase).packed
    rng = np.random.default_rng(5)
    for _ in range(3):
        y = x.copy()
        y[body.first:body.first + 6] += rng.normal(size=6) * 0.3
        y[nQ + body.first:nQ + body.first + 6] = rng.normal(size=6) * 2.0
        refs = []
        for chart in (0, 1):
            y[body.chart_index] = chart
            got = call(0.0, y.copy(), p.ints, p.reals, p.work, p.events)
            refs.append(interpreted_evaluate(system, 0.0, y, modes, phase).xdot)
            assert p.events[-1] == 1.0
            assert np.abs(got - refs[-1]).max() <= 1e-12 * (1.0 + np.abs(refs[-1]).max())
        assert np.abs(refs[1] - refs[0]).max() > 1e-3  # (the charts' rates differ: both were checked)


def test_a_tumble_through_both_charts_runs_the_same_compiled_and_interpreted(monkeypatch):
    """The tumble's first 1.5 s (a switch to B and back to A) on the compiled call and interpreted: every
    channel within 1e-9 of its largest value plus 1e-10 (SI units), the switches at the same instants to 1e-9 s."""
    runs = {}
    for use in (True, False):
        monkeypatch.setattr(LivePipelines, "use", use)
        runs[use] = _tumble(1.5)[0]
    fast, interpreted = runs[True], runs[False]
    _compiled(fast)
    assert {row["path"] for row in interpreted.stats["paths"].values()} == {INTERPRETED}, interpreted.stats["paths"]
    assert [e.get("to") for e in fast.events] == [e.get("to") for e in interpreted.events] == ["B", "A"]
    np.testing.assert_allclose([e["t"] for e in fast.events], [e["t"] for e in interpreted.events], rtol=0, atol=1e-9)
    for key, ref in interpreted.channels.items():
        ref, got = np.asarray(ref, float), np.asarray(fast.channels[key], float)
        if ref.size and not np.all(np.isnan(ref)):
            assert np.nanmax(np.abs(got - ref)) <= 1e-9 * np.nanmax(np.abs(ref)) + 1e-10, key


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
    _compiled(r)  # (its hinge's row in chart B: its placement on the turned roll link)
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


def test_corners_with_friction_touch_together_and_hold_by_their_sticks():
    """Corners with friction arriving without slip touch along with the located one, each held by its stick in the
    one impact: m v / 4 each, no friction impulse (the landing is straight down), no pulling; the box stops falling
    and the energy audit closes."""
    doc, file = _doc()
    doc["contact"] = {k: {**v, "tangent": {"model": "friction", "directions": [[1.0, 0.0, 0.0]], "mu": 0.3}}
                      for k, v in doc["contact"].items()}
    r = simulate(parse_scene(doc, None, file))
    landing = [hit for hit in r.impacts if hit["t"] == r.impacts[0]["t"]]
    assert len(landing) == 4 and sum("with" in hit for hit in landing) == 3
    v = np.sqrt(2 * G * 0.1)  # [m/s] after the 0.1 m fall
    np.testing.assert_allclose([hit["normal_impulse"] for hit in landing], M * v / 4, rtol=1e-6)
    np.testing.assert_allclose([f for hit in landing for f in hit["friction_impulse"]], 0.0, rtol=0, atol=1e-12)
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
    assert all(f"on c{k} (touching with c1): FΔt = 0.350179 N·s (no friction)" in lines[k - 1] for k in (2, 3, 4))


def test_resting_on_four_corners_the_call_solves_the_singular_system_as_the_interpreted_call():
    """At rest on its four corners (12 coordinates, the box's 6 held by 4 rows: the KKT matrix singular, its system
    consistent): the call takes the minimum-norm least squares (status 1, counted, not regular), ẋ and each
    corner's m g / 4 as the interpreted call's (``interpreted_evaluate``); a whole resting run counts its calls in
    ``singular_solves`` and has no call without an answer (``failed_calls``)."""
    system, modes, phase, x = prepare(load_scene("drop_box"))
    modes = [m.with_(touching=True) for m in modes]
    x[system.nv + 2] = 0.15  # [m] the box's centre: its bottom on the table
    pipe = Pipeline(system, modes, phase)
    p = pipe.packed
    got = call(0.0, x.copy(), p.ints, p.reals, p.work, p.events)
    ref = interpreted_evaluate(system, 0.0, x, modes, phase)
    assert p.events[-1] == 1.0 and pipe.least_squares == 1 and not ref.regular
    assert np.abs(got - ref.xdot).max() <= 1e-9 * (1.0 + np.abs(ref.xdot).max())
    ev = PipelineMode(pipe).evaluation(0.0, x)
    assert not ev.regular and pipe.failed_calls == 0
    for name in ("c1", "c2", "c3", "c4"):
        assert ev.normal_force[name] == pytest.approx(ref.normal_force[name], rel=1e-9) \
            == pytest.approx(M * G / 4, rel=1e-9)
    doc, file = _doc(duration=0.1)
    body = {**doc["body"]["box"], "position0": [0.0, 0.0, 0.15, 0.0, 0.0, 0.0]}
    run = HybridRun(System(parse_scene({**doc, "body": {"box": body}}, None, file)))
    r = run.run(0.0)
    modes_run = [m for m in run.pipelines.pipes.values() if not isinstance(m, str)]
    assert modes_run and sum(m.pipe.failed_calls for m in modes_run) == 0
    assert r.stats["singular_solves"] > 0  # (before: 0, the call's least squares not counted)
