"""Reference profiles: continuity, end points, derivatives by finite differences."""

from __future__ import annotations

import numpy as np
import pytest

from contactdyn.laws.trajectory import Move, Ramp, Reference, move_rows, move_table, profile, ramp_rows, ramp_table


@pytest.mark.parametrize("kind", ["trapezoid", "triangle", "constant_velocity"])
def test_profiles_go_from_0_to_1_with_consistent_derivatives(kind):
    taus = np.linspace(0.0, 1.0, 2001)
    s = np.array([profile(kind, t, 0.2)[0] for t in taus])
    ds = np.array([profile(kind, t, 0.2)[1] for t in taus])
    assert s[0] == pytest.approx(0.0, abs=1e-15) and s[-1] == pytest.approx(1.0, abs=1e-15)
    assert np.all(np.diff(s) >= -1e-15)  # monotone
    fd = np.gradient(s, taus)
    assert np.max(np.abs(fd[1:-1] - ds[1:-1])) < 2e-3 * max(1.0, ds.max())


def test_trapezoid_peak_velocity_and_triangle():
    # accel over 10 % of the move: peak dσ/dτ = 1 / (1 − 0.1)
    assert max(profile("trapezoid", t, 0.1)[1] for t in np.linspace(0, 1, 1001)) == pytest.approx(1 / 0.9)
    assert profile("triangle", 0.5)[1] == pytest.approx(2.0)


def test_velocity_ramp_reaches_and_keeps_its_velocity():
    move = Move(np.array([0.25 * 0.5, 0.0, 0.0]), start=0.0, duration=0.5, kind="velocity_ramp")
    ref = Reference(np.zeros(3), (move,))
    x, v, a = ref.at(2.0)
    assert v[0] == pytest.approx(0.25) and a[0] == 0.0
    assert x[0] == pytest.approx(0.25 * 2.0 - 0.25 * 0.25)  # ramp lost half its duration × v


def test_force_ramps():
    lin = Ramp(100.0, start=1.0, duration=0.1)
    assert lin.at(0.5) == (0.0, 0.0)
    assert lin.at(1.05)[0] == pytest.approx(50.0) and lin.at(1.05)[1] == pytest.approx(1000.0)
    assert lin.at(2.0) == (100.0, 0.0)
    exp = Ramp(100.0, start=0.0, duration=0.2, kind="exponential")
    assert exp.at(0.2)[0] == pytest.approx(100.0 * (1 - np.exp(-1.0)))


def test_circle_move_stays_on_its_circle_with_consistent_derivatives():
    center = np.array([0.05, 0.0, 0.0])
    move = Move(center, start=0.0, duration=2.0, kind="circle", accel_fraction=0.2, normal=np.array([0, 0, 1.0]))
    ts = np.linspace(0.0, 2.0, 4001)
    xs = np.array([move.at(t)[0] for t in ts])
    vs = np.array([move.at(t)[1] for t in ts])
    assert np.allclose(np.linalg.norm(xs - center, axis=1), 0.05, atol=1e-15)
    assert np.allclose(xs[-1], 0.0, atol=1e-15)  # one full turn back to the start
    assert np.max(np.abs(np.gradient(xs, ts, axis=0)[1:-1] - vs[1:-1])) < 1e-4
    acc_fd = np.gradient(vs, ts, axis=0)
    acc = np.array([move.at(t)[2] for t in ts])
    smooth = (np.abs(ts - 0.4) > 2e-3) & (np.abs(ts - 1.6) > 2e-3) & (ts > 0) & (ts < 2)  # angle-acceleration jumps
    assert np.max(np.abs(acc_fd - acc)[smooth]) < 5e-3


def test_exponential_move_follows_the_exponential_force_ramp():
    """Case 1's position-based push: the displacement rises like its force set-point, 1 − e^(−t/T)."""
    move = Move(np.array([0.04, 0.0, -0.04]), start=1.0, duration=0.2, kind="exponential")
    ramp = Ramp(100.0, start=1.0, duration=0.2, kind="exponential")
    for t in (0.5, 1.0, 1.1, 1.7, 5.0):
        x, v, a = move.at(t)
        F, dF = ramp.at(t)
        assert x[0] == pytest.approx(0.04 * F / 100.0, abs=1e-15) and x[2] == pytest.approx(-x[0])
        assert v[0] == pytest.approx(0.04 * dF / 100.0, abs=1e-15)
    ts = np.linspace(1.0, 2.0, 2001)
    xs = np.array([move.at(t)[0][0] for t in ts])
    vs = np.array([move.at(t)[1][0] for t in ts])
    accs = np.array([move.at(t)[2][0] for t in ts])
    assert np.max(np.abs(np.gradient(xs, ts)[1:-1] - vs[1:-1])) < 1e-5
    assert np.max(np.abs(np.gradient(vs, ts)[1:-1] - accs[1:-1])) < 1e-3


@pytest.mark.parametrize("kind, n_corners", [("trapezoid", 4), ("triangle", 3), ("velocity_ramp", 2),
                                             ("constant_velocity", 2), ("circle", 4)])
