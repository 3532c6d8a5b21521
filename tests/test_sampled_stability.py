"""The sampled loop's z-domain poles (contactdyn.analysis.sampled_stability): closed forms, and B1's force loop."""

from __future__ import annotations

import numpy as np
import pytest

from contactdyn.analysis.sampled_stability import (
    SampledLoop,
    closed_loop,
    decay_rate,
    linear_window,
    measured_rate,
    run_from,
    with_tip_velocity,
    zoh,
)
from contactdyn.analysis.stability import contact_phase_scene

B1_Q0 = [0.337307481430, -1.318116071653]  #: B1's start (tip at (0.45, −0.15))
B1_SCENE = "sims/b1_force_loop.toml"
SLIDE = 2e-4  #: [m/s] the runs' sliding speed (0.4 mm in a run: the poles move ~4 % per cm of pose)


def b1_reference(speed: float) -> dict:
    """B1's reference from (0.43, −0.15) moving along −x at ``speed`` [m/s], the slide's direction B1's."""
    return {"phase.0.reference.moves": [{"kind": "constant_velocity", "delta": [-4.0 * speed, 0.0, 0.0],
                                         "duration": 4.0}],
            "robot.v0": [0.287298334621 / 15.0, -0.774596669241 / 15.0]}


def test_zoh_of_a_scalar_system_is_the_closed_form():
    """ẋ = a x + b u held over h: Φ = e^{ah}, Γ = (e^{ah} − 1) / a · b."""
    a, b, h = -3.7, 2.5, 0.013
    Phi, Gamma = zoh(np.array([[a]]), np.array([[b]]), h)
    assert Phi[0, 0] == pytest.approx(np.exp(a * h), rel=1e-14)
    assert Gamma[0, 0] == pytest.approx((np.exp(a * h) - 1.0) / a * b, rel=1e-13)


def test_zoh_of_a_double_integrator_is_the_closed_form():
    """ẍ = u: Φ = [[1, h], [0, 1]], Γ = [h²/2, h]."""
    h = 0.004
    Phi, Gamma = zoh(np.array([[0.0, 1.0], [0.0, 0.0]]), np.array([[0.0], [1.0]]), h)
    np.testing.assert_allclose(Phi, [[1.0, h], [0.0, 1.0]], rtol=0, atol=1e-16)
    np.testing.assert_allclose(Gamma[:, 0], [h * h / 2.0, h], rtol=1e-14)


@pytest.mark.parametrize("delay", [0, 1, 3])
def test_a_delayed_integrator_loop_has_the_roots_of_its_characteristic_polynomial(delay):
    """ẋ = u, u_k = −k x_{k−d} under a hold: x_{k+1} = x_k − k h x_{k−d}, so z^{d+1} − z^d + k h = 0 (and the
    register's slots of the held command, which nothing reads, stay at z = 0)."""
    k, h = 30.0, 0.01
    Phi, Gamma = zoh(np.zeros((1, 1)), np.ones((1, 1)), h)
    K = np.array([[-k, 0.0]])  # reads m = [x, u_prev]
    T = closed_loop(Phi, Gamma, K, np.zeros((1, 0)), np.zeros((0, 2)), np.zeros((0, 0)), h, delay)
    z = np.linalg.eigvals(T)
    expected = np.roots([1.0, -1.0] + [0.0] * (delay - 1) + [k * h] if delay else [1.0, k * h - 1.0])
    found = z[np.argsort(-np.abs(z))][: delay + 1]
    np.testing.assert_allclose(np.sort_complex(found), np.sort_complex(expected), atol=1e-12)
    np.testing.assert_allclose(np.sort(np.abs(z))[: len(z) - delay - 1], 0.0, atol=1e-12)


def test_a_delayed_integrator_loop_turns_unstable_where_the_closed_form_says():
    """z² − z + kh = 0 (one sample of delay) has |z| = √(kh) for kh > 1/4: unstable beyond kh = 1."""
    h = 0.01
    Phi, Gamma = zoh(np.zeros((1, 1)), np.ones((1, 1)), h)
    for kh, stable in ((0.9, True), (1.1, False)):
        T = closed_loop(Phi, Gamma, np.array([[-kh / h, 0.0]]), np.zeros((1, 0)), np.zeros((0, 2)),
                        np.zeros((0, 0)), h, 1)
        z_max = np.max(np.abs(np.linalg.eigvals(T)))
        assert z_max == pytest.approx(np.sqrt(kh), rel=1e-12)
        assert (decay_rate(z_max, h) < 0.0) == stable


