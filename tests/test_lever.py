"""A body with a revolute joint (an articulated body, issue 32; ``sims/lever.toml``): a 1 kg bar, 0.5 m long,
hanging from a pivot 0.6 m above the table (a physical pendulum: d = 0.25 m, I_O = m L² / 3), its angle θ a
coordinate of the system, its H_b and h_b from its own Pinocchio model. A point-mass tool (2 kg) strikes its face
at the arm a = 0.4 m, lifts it by sliding along it (Coulomb, μ = 0.3) and holds it. Closed forms: the free swing's
θ̈ = −m g d sin θ / I_O and its energy; the strike's plastic impulse from the angular momentum about the pivot;
a static hold's normal force m g d sin θ / a; the energy audit closing; the rows by finite differences. The
scene runs on the compiled call (the bar's joint appended to the tool's in the rigid-body table,
``rigid_body.forest_table``), its right-hand side the interpreted call's to rounding (a free body's too:
tests/test_free_body.py). Unsupported inputs are one SceneError each.
"""

from __future__ import annotations

import numpy as np
import pytest
from run_agreement import interpreted_evaluate

from contactdyn import load_scene, parse_scene, simulate
from contactdyn.errors import SceneError
from contactdyn.hybrid.pipeline_mode import mode_runner
from contactdyn.model.paths import PIPELINE
from contactdyn.model.pipeline.pack import unsupported
from contactdyn.model.pipeline.pipeline import Pipeline
from contactdyn.model.system import System

G, M_BAR, L, M_TOOL, ARM, PIVOT_Z = 9.81, 1.0, 0.5, 2.0, 0.4, 0.6  #: the scene's numbers (SI)
D, I_O = L / 2, M_BAR * L**2 / 3  #: [m] the pivot to the centre of mass, [kg·m²] the inertia about the pivot
KP = 1e4  #: [N/m] the tool's stiffness (the scene's controller)


@pytest.fixture(scope="module")
def run():
    return simulate("lever")


def _doc(**edits):
    """The lever scene's document with top-level tables replaced (``body``, ``robot``, ``phase``...)."""
    scene = load_scene("lever")
    doc = {k: (dict(v) if isinstance(v, dict) else v) for k, v in scene.document.items()}
    doc.update(edits)
    return doc, scene.file


def _system(**edits) -> System:
    doc, file = _doc(**edits)
    return System(parse_scene(doc, None, file))


def _start(system: System, stuck: bool = False):
    """(x, modes, phase, the lever's index in Q) at the scene's start."""
    x, modes = system.initial_state()
    if stuck:
        modes = [m.with_(stuck=True) for m in modes]
    return x, modes, system.start_phase(0, 0.0, x, None), system.body_index["lever"]


def _far(theta0: float, omega0: float = 0.0) -> dict:
    """Edits: the lever released at θ0 [rad] (θ̇0 [rad/s]), no contact (the bar swings free)."""
    doc, _ = _doc()
    return {"body": {"lever": {**doc["body"]["lever"], "position0": theta0, "velocity0": omega0}}, "contact": {}}


def test_released_free_it_swings_with_the_pendulum_s_angular_acceleration():
    for theta0 in (0.3, 0.7, -1.2):
        system = _system(**_far(theta0))
        x, modes, phase, i = _start(system)
        ev = mode_runner(system)(modes, phase).evaluation(0.0, x)
        assert ev.xdot[system.nQ + i] == pytest.approx(-M_BAR * G * D * np.sin(theta0) / I_O, rel=0, abs=1e-9)


def test_a_free_swing_keeps_its_energy_and_the_audit_closes():
    doc, file = _doc(**_far(1.0), duration=1.2)
    r = simulate(parse_scene(doc, None, file))
    theta, omega = r["body.lever.x"], r["body.lever.v"]
    energy = 0.5 * I_O * omega**2 + M_BAR * G * D * (1 - np.cos(theta))  # [J]
    np.testing.assert_allclose(energy, energy[0], rtol=0, atol=1e-9)
    assert theta.min() < -0.99  # it swung through to the other side
    residual = r.meta["checks"]["energy_residual"]
    assert residual["value"] <= residual["tol"], residual


