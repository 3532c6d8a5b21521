"""Deformation chains where a side turns (issue 32): a chain on a surface that turns with a robot frame or an
articulated body (its masses riding the surface), and any chain under an articulated body's touching point.

On a turning surface a chain runs along the state's normal n and measures its nodes from the surface
(:func:`contactdyn.model.chain_forces.relative_sides`): its compression is the gap n·(p − p_s), its rate n·v_rel, so
a damped junction's state is a deformation the turning n does not shift. Closed forms: the tilting tray's part on a
Kelvin–Voigt normal carries m g cos θ at a sink F/k while it sticks and slips at tan θ = μ; undamped and carried
around the axis, the energy audit closes; the bar's end strikes a model-(b) chain with the plastic impact of two
masses (the bar's effective mass at its end, m′) and rests on it with m g d / L; the tool pressed into a
Kelvin–Voigt face of the bar holds it at rest with m g d sin θ / a. Both paths agree where the compiled call runs.
A chain's mass on a turning surface rides it (:class:`contactdyn.model.contact.RidingMass`): M and the bias are
Pinocchio's for a prismatic joint carrying a point mass; an impulse along its line moves it alone. A tangential chain
along the tray's slope holds the part where k x + b ẋ balances m g sin θ.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from test_lever import ARM, I_O, KP, M_BAR, M_TOOL, PIVOT_Z, D, G, L

from contactdyn import load_scene, parse_scene, simulate
from contactdyn.hybrid.pipeline_mode import mode_runner
from contactdyn.model.paths import INTERPRETED, PIPELINE
from contactdyn.model.system import System

MU, M_PART = 0.4, 0.2  #: the tilting tray's μ and part [kg]
K, B = 1e5, 100.0  #: [N/m], [N·s/m] our Kelvin–Voigt normal
K_T, B_T = 2e4, 40.0  #: [N/m], [N·s/m] our tangential Kelvin–Voigt stage
TRAY_CHANNELS = ("contact.rest.F_n", "contact.rest.F_f", "body.part.slide.x", "body.part.lift.x", "q")  #: compared


def _scene(name: str, **edits) -> tuple[dict, str]:
    scene = load_scene(name)
    doc = {k: (dict(v) if isinstance(v, dict) else v) for k, v in scene.document.items()}
    doc.update(edits)
    return doc, scene.file


def _tray_scene(contact: dict, y0: float = 0.0, **edits):
    """The tilting tray, its contact's keys ``contact`` replaced, the part ``y0`` [m] from the axis, output at 1 kHz
    (``edits``: top-level keys)."""
    doc, file = _scene("tilt_tray", **edits)
    doc["contact"] = {"rest": {**doc["contact"]["rest"], **contact}}
    doc["body"] = {"part": {**doc["body"]["part"], "position0": [y0, 0.0]}}
    doc["solver"] = {**doc["solver"], "output_rate": 1000.0}
    return parse_scene(doc, None, file)


def _tray(k: float = K, b: float = B, y0: float = 0.0, **edits):
    """The tilting tray with a Kelvin–Voigt normal (k [N/m], b [N·s/m]), the part ``y0`` [m] from the axis."""
    return _tray_scene({"normal": {"direction": [0.0, 0.0, 1.0], "model": "c", "k": k, "b": b}}, y0, **edits)


def _audit_closes(r) -> None:
    """The run's energy audit closes within its tolerance."""
    residual = r.meta["checks"]["energy_residual"]
    assert residual["value"] <= residual["tol"], residual


def _carries_m_g_cos_theta(r, settled_samples: int) -> np.ndarray:
    """While the part sticks (after the first second's decay: the chain starts undeformed; more than
    ``settled_samples`` samples), its normal force is m g cos θ to 1e-6 N; those samples' mask."""
    theta, t = r["q"][:, 0], r["t"]
    settled = r["contact.rest.stuck"].astype(bool) & (t > 1.0)
    assert settled.sum() > settled_samples
    np.testing.assert_allclose(r["contact.rest.F_n"][settled], M_PART * G * np.cos(theta[settled]), rtol=0,
                               atol=1e-6)
    return settled


