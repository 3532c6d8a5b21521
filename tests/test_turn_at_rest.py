"""A 2-D ``turn`` located at a slip within a few stick bands of rest, in the band or slowing, is decided at rest, like a
``stop``; one whose slip grows refreshes its direction."""

from types import SimpleNamespace

import numpy as np
import pytest

from contactdyn import simulate
from contactdyn.hybrid import transitions
from contactdyn.hybrid.transitions import TURN_AT_REST, Transitions, _After
from contactdyn.model.contact import ContactMode

BAND = 1e-9  #: [m/s] the stick band v_ε


def _turn(slip: np.ndarray, monkeypatch, rate: np.ndarray | None = None):
    """(modes, after, settle) after a turn event of a sliding contact whose slip velocity is ``slip`` [m/s] and its
    rate ``rate`` [m/s²] (slowing, −slip / 1 ms, unless given)."""
    system = SimpleNamespace(scene=None, slip_band=BAND, contacts=[SimpleNamespace(name="pencil")], nQ=1)
    monkeypatch.setattr(transitions, "_kinematics_at", lambda system, c, x: None)
    monkeypatch.setattr(transitions, "slip_acceleration",
                        lambda system, c, kin, qdd: -slip / 1e-3 if rate is None else rate)

    def runner(modes, phase):  # the mode's call, as the run's runner gives it: its evaluation at (t, x)
        return SimpleNamespace(evaluation=lambda t, x: SimpleNamespace(slip={"pencil": slip}, xdot=np.zeros(2)))

    run = Transitions(system, None, {}, [], runner=runner)  # the handler alone: handle() logs
    modes = [ContactMode(touching=True, stuck=False, slip=(1.0, 0.0))]
    after = _After()
    event = SimpleNamespace(kind="turn", contact="pencil")
    _, _, settle = run._on_turn(0.0, np.zeros(2), modes, None, event, after)
    return modes, after, settle


@pytest.mark.parametrize("factor", [0.5, 4.1, 0.999 * TURN_AT_REST])
def test_a_turn_near_rest_is_a_stop(factor, monkeypatch):
    slip = factor * BAND * np.array([0.6, 0.8])
    modes, after, settle = _turn(slip, monkeypatch)
    assert settle and after.rest == {0}
    assert modes[0].slip == (1.0, 0.0)  # the reference is left to the decision at rest


def test_a_turn_in_the_band_is_a_stop_however_its_slip_moves(monkeypatch):
    slip = 0.5 * BAND * np.array([0.6, 0.8])
    _, after, settle = _turn(slip, monkeypatch, rate=slip / 1e-3)
    assert settle and after.rest == {0}


def test_a_turn_near_rest_of_a_growing_slip_refreshes_its_direction(monkeypatch):
    """A slip at 2 v_ε whose rate is along it (leaving rest, not coming to it) turns: r is its own."""
    modes, after, settle = _turn(2.0 * BAND * np.array([0.6, 0.8]), monkeypatch, rate=np.array([3e-5, 4e-5]))
    assert not settle and not after.rest
    assert modes[0].slip == pytest.approx((0.6, 0.8), abs=1e-15)
    assert not modes[0].from_rest


def test_a_turn_of_a_real_slide_refreshes_its_direction(monkeypatch):
    modes, after, settle = _turn(0.05 * np.array([0.6, 0.8]), monkeypatch)  # [m/s]
    assert not settle and not after.rest
    assert modes[0].slip == pytest.approx((0.6, 0.8), abs=1e-15)


UR5 = "sims/case2_writer_ur5.toml"
#: every UR5 joint with 3 N·m of dry friction: more than the writer's controller overcomes for long
DRY_UR5 = {f"robot.joint.{j}.friction": 3.0 for j in ("shoulder_pan_joint", "shoulder_lift_joint", "elbow_joint",
                                                       "wrist_1_joint", "wrist_2_joint", "wrist_3_joint")}


def test_a_launch_that_turns_near_rest_while_its_slip_grows_runs_on():
    """At t = 1.00494 s the shoulder pan joint breaks away with every other joint stuck, and the pencil (F_n ≈ 0: the
    cone a point) slides from rest along −F_f of its stick trial, (−0.96, −0.30): a split of redundant holds, square
    to the one direction the pan moves the tip in, (−0.30, 0.96), where its slip grows. Its turn at |v_t| = 2 v_ε is
    not a slide coming to rest: decided at rest it gave the same direction again, and the turn fired again (an event
    storm at t = 1.00497 s)."""
    result = simulate(UR5, {**DRY_UR5, "duration": 1.005})
    turns = [e for e in result.events if e["kind"] == "turn"]
    assert len(turns) == 1 and turns[0]["t"] == pytest.approx(1.004969, abs=1e-6)
    assert result.meta["check_warnings"] == []


def test_a_launch_off_the_only_way_the_tip_can_move_settles_along_it():
    """At t = 1.62745 s the elbow breaks away with the pencil at its cone's edge, every other joint stuck: the pencil
    slides from rest along −F_f of a redundant stick trial, 7° off the one direction the elbow moves the tip in. From
    there the launch's Newton converges only linearly (the load just past the cone: φ ~ δ³) and gave up after its 4
    updates, the friction along r, not against the slip, until the slip left the band; LSODA then crawled at 6 ns
    steps to the step budget (stopped at 1.628 s). The last trial along a_t settles it at once."""
    result = simulate(UR5, {**DRY_UR5, "duration": 1.63})
    assert result.stats["steps"] < 1000  # (the whole 4.5 s run takes ~800)
    assert result.meta["check_warnings"] == []