def test_the_strike_is_plastic_with_the_impulse_the_angular_momentum_gives(run):
    """The tool (speed v⁻ along −x) strikes the hanging bar at the arm a: P (1/m_t + a²/I_O) = v⁻, the tool then
    moving at v⁻ − P/m_t, the bar turning at a P / I_O, the tip's velocity along the bar zero before and after
    (no friction impulse)."""
    (hit,) = [imp for imp in run.impacts if imp["contact"] == "push"][:1]
    v_minus = -hit["v_before"][0]  # [m/s] toward the bar
    P = v_minus / (1 / M_TOOL + ARM**2 / I_O)
    assert hit["normal_impulse"] == pytest.approx(P, rel=1e-12)
    tool_x, tool_z, omega = hit["v_after"]
    assert tool_x == pytest.approx(-(v_minus - P / M_TOOL), rel=1e-12)
    assert omega == pytest.approx(ARM * P / I_O, rel=1e-12)
    assert abs(tool_z) < 1e-12 and abs(hit["friction_impulse"][0]) < 1e-12
    assert hit["energy_loss"] == pytest.approx(0.5 * M_TOOL * v_minus**2 - 0.5 * M_TOOL * tool_x**2
                                               - 0.5 * I_O * omega**2, rel=1e-9)


def test_the_scene_runs_on_the_compiled_call_and_its_energy_closes(run):
    assert {row["path"] for row in run.stats["paths"].values()} == {PIPELINE}
    residual = run.meta["checks"]["energy_residual"]
    assert residual["value"] <= residual["tol"], residual
    kinds = [(e["kind"], e["name"]) for e in run.events]
    assert kinds[:2] == [("touch", "push"), ("slip", "push")]  # it strikes, then slides along the bar
    assert run["body.lever.x"][-1] > 0.3  # lifted


def _hold(theta: float, pull: float = 0.0) -> dict:
    """Edits: the bar at rest at θ [rad], the tool on its face at the arm a, the tool's reference set off the face
    so that its spring gives the normal force m g d sin θ / a (and ``pull`` [N] along the bar): a static hold."""
    doc, _ = _doc()
    n, t = np.array([np.cos(theta), -np.sin(theta)]), np.array([np.sin(theta), np.cos(theta)])  # (x, z): face, bar
    tool = np.array([-ARM * np.sin(theta), PIVOT_Z - ARM * np.cos(theta)])
    F_n = M_BAR * G * D * np.sin(theta) / ARM
    ref = tool - (F_n * n - pull * t) / KP  # the spring kp (x_d − x) balances the face's push F_n n and friction
    phase = {"name": "hold", "reference": {"start": [ref[0], 0.0, ref[1]], "moves": []}}
    return {"body": {"lever": {**doc["body"]["lever"], "position0": theta}},
            "robot": {**doc["robot"], "q0": tool.tolist()}, "phase": [phase]}


@pytest.mark.parametrize("theta, pull", [(0.3, 0.0), (0.6, 1.5)])
def test_a_static_hold_needs_the_normal_force_m_g_d_sin_theta_over_the_arm(theta, pull):
    system = _system(**_hold(theta, pull))
    x, modes, phase, i = _start(system, stuck=True)
    ev = mode_runner(system)(modes, phase).evaluation(0.0, x)
    nQ = system.nQ
    np.testing.assert_allclose(ev.xdot[nQ:2 * nQ], 0.0, rtol=0, atol=1e-9)  # nothing accelerates
    assert ev.normal_force["push"] == pytest.approx(M_BAR * G * D * np.sin(theta) / ARM, rel=1e-9)
    assert ev.friction["push"][0] == pytest.approx(-pull, rel=0, abs=1e-9)  # along the bar: no moment


def test_held_it_stays_stuck_at_rest():
    theta = 0.3
    doc, file = _doc(**_hold(theta), duration=0.3)
    r = simulate(parse_scene(doc, None, file))
    assert r["contact.push.stuck"].all() and r["contact.push.touching"].all()
    np.testing.assert_allclose(r["body.lever.x"], theta, rtol=0, atol=1e-9)
    np.testing.assert_allclose(r["contact.push.F_n"], M_BAR * G * D * np.sin(theta) / ARM, rtol=1e-9)