def _agree(interpreted, fast, keys) -> None:
    """Each channel of ``keys`` of the compiled run ``fast`` within 1e-9 of its largest value on the interpreted
    run."""
    for key in keys:
        ref = np.asarray(interpreted[key], float)
        np.testing.assert_allclose(fast[key], ref, rtol=0, atol=1e-9 * np.abs(ref).max(), err_msg=key)


@pytest.fixture(scope="module")
def tray():
    return simulate(_tray())


def test_on_the_tilting_tray_the_part_sinks_f_over_k_and_carries_m_g_cos_theta_while_it_sticks(tray):
    r = tray
    settled = _carries_m_g_cos_theta(r, settled_samples=2500)
    theta, F_n = r["q"][:, 0], r["contact.rest.F_n"]
    y, z = r["body.part.slide.x"], r["body.part.lift.x"]
    sink = -np.sin(theta) * y + np.cos(theta) * z  # [m] along the tray's normal
    np.testing.assert_allclose(sink[settled], -F_n[settled] / K, rtol=0, atol=1e-8)


def test_on_the_tilting_tray_the_part_slips_where_tan_theta_is_mu_and_the_energy_closes(tray):
    (slip,) = [e["t"] for e in tray.events if e["kind"] == "slip"]
    assert slip == pytest.approx(np.arctan(MU) / 0.1, abs=1e-3)  # the tray tilts at 0.1 rad/s from level
    _audit_closes(tray)


def test_the_chain_on_the_tray_runs_compiled_and_the_interpreted_run_agrees(tray):
    assert {row["path"] for row in tray.stats["paths"].values()} == {PIPELINE}
    interpreted = simulate(_tray(), compiled=False)
    assert {row["path"] for row in interpreted.stats["paths"].values()} == {INTERPRETED}
    _agree(interpreted, tray, TRAY_CHANNELS)


def test_undamped_and_off_the_axis_the_part_rides_the_tray_and_the_energy_audit_closes():
    """b = 0: the part, 0.1 m from the axis, falls onto the spring and rings as the tray carries it around (the
    material point under it moves and turns; only the tray's PD damps the ringing): the audit's residual is the
    model's consistency."""
    r = simulate(_tray(b=0.0, y0=0.1, duration=2.0))
    assert r["contact.rest.touching"].all()
    assert r["contact.rest.F_n"].max() > 1.5 * M_PART * G  # it rang (the tray's PD damps it through the tilt)
    _audit_closes(r)


def _bar_onto(normal: dict, theta0: float = 1.2, duration: float = 1.0):
    """The lever's bar released at θ0 [rad], its lower end (0.5 m from the pivot) over a frictionless table 0.4 m
    below the pivot, the table's normal ``normal``; the tool far aside."""
    doc, file = _scene("lever", duration=duration)
    table = {"frame": "lever", "body_frame": "bar", "frame_point": [0.0, 0.0, -L], "body": "ground",
             "point": [0.0, 0.0, PIVOT_Z - 0.4], "normal": {"direction": [0.0, 0.0, 1.0], **normal},
             "tangent": {"model": "free"}}
    doc["body"] = {"lever": {**doc["body"]["lever"], "position0": theta0}}
    doc["contact"] = {"table": table}
    doc["robot"] = {**doc["robot"], "q0": [1.0, 0.2]}
    return simulate(parse_scene(doc, None, file))


def test_the_bar_s_end_strikes_a_model_b_chain_as_two_masses_and_rests_on_it_with_m_g_d_over_l():
    """The end meets m′ at θ_c = arccos(0.8) moving at v = L sin θ_c θ̇ (θ̇ from the swing's energy); its mass along
    the normal there is I_O / (L sin θ_c)²: the plastic impact keeps v m_eff / (m_eff + m′) and loses
    ½ m_eff m′ v² / (m_eff + m′). At rest the chain carries m g d / L whatever the angle (moments about the
    pivot: m g d sin θ = F L sin θ)."""
    m_prime = 0.05
    r = _bar_onto({"model": "b", "k": 1e4, "b": 60.0, "m": m_prime}, duration=2.0)
    hit = r.impacts[0]  # (the first: the bar rebounds off the chain and strikes it again, less each time)
    assert hit["contact"] == "table"
    theta_c, theta0 = np.arccos(0.8), 1.2
    omega = np.sqrt(2 * M_BAR * G * D * (np.cos(theta_c) - np.cos(theta0)) / I_O)
    v, m_eff = L * np.sin(theta_c) * omega, I_O / (L * np.sin(theta_c)) ** 2
    assert hit["energy_loss"] == pytest.approx(0.5 * m_eff * m_prime * v**2 / (m_eff + m_prime), rel=1e-6)
    assert r["contact.table.F_n"][-1] == pytest.approx(M_BAR * G * D / L, rel=1e-6)
    assert abs(r["body.lever.v"][-1]) < 1e-6
    _audit_closes(r)


