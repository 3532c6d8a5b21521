"""Events whose function dips below zero and back within one step (events.DipWatch): a touch, a slide's stop.

The touch: a point mass (tests/test_friction.py's, m = 2 kg on a rigid floor z = 0) falls at u = 1 m/s and is pushed
up by F = 29.62 N: it decelerates at a = (F − m g)/m = 5 m/s² and would turn around δ below the floor. Its height is
a parabola, which DOP853 integrates exactly, so its steps grow to ~0.2 s and both ends of the step that crosses the
floor lie above it. The closed form: the touch at t* = (u − √(2 a δ))/a with v_z = −√(2 a δ), a plastic impact of
normal impulse m √(2 a δ), and the mass lifted off by F > m g at once.
"""

from __future__ import annotations

import copy
import math

import pytest
from test_friction import M, W, scene

from contactdyn import parse_scene, simulate

F, U = 29.62, 1.0  #: [N] the upward push, [m/s] the falling speed at t = 0
A = (F - W) / M  #: [m/s²] the upward acceleration


def grazing(delta: float, method: str = "DOP853C") -> dict:
    """The mass turning δ [m] below the floor (above it where δ < 0), in free flight at t = 0."""
    return scene(duration=0.5, **{"controller.force": [0.0, 0.0, F], "robot.q0": [0.0, U * U / (2 * A) - delta],
                                  "robot.v0": [0.0, -U], "solver": {"rtol": 1e-8, "atol": 1e-10, "method": method,
                                                                    "output_rate": 1000.0}})


@pytest.mark.parametrize("delta", [1e-3, 1e-6])
@pytest.mark.parametrize("method, compiled, t_tol", [("DOP853C", True, 1e-9), ("DOP853C", False, 1e-9),
                                                     ("LSODA", True, 1e-6), ("RK45", True, 1e-9), ("Radau", True, 1e-9),
                                                     ("BDF", True, 1e-6)])  # (t_tol [s]: LSODA's, BDF's interpolants)
def test_a_dip_through_the_floor_within_one_step_touches(delta, method, compiled, t_tol):
    """Every method finds it: our DOP853 and LSODA (numerics.dop853's event watch), solve_ivp's RK45, Radau and BDF
    (numerics.integrators._searching_steps: before, they passed 1 mm through the floor, seeing their step ends only)."""
    res = simulate(parse_scene(copy.deepcopy(grazing(delta, method))), compiled=compiled)
    speed = math.sqrt(2.0 * A * delta)  # [m/s] at the touch
    touches = [e for e in res.events if e["kind"] == "touch"]
    assert len(touches) == 1 and len(res.impacts) == 1
    assert touches[0]["t"] == pytest.approx((U - speed) / A, abs=t_tol)
    # (the speed at the touch is off by a·Δt where the touch is off by Δt ≤ t_tol)
    assert res.impacts[0]["normal_impulse"] == pytest.approx(M * speed, rel=max(1e-6, 2.0 * A * t_tol / speed))
    assert res["contact.ground.gap"].min() > -1e-9  # [m] (1 mm before: the whole dip)
    assert res.stats["dips_seen_inside_a_step"] == 1 or method == "LSODA"  # (LSODA's short steps may see the floor)
    assert not res.meta["check_warnings"]


@pytest.mark.parametrize("compiled", [True, False])
def test_a_turn_just_above_the_floor_does_not_touch(compiled):
    """The same fall turning 1 µm above the floor: no touch, and the steps stay long (the dip search is a check,
    not a step control)."""
    res = simulate(parse_scene(copy.deepcopy(grazing(-1e-6))), compiled=compiled)
    assert not res.events and not res.impacts and res.stats["dips_seen_inside_a_step"] == 0
    assert res["contact.ground.gap"].min() == pytest.approx(1e-6, abs=1e-9)
    assert res.stats["steps"] < 20


W_PUSH = 2.0 * math.pi  #: [rad/s] the push's angular frequency (1 Hz)
A_PUSH = 10.0  #: [N] its amplitude