def test_the_rows_and_gamma_on_the_bar_are_the_derivatives_of_the_gap_and_the_slip():
    """Along a smooth motion of the tool and the bar (Q, Q̇, Q̈ given), the normal row n·Q̇ is ġ and the slip row's
    rate with γ is d/dt of the slip velocity (central differences, h = 1e-5 s); the same for the bar's point."""
    for edits in (_hold(0.3), _bar_point(), _bar_point(on_tool=True)):
        system = _system(**edits)
        c = system.contacts[0]
        x0, _, _, _ = _start(system)
        nQ, nv = system.nQ, system.nv
        a, w = np.array([0.02, 0.01, 0.3]), np.array([2.0, 3.0, 1.5])

        def at(t, c=c, system=system, x0=x0, a=a, w=w, nQ=nQ, nv=nv):
            x = x0.copy()
            x[:nQ] += a * np.sin(w * t)
            x[nQ:2 * nQ] = a * w * np.cos(w * t)
            acc = -a * w**2 * np.sin(w * t)
            system.robot.update(x[:nv], x[nQ:nQ + nv])
            kin = system.kinematics(c, x)
            gap = float(kin.normal @ (kin.p_tip - kin.p_env))
            rows = np.array([_row(system, c, u, kin) for u in (kin.normal, *kin.tangents)])
            drift = np.array([u @ kin.drift for u in (kin.normal, *kin.tangents)])
            return gap, rows @ x[nQ:2 * nQ], rows @ acc + drift

        h = 1e-5
        for t in (0.1, 0.4, 0.9):
            (g0, r0, _), (g1, r1, _) = at(t - h), at(t + h)
            _, rates, accelerations = at(t)
            np.testing.assert_allclose((g1 - g0) / (2 * h), rates[0], rtol=0, atol=1e-8)
            np.testing.assert_allclose((r1 - r0) / (2 * h), accelerations, rtol=0, atol=1e-7)


def _row(system, c, u, kin):
    from contactdyn.model.constraints import contact_row
    return contact_row(system, c, u, kin)


def _bar_point(on_tool: bool = False) -> dict:
    """Edits: the bar's lower end (a point of its frame, ``body_frame``) over the table, friction along x (for its
    rows: its one coordinate moves the end along the normal and the tangent at once, so a run holds it frictionless),
    the bar at 0.5 rad; ``on_tool``: over a surface carried by the tool's frame instead (body = "robot")."""
    doc, _ = _doc()
    contact = {"frame": "lever", "body_frame": "bar", "frame_point": [0.0, 0.0, -0.5], "body": "ground",
               "point": [0.0, 0.0, 0.0], "normal": {"direction": [0.0, 0.0, 1.0]},
               "tangent": {"model": "friction", "directions": [[1.0, 0.0, 0.0]], "mu": 0.3}}
    if on_tool:
        contact.update(body="robot", surface_frame="tip", point=[0.0, 0.0, -0.2])
    return {"body": {"lever": {**doc["body"]["lever"], "position0": 0.5}}, "contact": {"table": contact}}


def test_the_bar_s_end_swings_onto_the_table_and_stops_dead():
    """Released at 1.2 rad over a table 0.4 m below the pivot (a frictionless rigid contact), the bar's lower end
    (0.5 m from the pivot) meets it at θ_c = arccos(0.8): the plastic impact stops it dead (its one coordinate
    moves the end along the table's normal), the energy lost the whole ½ I_O θ̇² = m g d (cos θ_c − cos θ0);
    it rests there."""
    doc, file = _doc(**_bar_point(), duration=1.0)
    doc["body"]["lever"] = {**doc["body"]["lever"], "position0": 1.2}
    doc["contact"]["table"] = {**doc["contact"]["table"], "tangent": {"model": "free"}, "point": [0.0, 0.0, 0.2]}
    doc["robot"] = {**doc["robot"], "q0": [1.0, 0.2]}
    r = simulate(parse_scene(doc, None, file))
    (hit,) = [imp for imp in r.impacts if imp["contact"] == "table"][:1]
    theta_c = np.arccos(0.4 / 0.5)
    assert hit["energy_loss"] == pytest.approx(M_BAR * G * D * (np.cos(theta_c) - np.cos(1.2)), rel=1e-7)
    assert abs(hit["v_after"][-1]) < 1e-12
    assert r["body.lever.x"][-1] == pytest.approx(theta_c, abs=1e-9)
    residual = r.meta["checks"]["energy_residual"]
    assert residual["value"] <= residual["tol"], residual


# ---- what a body with revolute joints does not support yet, or was given wrong: one clear error each -----------------

def _edit_push(**changes):
    doc, _ = _doc()
    return {"contact": {"push": {**doc["contact"]["push"], **changes}}}


