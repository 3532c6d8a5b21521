"""Every sliding contact of an impact takes its friction impulse (:mod:`contactdyn.model.impact`): a box landing flat
while it slides.

``sims/drop_box.toml``'s box (1 kg, 0.1 × 0.2 × 0.3 m, its bottom corners at x = ±a, y = ±b, h = 0.15 m below its
centre) on a table with Coulomb friction μ, released 0.1 m above it moving sideways at u along d (unit, in the
table's plane): it lands at v = √(2 g 0.1) on its four corners at once, one impact. Closed form while it keeps
sliding (μ v < u): the normal impulses sum to P = m v, the friction impulses to −μ P d, so u⁺ = u − μ v along d and
nothing turns (every corner keeps v_n⁺ = 0); their moments about the centre balance, so the corner at (s_x a, s_y b)
takes P/4 (1 + s_x μ h d_x / a + s_y μ h d_y / b) (the four rows are one too many: this is the split that is
linear over the corners, the one the solve gives by symmetry), and ½ m (u² + v²) − ½ m (u − μ v)² is lost. Before,
only the located corner took friction (u⁺ = u − μ P/4 or less).
If μ v ≥ u the slide stops in the impact: everything at rest, all four stuck, the friction impulses summing to −m u
d, each inside its own cone. Fast and with high friction the tall box trips over its front edge instead: the
angular momentum about that edge is kept.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from contactdyn import load_scene, simulate

SIMS = Path(__file__).resolve().parent.parent / "sims"
M, A, B, H, G = 1.0, 0.05, 0.1, 0.15, 9.81  #: [kg], corner half-spans [m], depth below the centre [m], [m/s²]
V = math.sqrt(2 * G * 0.1)  #: [m/s] landing speed after the 0.1 m fall
CORNERS = {"c1": (1, 1), "c2": (-1, 1), "c3": (-1, -1), "c4": (1, -1)}  #: (s_x, s_y) of sims/drop_box.toml's


def _landing(mu: float, u: float, d: tuple[float, float]):
    """The box's run landing with friction μ while sliding at u [m/s] along d: (the result, its impact entries by
    contact, the located contact's entry)."""
    overrides = {f"contact.c{k}.tangent": {"model": "friction", "mu": mu,
                                           "directions": [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]} for k in range(1, 5)}
    overrides["body.box.velocity0"] = [u * d[0], u * d[1], 0.0, 0.0, 0.0, 0.0]
    scene = load_scene(SIMS / "drop_box.toml", overrides)
    r = simulate(scene)
    hits = {i["contact"]: i for i in r.impacts}
    assert sorted(hits) == sorted(CORNERS) and len({i["t"] for i in r.impacts}) == 1  # one impact, four corners
    (located,) = [i for i in r.impacts if "with" not in i]  # its entry carries the loss
    return r, hits, located


@pytest.mark.parametrize("d", [(1.0, 0.0), (0.6, 0.8)])
def test_a_box_landing_while_it_slides_loses_mu_v_of_its_speed_at_once(d):
    mu, u = 0.2, 1.0
    r, hits, hit = _landing(mu, u, d)
    v_after = np.array(hit["v_after"])
    nQ = 2  # (the point-mass tool's two coordinates first)
    np.testing.assert_allclose(v_after[nQ:nQ + 2], (u - mu * V) * np.array(d), rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(v_after[nQ + 2:], 0.0, atol=1e-12)  # it lands flat and nothing turns
    P = M * V
    for name, (sx, sy) in CORNERS.items():
        P_n = P / 4 * (1 + sx * mu * H * d[0] / A + sy * mu * H * d[1] / B)
        assert hits[name]["normal_impulse"] == pytest.approx(P_n, rel=1e-9), name
        np.testing.assert_allclose(hits[name]["friction_impulse"], -mu * P_n * np.array(d), rtol=1e-9, atol=1e-15)
        assert not hits[name]["jammed"]
    assert hit["energy_loss"] == pytest.approx(0.5 * M * (u**2 + V**2 - (u - mu * V) ** 2), rel=1e-9)
    assert all(r[f"contact.{name}.touching"][-1] for name in CORNERS)
    t_hit = hit["t"]  # then it slides on, braked at μ g, until the run ends (before it stops)
    speed = math.hypot(r["body.box.x.v"][-1], r["body.box.y.v"][-1])
    assert speed == pytest.approx(u - mu * V - mu * G * (r["t"][-1] - t_hit), rel=1e-7)


def test_a_slow_slide_stops_in_the_impact_and_the_box_stays_stuck():
    mu, u, d = 0.2, 0.1, (1.0, 0.0)  # μ v = 0.28 m/s > u
    r, hits, hit = _landing(mu, u, d)
    np.testing.assert_allclose(hit["v_after"], 0.0, atol=1e-12)
    assert hit["energy_loss"] == pytest.approx(0.5 * M * (u**2 + V**2), rel=1e-9)
    friction = np.sum([hits[name]["friction_impulse"] for name in CORNERS], axis=0)
    np.testing.assert_allclose(friction, -M * u * np.array(d), rtol=1e-9, atol=1e-12)
    for name in CORNERS:
        assert np.linalg.norm(hits[name]["friction_impulse"]) <= mu * hits[name]["normal_impulse"] * (1 + 1e-9)
        assert r[f"contact.{name}.touching"][-1]
    np.testing.assert_allclose([r["body.box.x.v"][-1], r["body.box.y.v"][-1]], 0.0, atol=1e-9)
    assert not any(e["kind"] in {"slip", "separate"} for e in r.events)


def test_a_fast_slide_with_high_friction_trips_the_box_over_its_front_edge():
    """μ = 0.9, 1 m/s along x: the front corners jam (their impulse inside the cone), the rear ones let go, and the
    box turns about its front edge. The impulses act on that edge, so the angular momentum about it is kept:
    ω = m (h u − a v) / I_edge, I_edge = I_yy + m (a² + h²), the centre moving at ω × r (r from the edge to the centre,
    (−a, 0, h)). Before every corner took its friction impulse this run ended in more than 10,000 events."""
    mu, u = 0.9, 1.0
    r, hits, hit = _landing(mu, u, (1.0, 0.0))
    I_yy = M * (0.1**2 + 0.3**2) / 12  # [kg·m²] (sims/free_box.urdf: 0.1 × 0.2 × 0.3 m)
    omega = M * (H * u - A * V) / (I_yy + M * (A**2 + H**2))
    nQ = 2
    np.testing.assert_allclose(hit["v_after"][nQ:], [omega * H, 0.0, omega * A, 0.0, omega, 0.0], rtol=0, atol=1e-9)
    assert {name for name, h in hits.items() if h["jammed"]} == {"c1", "c4"}  # the front pair, at x = +a
    assert {e["name"] for e in r.events if e["kind"] == "separate"} == {"c2", "c3"}
    for name in ("c1", "c4"):
        assert np.linalg.norm(hits[name]["friction_impulse"]) <= mu * hits[name]["normal_impulse"]
    residual = r.meta["checks"]["energy_residual"]
    assert residual["value"] <= residual["tol"], residual