def dipping_slide(eps: float, method: str = "DOP853C") -> dict:
    """The mass sliding along x on the floor (μ_s 0.5, μ_k 0.4), pushed with μ_k m g + A sin(ω t + π/2): while it
    slides m v̇ = A cos ω t, so v = A/(m ω) (1 + sin ω t) − ε dips to −ε at t = 0.75 s and back: it stops there."""
    return scene(mu_s=0.5, mu_k=0.4, duration=1.0, **{
        "controller.force": [0.4 * W, 0.0, 0.0], "controller.amplitude": [A_PUSH, 0.0, 0.0],
        "controller.frequency": 1.0, "controller.phase": [math.pi / 2, 0.0, 0.0],
        "robot.v0": [A_PUSH / (M * W_PUSH) - eps, 0.0],
        "solver": {"rtol": 1e-8, "atol": 1e-10, "method": method, "output_rate": 1000.0}})


@pytest.mark.parametrize("eps", [1e-4, 1e-8])
@pytest.mark.parametrize("compiled, method", [(True, "DOP853C"), (False, "DOP853C"), (True, "RK45"), (True, "Radau"),
                                              (True, "BDF")])
def test_a_slide_whose_speed_dips_through_zero_within_one_step_stops(eps, compiled, method):
    """Closed form: it stops where v reaches the stick band (just before 0.75 s), sticks (the push is then μ_k m g,
    inside the cone), and slips again where the push reaches μ_s m g: cos ω t_s = (μ_s − μ_k) m g / A, at
    t_s = 0.75 s + asin((μ_s − μ_k) m g / A)/ω; from rest there, v(1 s) = A/(m ω) √(1 − c²). Missed, the slide went
    on: v(1 s) = A/(m ω) − ε, 2 % more."""
    res = simulate(parse_scene(copy.deepcopy(dipping_slide(eps, method))), compiled=compiled)
    c = 0.1 * W / A_PUSH
    t_slip = 0.75 + math.asin(c) / W_PUSH
    kinds = [(e["kind"], e["t"]) for e in res.events]
    stops = [t for k, t in kinds if k == "stop"]
    slips = [t for k, t in kinds if k == "slip"]
    assert len(stops) == 1 and 0.74 < stops[0] <= 0.75
    assert len(slips) == 1 and slips[0] == pytest.approx(t_slip, abs=1e-7)
    assert res["v"][-1, 0] == pytest.approx(A_PUSH / (M * W_PUSH) * math.sqrt(1.0 - c * c), rel=1e-6)


OMEGA, HEIGHT = 10.0, 0.5  #: [rad/s] the tray's free turn, [m] the part above its axis
THETA0 = -math.pi / 2 + 0.01  #: [rad] the tray's start: its plane 5 mm below the part, turning away from it


@pytest.mark.parametrize("compiled, method", [(True, "DOP853C"), (False, "DOP853C"), (True, "DOP853"),
                                              (True, "RK45")])
def test_a_plane_turning_past_a_point_touches_it_the_first_time(compiled, method):
    """sims/tilt_tray.toml's tray turning freely at ω (no gravity, no law) past its part at rest HEIGHT above the
    axis: the gap is HEIGHT cos θ, so the plane reaches the part at θ = π/2, t* = (π/2 − θ0)/ω. θ is linear in t, so
    DOP853's steps grow to ~1 s, ~10 rad: the gap falls through zero three times in the step, and the touch is the
    first fall (DipWatch.first_fall). Before, Brent's method found the third, at 9.41/ω, with the part 0.5 m inside the
    plane for 0.6 s; with the joint's limit at 3 rad the limit came first and the touch was never seen."""
    res = simulate("tilt_tray", {"robot.gravity": [0.0, 0.0, 0.0], "robot.q0": [THETA0], "robot.v0": [OMEGA],
                                 "controller.kp": 0.0, "controller.kd": 0.0, "controller.feedforward": "none",
                                 "body.part.position0": [0.0, HEIGHT], "phase": [{"name": "turn"}],
                                 "duration": 12.0 / OMEGA, "solver.method": method, "solver.output_rate": 100.0},
                   compiled=compiled)
    assert res.events[0]["kind"] == "touch"
    assert res.events[0]["t"] == pytest.approx((math.pi / 2 - THETA0) / OMEGA, abs=1e-9)
    assert res["contact.rest.gap"].min() > -1e-9  # [m]
