"""Coulomb's cone at every instant where modes are decided (issue 27).

A stuck contact whose holding force leaves the cone |F_f| ≤ μ_s F_n at an instant where the
law changes (a phase start, a corner of a set-point, another contact's touch, a joint
limit's impact) must slip at that instant, recorded as a ``slip`` event there, and slide
with |F_f| = μ_k F_n from then on. Each scene is the point mass of ``test_friction`` (H = m I,
the tip is the mass, rigid ground z = 0: F_n = m g exactly) so every force is known in closed
form; the run's own physics checks (:mod:`contactdyn.output.physics_checks`) must stay quiet.
"""

from __future__ import annotations

import copy

import numpy as np
import pytest

from contactdyn import parse_scene, simulate
from contactdyn.output.physics_checks import violations

M, G = 2.0, 9.81
W = M * G  #: [N] the normal force on the ground
MU_S, MU_K = 0.5, 0.4


def ground(duration: float, phases: list[dict], controller: dict, dims: int = 1, **contacts) -> dict:
    """The point mass on the ground with friction along x (1-D) or in x-y (2-D)."""
    return {
        "name": "cone_instants",
        "duration": duration,
        "solver": {"rtol": 1e-10, "atol": 1e-12, "output_rate": 1000.0},
        "robot": {"urdf": "point_mass_xz" if dims == 1 else "point_mass_xyz", "q0": [0.0] * (dims + 1)},
        "contact": {"ground": {
            "point": [0.0, 0.0, 0.0], "normal": {"direction": [0.0, 0.0, 1.0]},
            "tangent": {"model": "friction", "mu_s": MU_S, "mu_k": MU_K,
                        "directions": [[1.0, 0.0, 0.0]] if dims == 1 else [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]},
        }, **contacts},
        "controller": controller,
        "phase": phases,
    }


def run(doc: dict):
    result = simulate(parse_scene(copy.deepcopy(doc)))
    assert violations(result.meta["checks"]) == []
    return result


def slips(result, name: str = "ground") -> list[float]:
    return [e["t"] for e in result.events if e["kind"] == "slip" and e["name"] == name]


def assert_slides_from(result, t_switch: float, sign: float) -> None:
    """Stuck with x = 0 before t_switch [s]; from t_switch on, sliding along ``sign`` with F_f = −μ_k W."""
    t, stuck = result.t, result["contact.ground.stuck"]
    F_f = result["contact.ground.F_f"][:, 0]
    after = t >= t_switch
    assert np.all(stuck[~after] == 1) and np.all(stuck[after] == 0)
    assert np.max(np.abs(result["q"][~after, 0])) < 1e-12
    assert F_f[after] == pytest.approx(-sign * MU_K * W, rel=1e-10)
    assert np.all(np.abs(F_f[~after]) <= MU_S * W)


@pytest.mark.parametrize("dims", [1, 2])
def test_a_phase_start_whose_push_leaves_the_cone_slips_there(dims):
    """A push of 1.5 μ_s W from a timed phase start: the stick breaks at that instant (today's bug: it stayed
    stuck with |F_f| = 1.5 μ_s W for ever, no event)."""
    push = 1.5 * MU_S * W
    doc = ground(0.6, [{"name": "rest", "until": 0.25}, {"name": "push", "controller": {"force": [push, 0, 0]}}],
                 {"kind": "task_force"}, dims)
    r = run(doc)
    assert slips(r) == [0.25]
    assert_slides_from(r, 0.25, 1.0)


def test_a_phase_start_inside_the_cone_keeps_the_stick():
    """The same switch to a push of 0.9 μ_s W: still stuck, F_f = −push exactly, no slip."""
    push = 0.9 * MU_S * W
    doc = ground(0.4, [{"name": "rest", "until": 0.2}, {"name": "push", "controller": {"force": [push, 0, 0]}}],
                 {"kind": "task_force"})
    r = run(doc)
    assert slips(r) == []
    after = r.t >= 0.2
    assert np.all(r["contact.ground.stuck"] == 1)
    assert r["contact.ground.F_f"][after, 0] == pytest.approx(-push, rel=1e-12)


def test_a_corner_of_the_set_point_that_leaves_the_cone_slips_there():
    """A joint PD whose reference steps by 0.2 m at t = 0.3 s (a corner: the set-point jumps): the PD's push
    kp·0.2 = 2 μ_s W jumps out of the cone there."""
    kp = 2 * MU_S * W / 0.2
    moves = [{"kind": "step", "delta": [0.2, 0.0], "start": 0.3, "duration": 0.1}]
    doc = ground(0.5, [{"name": "hold", "reference": {"space": "joint", "moves": moves}}],
                 {"kind": "joint_pd", "kp": [kp, 0.0], "kd": [0.0, 0.0]})
    r = run(doc)
    assert slips(r) == [pytest.approx(0.3, abs=1e-12)]
    assert_slides_from(r, slips(r)[0], 1.0)


