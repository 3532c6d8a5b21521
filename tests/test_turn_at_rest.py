"""A 2-D ``turn`` located at a slip within a few stick bands of rest is decided at rest, like a ``stop``."""

from types import SimpleNamespace

import numpy as np
import pytest

from contactdyn.hybrid.transitions import TURN_AT_REST, Transitions, _After
from contactdyn.model.contact import ContactMode

BAND = 1e-9  #: [m/s] the stick band v_ε


def _turn(slip: np.ndarray):
    """(modes, after, settle) after a turn event of a sliding contact whose slip velocity is ``slip`` [m/s]."""
    system = SimpleNamespace(scene=None, slip_band=BAND, contacts=[SimpleNamespace(name="pencil")])

    def runner(modes, phase):  # the mode's call, as the run's runner gives it: its evaluation at (t, x)
        return SimpleNamespace(evaluation=lambda t, x: SimpleNamespace(slip={"pencil": slip}))

    transitions = Transitions(system, None, {}, [], runner=runner)  # the handler alone: handle() logs
    modes = [ContactMode(touching=True, stuck=False, slip=(1.0, 0.0))]
    after = _After()
    event = SimpleNamespace(kind="turn", contact="pencil")
    _, _, settle = transitions._on_turn(0.0, np.zeros(2), modes, None, event, after)
    return modes, after, settle


@pytest.mark.parametrize("factor", [0.5, 4.1, 0.999 * TURN_AT_REST])
def test_a_turn_near_rest_is_a_stop(factor):
    slip = factor * BAND * np.array([0.6, 0.8])
    modes, after, settle = _turn(slip)
    assert settle and after.rest == {0}
    assert modes[0].slip == (1.0, 0.0)  # the reference is left to the decision at rest


def test_a_turn_of_a_real_slide_refreshes_its_direction():
    modes, after, settle = _turn(0.05 * np.array([0.6, 0.8]))  # [m/s]
    assert not settle and not after.rest
    assert modes[0].slip == pytest.approx((0.6, 0.8), abs=1e-15)