FREE_FLYER = """<?xml version="1.0"?>
<robot name="flyer"><link name="world"/>
  <joint name="float" type="floating"><parent link="world"/><child link="box"/></joint>
  <link name="box"><inertial><mass value="1.0"/><inertia ixx="1e-3" ixy="0" ixz="0" iyy="1e-3" iyz="0" izz="1e-3"/>
  </inertial></link>
  <joint name="hinge" type="revolute"><parent link="box"/><child link="flap"/><axis xyz="0 1 0"/>
    <limit lower="-1" upper="1" effort="1" velocity="1"/></joint>
  <link name="flap"><inertial><mass value="1.0"/><inertia ixx="1e-3" ixy="0" ixz="0" iyy="1e-3" iyz="0" izz="1e-3"/>
  </inertial></link>
</robot>
"""


@pytest.mark.parametrize("edits, key, words", [
    (lambda: _edit_push(surface_frame=None), "contact.push.surface_frame", "required"),
    (lambda: _edit_push(surface_frame="nowhere"), "contact.push.surface_frame", "a frame of body 'lever'"),
    (lambda: _edit_push(body_frame="bar"), "contact.push.body_frame", "a frame of a body with revolute joints"),
    (lambda: {**_bar_point(), "contact": {"table": {**_bar_point()["contact"]["table"], "body_frame": None}}},
     "contact.table.body_frame", "required"),
    (lambda: {**_bar_point(), "contact": {"table": {**_bar_point()["contact"]["table"], "body_frame": "nowhere"}}},
     "contact.table.body_frame", "a frame of body 'lever'"),
    (lambda: {"body": {"lever": {"urdf": "lever.urdf", "servo": {"velocity": 0.1}}}}, "body.lever.servo",
     "revolute joints"),
    (lambda: {"phase": [{"name": "ride", "reference": {"body": "lever", "moves": []}}]}, "reference.body",
     "revolute joints"),
])
def test_a_body_with_revolute_joints_given_wrong_or_unsupported_is_one_clear_error(edits, key, words):
    changes = edits()
    for table in changes.get("contact", {}).values():  # None: the key left out
        for k in [k for k, v in table.items() if v is None]:
            del table[k]
    doc, file = _doc(**changes)
    with pytest.raises(SceneError) as err:
        simulate(parse_scene(doc, None, file))  # (frames are resolved with the bodies: at the run's start)
    assert key in str(err.value) and words in str(err.value), str(err.value)


def test_a_free_flying_body_without_free_true_is_one_clear_error(tmp_path):
    (tmp_path / "flyer.urdf").write_text(FREE_FLYER)
    doc, _ = _doc(body={"lever": {"urdf": str(tmp_path / "flyer.urdf")}}, contact={})
    with pytest.raises(SceneError) as err:
        parse_scene(doc, None, tmp_path / "scene.toml")
    assert "body.lever.urdf" in str(err.value) and "is declared free = true" in str(err.value), str(err.value)


def test_the_viewer_turns_the_push_s_arrows_with_the_bar():
    """The normal force's arrow on the tool stays along the bar's face normal as the bar swings: from its tail to
    the contact point it points along the bar frame's x turned by the bar's angle (the body's own model)."""
    from pathlib import Path

    from contactdyn.robot.body import load_body
    from contactdyn.viewer.build import build_scene

    r = simulate("lever", {"solver.output_rate": 50.0})
    scene = build_scene(r)
    tracks = {a["path"]: {t["name"][1:]: np.array([k["value"] for k in t["keys"]]) for t in a["clip"]["tracks"]}
              for a in scene.commands[-1]["animations"]}
    tail = tracks["/meshcat/forces/push_normal"]["position"]
    tip = tracks["/meshcat/tool/push/ball"]["position"]
    pressing = r["contact.push.F_n"] > 1e-3
    bar = load_body(str(Path(__file__).parent.parent / "sims" / "lever.urdf")).robot
    normal = np.array([bar.frame_placement(np.array([th]), "bar").rotation[:, 0] for th in r["body.lever.x"]])
    arrow = (tip - tail)[pressing] / np.linalg.norm((tip - tail)[pressing], axis=1)[:, None]
    np.testing.assert_allclose(arrow, normal[pressing], atol=1e-5)
    assert np.ptp(r["body.lever.x"][pressing]) > 0.1  # the bar did swing while pressed


