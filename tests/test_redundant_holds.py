"""Redundant holds split by their limits (contactdyn.model.pipeline.kkt.coulomb_split).

Stuck joints and a stuck contact that hold the same motion are statically indeterminate: their forces can change by a
split that moves nothing. The least-norm split is blind to the holds' limits; Coulomb's hold breaks only when no split
keeps every hold inside its limit. The scene: benchmarks/hard's stick-slip (B1's planar 2R, its tip dragged by a task
PD along x on a compliant surface, μ_s = 0.5) with 3 N·m of dry friction on both joints. From 0.574 s the tip and both
joints are stuck: three rows (the tip's x, q1, q2) on the arm's two joints, one split n ∝ (1, −J_x1, −J_x2) (tip force
[N], joint torques [N·m]: J_xᵀ F_f + τ_f is the same for every split). The least-norm split loads the elbow with
~12 N·m, four times its 3 N·m: it reversed at once, where the split nearest it that keeps every hold inside holds the
arm until the tip's force reaches its cone, 0.16 s later.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from contactdyn import simulate
from contactdyn.model.pipeline.kkt import hold_interval
from contactdyn.numerics.linalg import null_basis

SCENE = Path(__file__).resolve().parent.parent / "benchmarks" / "hard" / "stickslip.toml"
L1 = L2 = 0.3  #: [m] the arm's links (urdf planar2r_b1)
MU_S, TAU_S = 0.5, 3.0  #: the tip's static coefficient; each joint's static friction [N·m]


@pytest.fixture(scope="module")
def run():
    return simulate(str(SCENE), {"robot.joint.q1.friction": TAU_S, "robot.joint.q2.friction": TAU_S,
                                 "duration": 0.8})


def _held(r) -> np.ndarray:
    """The output samples where the tip and both joints are stuck."""
    return (r["contact.tip.stuck"] > 0.5) & np.all(r["joint_stuck"] > 0.5, axis=1)


def _split(q: np.ndarray) -> np.ndarray:
    """The unit split that moves nothing at the arm's pose q [rad]: (tip force along x, τ_f1, τ_f2)."""
    q1, q12 = q[0], q[0] + q[1]
    n = np.array([1.0, L1 * math.sin(q1) + L2 * math.sin(q12), L2 * math.sin(q12)])  # (1, −J_x1, −J_x2)
    return n / np.linalg.norm(n)


def test_a_redundant_hold_keeps_every_force_inside_its_limit(run):
    held = _held(run)
    assert held.sum() > 100  # [samples at 1 kHz] the arm is held for 0.16 s
    assert 0 < run.stats["holds_split"] <= run.stats["singular_solves"]
    F_f, F_n = np.abs(run["contact.tip.F_f"][held, 0]), run["contact.tip.F_n"][held]
    assert np.all(F_f <= MU_S * F_n)
    assert np.all(np.abs(run["joint_friction"][held]) <= TAU_S)
    assert np.abs(run["v"][held]).max() < 1e-9  # [rad/s] held: at rest


def test_redundant_holds_inside_their_limits_keep_the_least_norm_split():
    """The pinch: two pads stuck on one part are redundant rows, solved by least squares at every call; the least-norm
    split (m g / 2 per pad) is inside both cones, so no call splits it."""
    r = simulate("pinch_hold", {"duration": 0.5})
    assert r.stats["singular_solves"] > 0 and r.stats["holds_split"] == 0


def test_the_least_norm_split_of_the_same_hold_is_outside_a_limit(run):
    """The split matters here: the least-norm forces of the same hold (the reported ones less their share along the
    split) load the elbow past 3 N·m, at every held sample."""
    held = np.flatnonzero(_held(run))
    for i in held[::10]:
        lam = np.array([run["contact.tip.F_f"][i, 0], *run["joint_friction"][i]])
        n = _split(run["q"][i])
        least_norm = lam - (lam @ n) * n
        assert abs(least_norm[2]) > 3.0 * TAU_S


