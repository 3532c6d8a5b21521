"""The impact is unilateral (:mod:`contactdyn.model.impact`): a touching contact holds only while its normal impulse
pushes. A free plank, 0.6 m × 0.1 m, 1 kg, rests on four frictionless supports at x = ±0.1 m, y = ±0.05 m (its
mid-plane); the tool (a 2 kg point mass) strikes it at x = 0.3 m, beyond the supports. Held as equalities, the far
pair would pull the plank down; let go, the plank turns about the near pair. Closed form (moments about the near
pair's line, the tool's impulse P along the plank's normal): ω = 0.2 P / I_P, the tool after at −0.2 ω, so
P = m_t v / (1 + 0.04 m_t / I_P), I_P = I_c + m 0.1²; the near pair carries R = 0.1 m ω + P, the far pair lifts at
0.2 ω. Struck between the supports, all four hold.
"""

from __future__ import annotations

import numpy as np
import pytest

from contactdyn import parse_scene, simulate
from contactdyn.model.impact import impact
from contactdyn.model.system import System

M, M_TOOL, LENGTH, WIDTH, THICK = 1.0, 2.0, 0.6, 0.1, 0.002  #: [kg], [kg], [m], [m], [m]
I_C = M * (LENGTH**2 + THICK**2) / 12  #: [kg·m²] about its y axis through its centre
I_P = I_C + M * 0.1**2  #: [kg·m²] about the near supports' line
PLANK = f"""<?xml version="1.0"?>
<robot name="plank"><link name="plank"><inertial><mass value="{M}"/>
  <inertia ixx="{M * (WIDTH**2 + THICK**2) / 12!r}" iyy="{I_C!r}" izz="{M * (LENGTH**2 + WIDTH**2) / 12!r}"
           ixy="0" ixz="0" iyz="0"/></inertial></link></robot>
"""


def _support(x: float, y: float) -> dict:
    return {"frame": "plank", "body_frame": "plank", "frame_point": [x, y, 0.0], "body": "ground",
            "point": [0.0, 0.0, 0.0], "normal": {"direction": [0.0, 0.0, 1.0]}, "tangent": {"model": "free"}}


def _scene(tmp_path, strike_x: float, duration: float = 0.05, above: float = 0.0, g: float = 0.0):
    (tmp_path / "plank.urdf").write_text(PLANK)
    contacts = {f"s{k}": _support(x, y) for k, (x, y) in enumerate([(0.1, 0.05), (0.1, -0.05), (-0.1, 0.05),
                                                                     (-0.1, -0.05)])}
    contacts["strike"] = {"frame": "tip", "body": "plank", "surface_frame": "plank", "point": [strike_x, 0.0, 0.0],
                          "normal": {"direction": [0.0, 0.0, 1.0]}, "tangent": {"model": "free"}}
    doc = {"name": "plank", "duration": duration,
           "solver": {"method": "DOP853C", "rtol": 1e-10, "atol": 1e-12, "record_energy": True},
           "robot": {"urdf": "point_mass_xz", "tip": "tip", "q0": [strike_x, above], "v0": [0.0, -1.0],
                     "gravity": [0.0, 0.0, -g]},
           "body": {"plank": {"urdf": "plank.urdf", "free": True, "position0": [0.0] * 6}},
           "contact": contacts, "controller": {"kind": "joint_pd", "kp": 0.0, "kd": 0.0},
           "phase": [{"name": "strike"}]}
    return parse_scene(doc, None, tmp_path / "plank.toml")


def _struck(tmp_path, strike_x: float):
    """The impact map at the strike: every contact touching, the tool coming down at 1 m/s."""
    system = System(_scene(tmp_path, strike_x))
    x, modes = system.initial_state()
    modes = [m.with_(touching=True) for m in modes]
    x_after, imp = impact(system, 0.0, x, modes, next(c for c in system.contacts if c.name == "strike"))
    return system, x_after, imp


def test_struck_beyond_the_supports_the_far_pair_lets_go_and_the_plank_turns_about_the_near_pair(tmp_path):
    system, x, imp = _struck(tmp_path, 0.3)
    assert sorted(imp.separated) == ["s2", "s3"]
    v = 1.0
    P = M_TOOL * v / (1 + 0.04 * M_TOOL / I_P)
    omega = 0.2 * P / I_P
    assert imp.normal_impulse == pytest.approx(P, rel=1e-9)
    near = [imp.row_impulses[(name, "n", 0)] for name in ("s0", "s1")]
    np.testing.assert_allclose(near, 0.5 * (0.1 * M * omega + P), rtol=1e-9)  # R, split between the pair
    nQ, nv = system.nQ, system.nv
    tool_vz = x[nQ + 1]
    assert tool_vz == pytest.approx(-0.2 * omega, rel=1e-9)
    pitch_rate = x[nQ + nv + 4]  # (the plank's six: x, y, z, yaw, pitch, roll)
    assert abs(pitch_rate) == pytest.approx(omega, rel=1e-9)
    assert x[nQ + nv + 2] == pytest.approx(0.1 * omega, rel=1e-9)  # its centre rises with the near line fixed


def test_struck_between_the_supports_all_four_hold_with_pushing_impulses(tmp_path):
    _, _, imp = _struck(tmp_path, 0.05)
    assert imp.separated == ()
    assert min(imp.row_impulses[(f"s{k}", "n", 0)] for k in range(4)) > 0.0


def test_a_run_logs_the_far_pair_s_separation_at_the_strike_and_its_energy_closes(tmp_path):
    r = simulate(_scene(tmp_path, 0.3, duration=0.05, above=1e-3, g=9.81))  # (1 mm above: it strikes at ~1 ms; its
    # weight keeps the plank on its supports until then)
    (hit,) = [i for i in r.impacts if i["contact"] == "strike"][:1]
    separations = {e["name"] for e in r.events if e["kind"] == "separate" and e["t"] == hit["t"]}
    assert separations == {"s2", "s3"}
    assert not r["contact.s2.touching"][-1] and r["contact.s0.touching"][-1]
    residual = r.meta["checks"]["energy_residual"]
    assert residual["value"] <= residual["tol"], residual