def test_with_2d_friction_along_the_bar_the_lever_moves_as_with_1d():
    """Friction along the bar and across it (the bar's z and y): the same events, the bar's angle and the normal
    force as the 1-D run's (1e-9), the slip and friction across the bar exactly 0 (nothing moves along y)."""
    scene = load_scene("lever")
    doc = dict(scene.document)
    push = {**doc["contact"]["push"], "tangent": {**doc["contact"]["push"]["tangent"],
                                                  "directions": [[0.0, 0.0, 1.0], [0.0, 1.0, 0.0]]}}
    two, one = simulate(parse_scene({**doc, "contact": {"push": push}}, None, scene.file)), simulate("lever")
    assert [(e["kind"], e["name"]) for e in two.events] == [(e["kind"], e["name"]) for e in one.events]
    np.testing.assert_allclose(two["body.lever.x"], one["body.lever.x"], rtol=0, atol=1e-9)
    np.testing.assert_allclose(two["contact.push.F_n"], one["contact.push.F_n"], rtol=1e-8, atol=1e-9)
    assert np.all(two["contact.push.v_slip"][:, 1] == 0.0) and np.all(two["contact.push.F_f"][:, 1] == 0.0)


@pytest.mark.parametrize("edits, stuck", [({}, False), ({}, True), (_hold(0.6, 1.5), True), (_bar_point(), False),
                                          (_bar_point(on_tool=True), False)])
def test_the_compiled_call_gives_the_interpreted_call_s_rates(edits, stuck):
    """At states off the start (the tool and the bar moved and moving), touching or not, sliding or stuck: the
    compiled call's ẋ is the interpreted call's (``interpreted_evaluate``) to rounding (the bar's H_b, h_b, its frame
    and its point from the rigid-body table)."""
    system = _system(**edits)
    x0, modes, phase, _ = _start(system, stuck)
    nQ = system.nQ
    rng = np.random.default_rng(3)
    for touching in (False, True):
        ms = [m.with_(touching=touching) for m in modes]
        assert unsupported(system, ms, phase) == ""
        pipeline = Pipeline(system, ms, phase)
        for _ in range(3):
            x = x0.copy()
            x[:nQ] += 0.02 * rng.standard_normal(nQ)
            x[nQ:2 * nQ] += 0.5 * rng.standard_normal(nQ)
            want = interpreted_evaluate(system, 0.1, x, ms, phase).xdot
            np.testing.assert_allclose(pipeline.rhs(0.1, x), want, rtol=0, atol=1e-12 * (1 + np.abs(want).max()))
            assert pipeline.failed_calls == 0


def test_a_hold_at_mu_1e_3_creeps_in_the_stick_band_instead_of_stopping_at_once():
    """At μ = 1e-3 the hold's slide decays toward its balance (the PD spring's pull equal to μ_k F, its damper
    slowing the slip): at the band's edge (|v_t| = v_ε) it stops, the stick it is tried at needs more than μ_s F (the
    damping of v_ε still pulls), so it slides from rest from the state as it was, still at the edge and slowing. Its
    stop, armed there, fired at once: 50 stop/slip decisions at t = 1.3139 s (an event storm). A slide from rest
    stops only once it has left the band (events.stop_armed): the run ends, one stop/slip there, and the slide
    creeps within the band with kinetic friction, |F_f| = μ_k F, never reversing past −v_ε."""
    mu = 1e-3
    r = simulate("lever", {"contact.push.tangent.mu_s": mu, "contact.push.tangent.mu_k": mu})
    assert r.t[-1] == pytest.approx(1.5)
    last = [e for e in r.events if e["t"] > 1.3]
    assert [e["kind"] for e in last] == ["stop", "slip"] and last[0]["t"] == last[1]["t"]
    on, band = r["contact.push.touching"] > 0, 1e-9  # (solver.stick_velocity's default)
    F_n, F_f = r["contact.push.F_n"][on], r["contact.push.F_f"][on, 0]
    assert not r["contact.push.stuck"][on].any()
    np.testing.assert_allclose(np.abs(F_f), mu * F_n, rtol=1e-12, atol=0)  # Coulomb's kinetic law, sliding
    creep = r["contact.push.v_slip"][r.t > last[0]["t"]]
    assert np.all(np.abs(creep) <= band)  # within the band: no stop (left it never), no reverse (−v_ε)