def test_the_hold_breaks_where_no_split_is_left(run):
    """At the hold's last sample the forces are on two limits at once (the elbow's τ_s and the tip's cone): no split
    keeps both inside; and at each held sample the splits that do form an interval that shrinks to that point."""
    held = np.flatnonzero(_held(run))
    assert held[-1] < len(run["t"]) - 1 and not _held(run)[held[-1] + 1]
    widths = []
    for i in held:
        lam = np.array([run["contact.tip.F_f"][i, 0], *run["joint_friction"][i]])
        n = _split(run["q"][i])
        bounds = np.array([-np.inf, np.inf])
        hold_interval(MU_S, run["contact.tip.F_n"][i], 0.0, lam[0], 0.0, n[0], 0.0, bounds)
        for j in (1, 2):  # |τ_j + s n_j| ≤ τ_s
            ends = sorted(((TAU_S - lam[j]) / n[j], (-TAU_S - lam[j]) / n[j]))
            bounds = np.array([max(bounds[0], ends[0]), min(bounds[1], ends[1])])
        assert bounds[0] <= 1e-6 and bounds[1] >= -1e-6  # [N] the reported split (s = 0) is among them
        widths.append(bounds[1] - bounds[0])
    assert widths[-1] < 0.1 * widths[0]  # [N] the interval shrank as the drag grew
    assert abs(run["joint_friction"][held[-1], 1]) == pytest.approx(TAU_S, rel=1e-6)
    break_at = next(e["t"] for e in run.events if e["t"] > run["t"][held[-1]])
    assert run["t"][held[-1]] < break_at <= run["t"][held[-1]] + 1e-3  # [s] within the output's period


@pytest.mark.parametrize("seed", range(20))
def test_hold_interval_is_the_set_of_splits_inside_the_cone(seed):
    """hold_interval against sampling: ‖a + s b‖ ≤ μ (c + s d) for a 2-D tangential force along a line of splits."""
    rng = np.random.default_rng(seed)
    mu, c, d = rng.uniform(0.1, 1.0), rng.uniform(-5.0, 20.0), rng.normal()
    a, b = rng.normal(0.0, 5.0, 2), rng.normal(0.0, 1.0, 2)
    bounds = np.array([-np.inf, np.inf])
    hold_interval(mu, c, d, a[0], a[1], b[0], b[1], bounds)
    s = np.linspace(-200.0, 200.0, 400_001)
    inside = np.linalg.norm(a[None, :] + s[:, None] * b[None, :], axis=1) <= mu * (c + s * d)
    if not inside.any():
        assert bounds[0] > bounds[1] or bounds[1] < -200.0 or bounds[0] > 200.0
        return
    lo, hi = s[inside].min(), s[inside].max()
    assert bounds[0] == pytest.approx(lo, abs=2e-3) if lo > -200.0 else bounds[0] < -199.0
    assert bounds[1] == pytest.approx(hi, abs=2e-3) if hi < 200.0 else bounds[1] > 199.0


@pytest.mark.parametrize("seed", range(10))
def test_null_basis_spans_what_a_matrix_maps_to_zero(seed):
    """numerics.linalg.null_basis against the rank: n − rank orthonormal rows x with A x = 0 (A of random rank, up to
    7 × 7, or zero)."""
    rng = np.random.default_rng(seed)
    for _ in range(20):
        m, n = rng.integers(1, 8, size=2)
        k = rng.integers(0, min(m, n) + 1)
        A = rng.normal(size=(m, k)) @ rng.normal(size=(k, n)) if k else np.zeros((m, n))
        X = null_basis(A, 1e-10)
        assert X.shape == (n - np.linalg.matrix_rank(A), n)
        np.testing.assert_allclose(X @ X.T, np.eye(X.shape[0]), atol=1e-12)
        assert np.linalg.norm(A @ X.T) < 1e-9 * max(1.0, np.abs(A).max())


def test_holds_whose_splits_span_two_directions_are_split_by_their_limits():
    """The rigid writer (a planar 2R, its pencil bonded to a rigid paper) with 1.5 static and 0.5 kinetic N·m on both
    joints: the pencil's stick and both stuck joints are 3 holding rows beside the bond's on 2 joints, their splits two
    directions. The least-norm forces left the pencil's friction outside its cone at 0.998 s, and from 1.016 s q1's
    slide reversed 809 times, each reversal's least-norm hold past τ_s. Split along each direction in turn, the holds
    stay inside their limits (the reported forces, one such split, keep every stuck joint within τ_s and the stuck
    pencil inside its cone) and q1 reverses 3 times in all."""
    joints = ("q1", "q2")
    r = simulate("case2_writer_rigid", {**{f"robot.joint.{j}.friction_static": 1.5 for j in joints},
                                        **{f"robot.joint.{j}.friction_kinetic": 0.5 for j in joints}})
    assert r.stats["holds_split"] > 0
    assert len([e for e in r.events if e["kind"] == "joint_reverse"]) < 10  # (3: the slides' own, not a chatter)
    stuck = r["joint_stuck"] > 0.5
    assert stuck.any() and np.abs(r["joint_friction"][stuck]).max() <= 1.5
    held = r["contact.tip.stuck"] > 0.5
    cone = 0.4 * r["contact.tip.F_n"][held] * (1.0 + 1e-9)  # [N] μ_s F_n (its tests' slack)
    assert held.any() and np.all(np.abs(r["contact.tip.F_f"][held]).max(axis=1) <= cone)
