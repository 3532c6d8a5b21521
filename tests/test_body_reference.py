"""References carried by an active body (``[phase.reference] body = "cart"``): task coordinates
relative to a moving body, as the paper's case 1 (eq. 5: s_r1 = ... + q_e1).

x_d = o(t) + start + Σ moves with o = axis · Q_b the body's origin; its velocity joins v_d and
its acceleration a_d. The acceleration is an unknown of the linear system: it is folded there,
so a computed-torque law (A7) makes the error relative to the body obey its transient exactly,
even while the body accelerates.
"""

from __future__ import annotations

import numpy as np
import pytest

from contactdyn import Robot, SceneError, parse_scene, simulate

Q0 = np.array([0.3, 1.2])  # [rad] writer pose: tip at about (0.388, 0, 0.308)
CASE2 = {"kind": "dc_motor", "R": 0.272, "C_M": 0.061, "J": 0.000452, "N": 160.0, "N_star": 65.12}
AXIS = np.array([-1.0, 0.0, 0.0])  # the cart runs towards the robot's base
#: 20 kg cart from rest, servo to 0.2 m/s with 200 N·s/m: accelerates at 2 m/s² at first (time constant 0.1 s)
CART = {"mass": 20.0, "axis": AXIS.tolist(), "servo": {"velocity": 0.2, "gain": 200.0}}


def tip0() -> np.ndarray:
    return Robot.load("writer2r").frame_position(Q0, "tip")


def doc(phases: list[dict], controller: dict, drive: dict | None = None, duration: float = 0.5) -> dict:
    robot = {"urdf": "writer2r", "q0": Q0.tolist()}
    if drive is not None:
        robot["drive"] = drive
    return {"duration": duration, "solver": {"rtol": 1e-10, "atol": 1e-12, "output_rate": 500.0}, "robot": robot,
            "body": {"cart": CART}, "controller": controller, "phase": phases}


@pytest.mark.parametrize("drive", [None, CASE2], ids=["torque", "dc_motor"])
def test_position_law_on_an_accelerating_cart_makes_the_relative_error_obey_P(drive):
    """A7 in task space, reference on the cart: η = tip − x_d obeys η̈ = −400 η − 40 η̇ from
    η(0) = p0 − start (closed form (η0 + 20 η0 t) e^(−20 t)) to 1e-6 of |η0|, while the cart
    accelerates from rest at up to 2 m/s² (leaving out its acceleration would cost ~a/K_p = 5 mm)."""
    p0 = tip0()
    start = p0 + np.array([0.002, 0.0, -0.008])  # [m] relative to the cart's origin (at 0 when t = 0)
    ref = {"body": "cart", "start": start.tolist(),
           "moves": [{"kind": "trapezoid", "delta": [0.004, 0.0, 0.03], "duration": 0.4, "start": 0.05}]}
    r = simulate(parse_scene(doc([{"name": "main", "reference": ref}], {"kind": "position_dynamic"}, drive)))
    v_cart = r["body.cart.v"]
    assert v_cart[-1] > 0.19 and np.max(np.diff(v_cart) / np.diff(r.t)) > 1.5  # [m/s, m/s²] it really accelerates
    eta0 = p0 - start
    expected = np.outer((1.0 + 20.0 * r.t) * np.exp(-20.0 * r.t), eta0)
    np.testing.assert_allclose(r["tip"] - r["tip_ref"], expected, rtol=0, atol=1e-6 * np.linalg.norm(eta0))
    # the recorded reference is absolute: the cart's origin plus the relative one
    relative = r["tip_ref"] - np.outer(r["body.cart.x"], AXIS)
    np.testing.assert_allclose(relative[0], start, atol=1e-12)
    np.testing.assert_allclose(relative[-1], start + [0.004, 0.0, 0.03], atol=1e-12)


def test_a_carried_reference_continues_where_the_previous_phase_left():
    """Without a start, the carried reference starts at the previous reference's absolute position
    (no jump), then rides on the cart, also after the last phase's end (it runs on to the scene's
    duration): a PD holds the tip on the cart to within its lag."""
    p0 = tip0()
    pd = {"kind": "task_pd", "kp": 2e4, "kd": 400.0, "axes": [[1, 0, 0], [0, 0, 1]], "feedforward": "gravity"}
    phases = [{"name": "hold", "until": 0.1, "reference": {"start": p0.tolist()}},
              {"name": "ride", "until": 0.4, "reference": {"body": "cart"}}]
    r = simulate(parse_scene(doc(phases, pd, duration=0.6)))
    k = int(np.searchsorted(r.t, 0.1))
    np.testing.assert_allclose(r["tip_ref"][k - 1], p0, atol=1e-12)
    np.testing.assert_allclose(r["tip_ref"][k + 1], p0 + AXIS * (r["body.cart.x"][k + 1] - r["body.cart.x"][k]),
                               atol=1e-12)  # continuous, carried from the cart's position at the switch
    on_cart = r["tip_ref"][k + 1:] - np.outer(r["body.cart.x"][k + 1:], AXIS)
    np.testing.assert_allclose(on_cart, on_cart[0] + 0 * on_cart, atol=1e-12)  # fixed on the cart, to the end
    moved = r["body.cart.x"][-1] - r["body.cart.x"][k]
    assert moved > 0.08  # [m]
    np.testing.assert_allclose(r["tip"][-1], p0 + AXIS * moved, atol=2e-3)  # [m] the PD's lag at 0.2 m/s


@pytest.mark.parametrize("reference, match", [
    ({"body": "crat"}, r"phase\[0\]\.reference\.body.*'cart'.*did you mean 'cart'.*crat"),
    ({"body": "cart", "space": "joint", "start": [0.3, 1.2]}, r"reference\.body.*'ground' for a joint-space"),
])
def test_a_bad_carrier_names_the_key(reference, match):
    with pytest.raises(SceneError, match=match):
        parse_scene(doc([{"name": "main", "reference": reference}], {"kind": "task_pd"}))


def test_a_tangential_force_reference_needs_a_tangential_chain():
    """force_reference presses F_d/k beyond a tangential chain's anchor; a friction tangent has none (the scene
    reader refuses any tangential set-point there)."""
    p0 = tip0()
    d = doc([{"name": "main", "reference": {"start": p0.tolist()}, "force": [{"contact": "c", "direction": "t1",
                                                                               "value": 10.0}]}],
            {"kind": "position_dynamic", "force_reference": True})
    d["contact"] = {"c": {"point": p0.tolist(), "normal": {"direction": [0, 0, 1], "model": "c", "k": 1e4},
                          "tangent": {"model": "friction", "directions": [[1, 0, 0]], "mu": 0.3}}}
    with pytest.raises(SceneError, match=r"phase\[0\]\.force\[0\]\.direction.*chain force.*'friction'"):
        simulate(parse_scene(d))