def test_a_tool_pressed_into_a_kelvin_voigt_face_of_the_bar_holds_it_at_rest():
    """The bar at θ, the tool sunk F/k into its face at the arm a with F = m g d sin θ / a (the static hold's), its
    spring's reference set to balance F: nothing accelerates, the chain's force acts on the bar's coordinate
    through the face's turning normal."""
    theta, k = 0.3, 2e4
    doc, file = _scene("lever")
    n = np.array([np.cos(theta), -np.sin(theta)])  # the face's normal in (x, z)
    F_n = M_BAR * G * D * np.sin(theta) / ARM
    face = np.array([-ARM * np.sin(theta), PIVOT_Z - ARM * np.cos(theta)])
    tool = face - F_n / k * n  # sunk into the face
    ref = tool - F_n * n / KP
    push = {**doc["contact"]["push"], "normal": {"direction": [1.0, 0.0, 0.0], "model": "c", "k": k, "b": 40.0},
            "tangent": {"model": "free"}}
    doc.update(body={"lever": {**doc["body"]["lever"], "position0": theta}}, contact={"push": push},
               robot={**doc["robot"], "q0": tool.tolist()},
               phase=[{"name": "hold", "reference": {"start": [ref[0], 0.0, ref[1]], "moves": []}}])
    system = System(parse_scene(doc, None, file))
    x, modes = system.initial_state()
    modes = [m.with_(touching=True) for m in modes]
    ev = mode_runner(system)(modes, system.start_phase(0, 0.0, x, None)).evaluation(0.0, x)
    assert ev.normal_force["push"] == pytest.approx(F_n, rel=1e-9)
    np.testing.assert_allclose(ev.xdot[system.nQ:2 * system.nQ], 0.0, rtol=0, atol=1e-9)
    doc["duration"] = 0.3
    r = simulate(parse_scene(doc, None, file))  # and held so for a while
    assert r["contact.push.touching"].all()
    np.testing.assert_allclose(r["body.lever.x"], theta, rtol=0, atol=1e-9)
    np.testing.assert_allclose(r["contact.push.F_n"], F_n, rtol=1e-7)


# ---- a chain's mass riding a turning surface (contact.RidingMass) ---------------------------------------------------

def _tray_b(k: float = K, b: float = B, m: float = 0.01, duration: float = 2.0, **contact):
    """The tilting tray with a model-(b) normal: ground —[k, b]— m′, the part striking m′ (a mass riding the tray);
    ``duration`` [s]."""
    return _tray_scene({"normal": {"direction": [0.0, 0.0, 1.0], "model": "b", "k": k, "b": b, "m": m}, **contact},
                       duration=duration)


RIDER = """<joint name="xi" type="prismatic"><parent link="tray"/><child link="rider"/>
  <origin xyz="{p[0]!r} {p[1]!r} {p[2]!r}"/><axis xyz="{n[0]!r} {n[1]!r} {n[2]!r}"/>
  <limit lower="-1" upper="1" effort="1" velocity="1"/></joint>
<link name="rider"><inertial><mass value="{m!r}"/><inertia ixx="0" ixy="0" ixz="0" iyy="0" iyz="0" izz="0"/>
  </inertial></link>
</robot>"""