def test_a_sampled_integrator_state_advances_by_forward_euler():
    """A law with a state z, ż = −c x, u = z, on ẋ = 0 (a plant that holds x): z_{k+1} = z_k − c h x_k, and
    x stays; with ẋ = u: x_{k+1} = x_k + h z_k, z_{k+1} = z_k − c h x_k → z² − 2z + 1 + c h² = 0."""
    c, h = 400.0, 0.01
    Phi, Gamma = zoh(np.zeros((1, 1)), np.ones((1, 1)), h)
    T = closed_loop(Phi, Gamma, np.zeros((1, 2)), np.ones((1, 1)), np.array([[-c, 0.0]]), np.zeros((1, 1)), h, 0)
    z = np.linalg.eigvals(T)
    np.testing.assert_allclose(np.sort_complex(z[np.abs(z) > 1e-9]), np.sort_complex(np.roots([1, -2, 1 + c * h * h])),
                               atol=1e-12)


@pytest.fixture(scope="module")
def b1_sampled():
    """B1's force loop sampled, linearised at its start with the reference held there (the contact sliding)."""
    loop = SampledLoop(contact_phase_scene(B1_SCENE, B1_Q0, b1_reference(0.0)), t_eq=0.0)
    return loop, loop.linearize()


@pytest.fixture(scope="module")
def b1_force_loop(b1_sampled):
    return b1_sampled[1]


def test_b1_force_loop_tends_to_the_continuous_poles_at_first_order_in_h(b1_force_loop):
    """No delay: the sampled loop's poles z map back (ln z · rate) to the continuous loop's (the simulator's own,
    stability.ContactLoop) as h → 0, at first order (the hold lags by h/2): the force loop's −33.35 ± 47.13i
    within 0.5 % at 100 kHz, ten times closer than at 10 kHz."""
    lin = b1_force_loop
    force_pole = lin.continuous[np.argmax(lin.continuous.imag)]
    assert force_pole.real == pytest.approx(-33.35, abs=0.01) and force_pole.imag == pytest.approx(47.13, abs=0.01)
    gaps = []
    for rate in (1e4, 1e5):
        s = np.log(lin.poles(rate, 0).astype(complex)) * rate
        gaps.append(float(np.min(np.abs(s - force_pole))))
    assert gaps[1] < 0.005 * abs(force_pole)
    assert gaps[0] / gaps[1] == pytest.approx(10.0, rel=0.1)


def test_b1_force_loop_turns_unstable_as_the_rate_drops_or_the_delay_grows(b1_force_loop):
    """The boundary |z_max| = 1 lies inside the map's range: stable at 2 kHz for every delay up to 5 and at
    any rate down to 100 Hz without delay; unstable at 200 Hz with 4 samples and at 100 Hz with 2."""
    lin = b1_force_loop
    assert all(lin.sigma(2000.0, d) < -5.0 for d in range(6))
    assert all(lin.sigma(f, 0) < -5.0 for f in (1000.0, 500.0, 200.0, 100.0))
    assert lin.sigma(200.0, 2) < 0.0 < lin.sigma(200.0, 4)
    assert lin.sigma(100.0, 1) < 0.0 < lin.sigma(100.0, 2)


def test_the_sampled_loop_is_read_off_the_simulators_own_sampled_phase(b1_sampled):
    """The held command is the state's held slots (SampledController) at the law's fixed point, and the pieces do
    not depend on the scene's own rate and delay: the same poles from a scene sampled at 50 Hz with 3 samples."""
    loop, lin = b1_sampled
    ctl = loop.loop.phase.controller
    assert len(lin.held) == ctl.nv and np.array_equal(lin.u, lin.x[lin.held])
    tau, _ = b1_sampled[0]._command(lin.x)  # the law's command on what it measures under u itself: u again
    np.testing.assert_allclose(tau, lin.u, rtol=1e-11, atol=0.0)
    other = SampledLoop(contact_phase_scene(B1_SCENE, B1_Q0, {**b1_reference(0.0), "controller.sample_rate": 50.0,
                                                              "controller.delay": 3}), t_eq=0.0).linearize()
    np.testing.assert_allclose(other.poles(200.0, 4), lin.poles(200.0, 4), rtol=1e-9)