def test_a_moves_corners_split_its_pieces_at_adjacent_floats(kind, n_corners):
    """``before`` is still on the piece before the corner, ``after`` (the next float) on the piece after:
    the acceleration there equals its value a little way inside each piece (piecewise constant)."""
    normal = np.array([0.0, 0.0, 1.0]) if kind == "circle" else None
    move = Move(np.array([0.3, -0.1, 0.0]), start=0.1 + 0.2, duration=0.7, kind=kind, accel_fraction=0.3,
                normal=normal)
    corners = move.corners()
    assert len(corners) == n_corners
    nominal = [0.3, 0.51, 0.79, 1.0] if kind in ("trapezoid", "circle") else \
        [0.3, 0.65, 1.0] if kind == "triangle" else [0.3, 1.0]
    for c, t_c in zip(corners, nominal, strict=True):
        assert c.after == np.nextafter(c.before, np.inf) and abs(c.before - t_c) <= 1e-15
        if kind != "circle":  # the circle's acceleration is not piecewise constant
            np.testing.assert_array_equal(move.at(c.before)[2], move.at(c.before - 1e-4)[2])
            np.testing.assert_array_equal(move.at(c.after)[2], move.at(c.after + 1e-4)[2])
    assert move.tau(corners[0].before) < 0.0 <= move.tau(corners[0].after)


def test_force_ramp_corners_and_overlapping_corners_merge():
    linear = Ramp(10.0, start=0.3, duration=0.2)
    (c0, c1) = linear.corners()
    assert linear.at(c0.before)[1] == 0.0 and linear.at(c0.after)[1] == pytest.approx(50.0)
    assert linear.at(c1.before)[1] == pytest.approx(50.0) and linear.at(c1.after)[1] == 0.0
    assert len(Ramp(10.0, start=0.3, kind="step").corners()) == 1
    # case 1's push: the ramp's end and the triangle's peak meet at 0.5 s: one corner
    ramp = Move(np.array([0.1, 0.0, 0.0]), 0.0, 0.5, "velocity_ramp")
    tri = Move(np.array([0.0, 0.0, -0.1]), 0.0, 1.0, "triangle")
    corners = Reference(np.zeros(3), (ramp, tri)).corners()
    assert len(corners) == 3 and abs(corners[1].before - 0.5) <= 1e-15


def test_positions_are_at_elementwise_over_times():
    """Reference.positions(ts) gives at(t)'s position bit for bit at every time, every profile and a circle."""
    moves = tuple(Move(np.array([0.01 * (i + 1), -0.02, 0.003]), 0.1 * i, 0.3, kind)
                  for i, kind in enumerate(("trapezoid", "triangle", "velocity_ramp", "constant_velocity", "step",
                                            "exponential")))
    circle = Move(np.array([0.0, 0.05, 0.0]), 0.2, 0.5, "circle", normal=np.array([0.0, 0.0, 1.0]), turns=1.5)
    ts = np.linspace(-0.1, 1.2, 263)
    for ref in (Reference(np.array([0.4, 0.1, -0.2]), moves), Reference(np.array([0.4, 0.1, -0.2]), (circle,)),
                Reference(np.array([0.4, 0.1, -0.2]))):
        want = np.array([ref.at(t)[0] for t in ts])
        assert np.array_equal(ref.positions(ts), want)


@pytest.mark.parametrize("kind", ["trapezoid", "triangle", "velocity_ramp", "constant_velocity", "step",
                                  "exponential"])
def test_compiled_move_rows_are_each_moves_rows(kind):
    """move_rows (the compiled time parts' σ, σ'/T, σ''/T² per move) times Δ is Move.rows at every time, across
    the corners and outside the move."""
    moves = (Move(np.array([0.3, -0.1, 0.2]), 0.2, 0.5, kind, 0.2), Move(np.array([1.0, 0.0, 0.0]), 0.0, 0.3))
    table = move_table(moves)
    w = np.zeros(6)
    for t in np.linspace(-0.1, 1.0, 57):
        move_rows(t, table, w)
        for k, m in enumerate(moves):
            assert np.array_equal(np.multiply.outer(w[3 * k:3 * k + 3], m.delta), m.rows(t))


def test_compiled_ramp_rows_are_ramp_at():
    """ramp_rows gives each ramp's (F_d, Ḟ_d) of Ramp.at, for every kind, before, during and after its rise."""
    ramps = [Ramp(100.0, 0.2, 0.3, "linear", 5.0), Ramp(-40.0, 0.1, 0.05, "exponential"), Ramp(7.0, 0.4, kind="step")]
    table = ramp_table(ramps)
    w = np.zeros(6)
    for t in np.linspace(0.0, 1.0, 41):
        ramp_rows(t, table, w)
        assert [tuple(w[2 * j:2 * j + 2]) for j in range(3)] == [r.at(t) for r in ramps]
    closed_form = (5.0 + 95.0 * 0.15 / 0.3, 95.0 / 0.3)  # [N, N/s] halfway up the linear ramp
    assert Ramp(100.0, 0.2, 0.3, "linear", 5.0).at(0.35) == pytest.approx(closed_form, rel=1e-14)


def test_elementwise_values_are_the_pointwise_ones():
    """Ramp.values and Move.displacements (compiled loops over times) are Ramp.at's and Move.rows' first rows."""
    ts = np.linspace(-0.2, 1.2, 71)
    for kind in ("linear", "exponential", "step"):
        ramp = Ramp(30.0, 0.1, 0.4, kind, -2.0)
        assert np.array_equal(ramp.values(ts), [ramp.at(t)[0] for t in ts])
    for kind in ("trapezoid", "triangle", "velocity_ramp", "constant_velocity", "step", "exponential"):
        move = Move(np.array([0.2, -0.3, 0.1]), 0.1, 0.6, kind, 0.25)
        assert np.array_equal(move.displacements(ts), [move.rows(t)[0] for t in ts])