def test_another_contacts_touch_breaks_the_stick_at_that_instant():
    """A cart at 0.5 m/s (servo-driven, 100 kg) reaches the stuck mass from −x at t = 0.1 s: the touch's impact
    sets the mass moving with the cart, the ground's stick cannot hold it, and it slips at the touch."""
    wall = {"body": "cart", "point": [-0.05, 0.0, 0.0], "normal": {"direction": [1.0, 0.0, 0.0]}}
    doc = ground(0.3, [{"name": "rest"}], {"kind": "task_force"}, wall=wall)
    doc["body"] = {"cart": {"mass": 100.0, "axis": [1, 0, 0], "position0": 0.0, "velocity0": 0.5,
                            "servo": {"velocity": 0.5, "gain": 1e4}}}
    r = run(doc)
    touch = [e["t"] for e in r.events if e["kind"] == "touch" and e["name"] == "wall"]
    assert touch == [pytest.approx(0.1, rel=1e-9)]
    assert slips(r) == touch or r.impacts[0]["jammed"] is False
    after = r.t > touch[0]
    assert np.all(r["contact.ground.stuck"][after] == 0)
    assert np.all(np.abs(r["contact.ground.F_f"][after, 0]) <= MU_S * W * (1 + 1e-12))


def test_the_ur10_slide_then_lift_slips_at_the_lift_start():
    """Issue 27's scene as reported: the lift's start pulls the stuck tip out of the cone; it slips there,
    then slides at μ F_n until it separates."""
    from pathlib import Path

    r = simulate(Path(__file__).parent / "scenes" / "ur10_slide_lift.toml")
    assert violations(r.meta["checks"]) == []
    lift = next(e["t"] for e in r.events if e["kind"] == "phase" and e["name"] == "lift")
    assert lift in slips(r, "table")
    after = (r.t >= lift) & (r["contact.table.touching"] == 1)
    assert after.sum() > 5 and np.all(r["contact.table.stuck"][after] == 0)
    F_f, F_n = np.abs(r["contact.table.F_f"][after, 0]), r["contact.table.F_n"][after]
    assert F_f == pytest.approx(0.3 * F_n, rel=1e-9, abs=1e-9)


def _slider_pair_urdf(path) -> str:
    """Two 1 kg carriages on x slides in series (x1, then x2 with lower limit −0.05 m), a 2 kg tip on a z slide."""
    def link(name: str, mass: float) -> str:
        return (f'<link name="{name}"><inertial><mass value="{mass}"/>'
                '<inertia ixx="1e-3" ixy="0" ixz="0" iyy="1e-3" iyz="0" izz="1e-3"/></inertial></link>')

    def joint(name: str, parent: str, child: str, axis: str, lower: float) -> str:
        return (f'<joint name="{name}" type="prismatic"><parent link="{parent}"/><child link="{child}"/>'
                f'<axis xyz="{axis}"/><limit lower="{lower}" upper="1.0" effort="1e4" velocity="100"/></joint>')

    path.write_text('<?xml version="1.0"?><robot name="slider_pair"><link name="base"/>'
                    + link("a", 1.0) + link("b", 1.0) + link("body", M)
                    + joint("x1", "base", "a", "1 0 0", -1.0) + joint("x2", "a", "b", "1 0 0", -0.05)
                    + joint("z", "b", "body", "0 0 1", -1.0)
                    + '<joint name="tip_joint" type="fixed"><parent link="body"/><child link="tip"/></joint>'
                    + '<link name="tip"/></robot>')
    return str(path)


def test_a_joint_limit_impact_that_loads_the_stick_past_the_cone_slips_it(tmp_path):
    """Carriage a is pushed with 1.5 μ_s W along +x; the tip is stuck, so x2 = −x1 and the free slide x2 passes
    nothing to the tip (F_f = 0) until x2 reaches its lower limit at x1 = 0.05 m. From that impact on, the
    push reaches the ground through the locked slide: more than the cone holds, so the stick breaks there. The
    impact itself could not be held by friction either (today's bug: the stick took a friction impulse of
    1.2 N·s with no normal impulse and stopped every body)."""
    push = 1.5 * MU_S * W  # [N] a PD on x1 towards 10 m with kp = push / 10 m: push − kp x1 ≈ push
    reference = {"space": "joint", "start": [10.0, 0.0, 0.0]}
    doc = ground(0.5, [{"name": "push", "reference": reference}],
                 {"kind": "joint_pd", "kp": [push / 10.0, 0.0, 0.0], "kd": [0.0, 0.0, 0.0]})
    doc["robot"] = {"urdf": _slider_pair_urdf(tmp_path / "sliders.urdf"), "q0": [0.0, 0.0, 0.0]}
    r = run(doc)
    limit = [e["t"] for e in r.events if e["kind"] == "limit"]
    assert len(limit) == 1
    before = r.t < limit[0]
    assert np.all(r["contact.ground.stuck"][before] == 1)
    assert np.max(np.abs(r["contact.ground.F_f"][before, 0])) < 1e-9  # the free slide passes nothing
    assert limit[0] in slips(r)
    after = r.t > limit[0]
    assert np.all(r["contact.ground.stuck"][after] == 0)
    # the impact: no normal impulse, so no friction impulse (the cone at impulse level); a moved at v, b and the
    # tip at rest; after it all three move together: momentum 1 kg · v = (1 + 1 + 2) kg · v⁺
    (imp,) = r.impacts
    v = imp["v_before"][0]
    assert imp["friction_impulse"] == [0.0] and imp["normal_impulse"] == 0.0 and not imp["jammed"]
    assert imp["v_after"][0] == pytest.approx(v / 4.0, rel=1e-12) and imp["v_after"][1] == pytest.approx(0.0, abs=1e-12)
    assert imp["energy_loss"] == pytest.approx(0.5 * v**2 - 0.5 * 4.0 * (v / 4.0) ** 2, rel=1e-12)