@pytest.mark.parametrize(("rate", "delay"), [(200.0, 2), (200.0, 4)])
def test_b1_sampled_run_decays_or_grows_at_the_z_domain_rate(b1_sampled, rate, delay):
    """The simulator's sampled run from the equilibrium, sliding at 0.2 mm/s, its set-point raised by 0.01 N (the
    error stays near 0.01 N, the slip keeps its direction): the force error's mode at the sample instants has the
    dominant z-pole's rate and frequency, on both sides of the boundary (σ = −2.464 and +1.570 1/s). Over 8 points
    the benchmark finds 0.03–0.22 %; the tolerance is 1 % (a one-sample change of the delay moves σ by over 1 /s,
    40 times as much)."""
    loop, lin = b1_sampled
    over = {**b1_reference(SLIDE), "controller.sample_rate": rate, "controller.delay": delay, "duration": 2.0,
            "solver.output_rate": rate, "solver.rtol": 1e-10, "solver.atol": 1e-12, "phase.0.force.0.value": 100.01}
    r = run_from(contact_phase_scene(B1_SCENE, B1_Q0, over), with_tip_velocity(loop.loop, lin.x, [-SLIDE, 0.0, 0.0]))
    t, err = linear_window(r, 0.3, 0.5)
    assert t[-1] == pytest.approx(2.0)  # linear over the whole run
    z = lin.dominant(rate, delay)
    sigma, freq = measured_rate(t, err, z, 1.0 / rate)
    predicted = lin.sigma(rate, delay)
    assert (predicted > 0.0) == (delay == 4) and (sigma > 0.0) == (predicted > 0.0)
    assert sigma == pytest.approx(predicted, rel=0.01)
    assert freq == pytest.approx(abs(np.angle(z)) * rate / (2.0 * np.pi), abs=0.01)
    assert abs(lin.sigma(rate, delay + 1) - predicted) > 1.0


MOTORS = {"robot.drive.kind": "dc_motor", "robot.drive.C_M": 0.05, "robot.drive.C_E": 0.05, "robot.drive.R": 1.0,
          "robot.drive.J": 1e-5, "robot.drive.N": 20.0}  #: B1's joints through DC motors (eq. 51)


@pytest.mark.parametrize(("rate", "delay"), [(100.0, 1), (100.0, 2)])
def test_a_voltage_hold_decays_or_grows_at_its_own_z_domain_rate(rate, delay):
    """B1's force loop through DC motors with the motors' voltages held (``hold = "voltage"``): the oracle linearises
    the same sampled law, the conversion to voltages at the measured speeds included, and the simulator's run decays
    or grows at its rate on both sides of the boundary (σ = −1.808 and +1.459 1/s; 0.01 % and 0.15 % measured), which
    is not the torque hold's (−1.727 and +1.652 1/s: 4.5 % and 13 % away)."""
    lins = {hold: SampledLoop(contact_phase_scene(B1_SCENE, B1_Q0, {**b1_reference(0.0), **MOTORS,
                                                                     "controller.sample_rate": rate,
                                                                     "controller.hold": hold}), t_eq=0.0)
            for hold in ("voltage", "command")}
    loop = lins["voltage"]
    lin, other = loop.linearize(), lins["command"].linearize()
    over = {**b1_reference(SLIDE), **MOTORS, "controller.hold": "voltage", "controller.sample_rate": rate,
            "controller.delay": delay, "duration": 2.0, "solver.output_rate": rate, "solver.rtol": 1e-10,
            "solver.atol": 1e-12, "phase.0.force.0.value": 100.01}
    r = run_from(contact_phase_scene(B1_SCENE, B1_Q0, over), with_tip_velocity(loop.loop, lin.x, [-SLIDE, 0.0, 0.0]))
    t, err = linear_window(r, 0.3, 0.5)
    assert t[-1] == pytest.approx(2.0)
    sigma, _ = measured_rate(t, err, lin.dominant(rate, delay), 1.0 / rate)
    predicted = lin.sigma(rate, delay)
    assert (predicted > 0.0) == (delay == 2) and sigma == pytest.approx(predicted, rel=0.01)
    assert abs(other.sigma(rate, delay) - predicted) > 3 * 0.01 * abs(predicted)  # (3 × the tolerance apart)