@pytest.mark.parametrize("chain", ["normal", "tangent"])
def test_a_riding_mass_is_a_prismatic_joint_of_what_carries_the_surface(chain):
    """M and the bias of the tray and m′ are Pinocchio's for the tray with a prismatic joint at the surface's point
    along the chain's direction (its normal, or a tangent) carrying a point mass m′ (no gravity on m′: the chain's
    masses are weightless), at a state with every term awake: the tray tilted and turning, m′ off the point and
    moving."""
    import pinocchio as pin

    p0, n0, t0, m = np.array([0.02, -0.1, -0.03]), np.array([0.0, 0.6, 0.8]), np.array([0.0, 0.8, -0.6]), 0.05
    if chain == "normal":
        normal = {"direction": n0.tolist(), "model": "b", "k": K, "b": B, "m": m}
        tangent = {"model": "friction", "directions": [t0.tolist()], "mu": MU}
    else:
        normal = {"direction": n0.tolist()}
        tangent = {"model": "chain", "directions": [t0.tolist()], "environment": [{"k": K_T}, {"m": m}]}
    from contactdyn.model.pipeline.contacts import add_riding
    from contactdyn.model.pipeline.pipeline import Pipeline
    from contactdyn.model.pipeline.robot_terms import frame_terms, robot_terms
    from contactdyn.simulate import prepare

    system, modes, phase, x = prepare(_tray_b(point=p0.tolist(), normal=normal, tangent=tangent))
    (rm,) = system.riding
    np.testing.assert_array_equal(rm.direction, n0 if chain == "normal" else t0)
    nQ, i = system.nQ, rm.coord
    x[0], x[nQ], x[i], x[nQ + i] = 0.3, 0.7, 0.04, -0.4  # [rad, rad/s, m, m/s]
    system.robot.update(x[:1], x[nQ:nQ + 1])
    system.update_bodies(x)
    M = system.mass_matrix()[np.ix_([0, i], [0, i])]
    # the call's own: the rigid-body table's H (the tray), the mass riding it coupled in and its bias added to f
    p = Pipeline(system, modes, phase).packed
    H, _, _, Jw, W = robot_terms(x, p.ints, p.reals)
    FJ, Fa, _, _, FR = frame_terms(x, p.ints, p.reals, W, Jw)
    f = np.zeros(nQ)
    M_call = add_riding(x, p.ints, p.reals, FJ, Fa, FR, H.copy(), f)[np.ix_([0, i], [0, i])]
    M_call[1, 1] += m  # (m′'s own mass: M_rest's diagonal, packed apart)
    bias = -f[[0, i]]  # the rider's part of the bias
    xml = (Path(__file__).parents[1] / "urdf" / "tilt_tray.urdf").read_text().replace("</robot>", "")
    model = pin.buildModelFromXML(xml + RIDER.format(p=p0.tolist(), n=rm.direction.tolist(), m=m))
    alone = pin.buildModelFromXML(xml + "</robot>")
    model.gravity.linear[:] = alone.gravity.linear[:] = 0.0
    q, v = np.array([0.3, 0.04]), np.array([0.7, -0.4])
    data, data_alone = model.createData(), alone.createData()
    expected_M = pin.crba(model, data, q)
    expected_M = np.triu(expected_M) + np.triu(expected_M, 1).T
    np.testing.assert_allclose(M, expected_M, rtol=0, atol=1e-13)
    np.testing.assert_allclose(M_call, expected_M, rtol=0, atol=1e-13)
    expected_bias = pin.rnea(model, data, q, v, np.zeros(2)) - [pin.rnea(alone, data_alone, q[:1], v[:1],
                                                                          np.zeros(1))[0], 0.0]
    np.testing.assert_allclose(bias, expected_bias, rtol=0, atol=1e-13)


@pytest.fixture(scope="module")
def riding():
    return simulate(_tray_b())


def test_on_the_tilting_tray_a_model_b_chain_carries_m_g_cos_theta_and_the_audit_closes(riding):
    r = riding
    _carries_m_g_cos_theta(r, settled_samples=900)
    _audit_closes(r)


def test_a_riding_mass_runs_on_the_compiled_call_and_the_interpreted_run_agrees(riding):
    """The mass's coupling with the tray (contact.riding_point, one function for both paths) in the compiled call's M
    and f: the runs agree to 1e-9 of each channel's largest value."""
    assert {row["path"] for row in riding.stats["paths"].values()} == {PIPELINE}
    interpreted = simulate(_tray_b(), compiled=False)
    assert {row["path"] for row in interpreted.stats["paths"].values()} == {INTERPRETED}
    _agree(interpreted, riding, (*TRAY_CHANNELS, "v"))
    assert [e["kind"] for e in riding.events] == [e["kind"] for e in interpreted.events]
    np.testing.assert_allclose([e["t"] for e in riding.events], [e["t"] for e in interpreted.events], rtol=0,
                               atol=1e-9)


def test_the_tool_strikes_a_mass_riding_the_bar_s_face_and_the_bar_feels_no_impulse():
    """m′ rides the bar on a prismatic line along the face's normal: an impulse along that line moves m′ alone. The
    tool (2 kg) strikes it plastically: the loss ½ m_t m′ v² / (m_t + m′), the bar still at rest just after."""
    m_prime = 0.1
    doc, file = _scene("lever", duration=0.3)
    push = {**doc["contact"]["push"], "normal": {"direction": [1.0, 0.0, 0.0], "model": "b", "k": 2e4, "b": 50.0,
                                                 "m": m_prime}}
    doc["contact"] = {"push": push}
    r = simulate(parse_scene(doc, None, file))
    hit = r.impacts[0]
    v = -float(hit["v_before"][0]) if "v_before" in hit else None
    assert hit["contact"] == "push" and v is not None and v > 0.0, hit
    assert hit["energy_loss"] == pytest.approx(0.5 * M_TOOL * m_prime * v**2 / (M_TOOL + m_prime), rel=1e-9)
    bar = 2  # (Q: the tool's x and z, the bar's angle, m′'s ξ)
    assert abs(hit["v_after"][bar]) < 1e-15 and hit["v_after"][-1] == pytest.approx(hit["v_after"][0], rel=1e-12)
    _audit_closes(r)


# ---- a tangential chain on a turning surface -------------------------------------------------------------------------

def _tray_t():
    """The tilting tray, its part held along the slope by a tangential Kelvin–Voigt chain (rigid normal)."""
    return _tray_scene({"tangent": {"model": "chain", "directions": [[0.0, 1.0, 0.0]],
                                    "environment": [{"k": K_T, "b": B_T}]}})


@pytest.fixture(scope="module")
def held():
    return simulate(_tray_t())


def test_a_tangential_chain_holds_the_part_on_the_tilting_tray_m_g_sin_theta_over_k_down_the_slope(held):
    r = held
    theta, t = r["q"][:, 0], r["t"]
    late = (t > 1.0) & (t < 5.0)  # (the chain starts undeformed: a decay first; at 5 s the tilt stops)
    assert r["contact.rest.touching"].all() and not [e for e in r.events if e["kind"] in ("separate", "slip")]
    y, z = r["body.part.slide.x"], r["body.part.lift.x"]
    along = np.cos(theta) * y + np.sin(theta) * z  # [m] along the tray's y: up the slope
    F, F_dot = M_PART * G * np.sin(theta), M_PART * G * np.cos(theta) * r["v"][:, 0]  # the slope's pull [N], [N/s]
    quasi_static = -(F - B_T / K_T * F_dot) / K_T  # k x + b ẋ = −F, x ≈ −F/k + b Ḟ / k² [m]
    np.testing.assert_allclose(along[late], quasi_static[late], rtol=0, atol=1e-11)
    np.testing.assert_allclose(r["contact.rest.F_n"][late], M_PART * G * np.cos(theta[late]), rtol=0, atol=1e-6)
    _audit_closes(r)


def test_the_tangential_chain_on_the_tray_runs_compiled_and_the_interpreted_run_agrees(held):
    assert {row["path"] for row in held.stats["paths"].values()} == {PIPELINE}
    interpreted = simulate(_tray_t(), compiled=False)
    assert {row["path"] for row in interpreted.stats["paths"].values()} == {INTERPRETED}
    _agree(interpreted, held, ("contact.rest.F_n", "body.part.slide.x", "body.part.lift.x", "q"))


def test_a_chain_with_a_mass_on_its_robot_side_rides_the_tray_too_and_the_audit_closes():
    """tip —[k, b]— m′ —[k, b]— surface: a chain is one line, carried by its surface (as a fixed surface's is by the
    world): m′ rides the tray like an environment-side mass. The part held by the tray's friction: F_n m g cos θ
    through the two stages in series, the audit closing."""
    stage = {"k": 2e4, "b": 20.0}  # (our choice: m′ = 0.1 kg rings at 630 rad/s, ζ = 0.3: an explicit step's pace)
    r = simulate(_tray_b(normal={"direction": [0.0, 0.0, 1.0], "robot": [stage, {"m": 0.1}, stage]}))
    _carries_m_g_cos_theta(r, settled_samples=900)
    _audit_closes(r)
