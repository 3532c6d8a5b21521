"""Linearised contact loops (contactdyn.analysis.stability): closed forms, and growth rates against simulation."""

from __future__ import annotations

import numpy as np
import pytest

from contactdyn.analysis.stability import ContactLoop, contact_phase_scene, envelope_rate, modal_poles, simulated_growth
from contactdyn.scene.scene_file import parse_scene


def rigid_case3_b_a7(kp: float, kv: float) -> ContactLoop:
    scene = contact_phase_scene("case3_b_position", [1.0], {"phase.0.controller.kp": kp, "phase.0.controller.kv": kv,
                                                            "phase.0.controller.inertia": "model"})
    doc = scene.document
    drive = doc["robot"]["drive"]
    for key in ("c", "d", "twist_damping"):
        drive.pop(key, None)
    drive["kind"] = "dc_motor"
    return ContactLoop(parse_scene(doc, None, scene.file))


def test_a7_through_a_rigid_gear_has_exactly_the_poles_of_P():
    """A7 with the exact rigid model (link + reflected rotor) cancels everything but P: on the bonded
    model (b) surface the loop is η̈ = −K_p η − K_v η̇, poles −10 and −30 for (300, 40)."""
    lin = rigid_case3_b_a7(300.0, 40.0).linearize()
    np.testing.assert_allclose(np.sort(lin.poles.real), [-30.0, -10.0], rtol=1e-6)
    np.testing.assert_allclose(lin.poles.imag, 0.0, atol=1e-6)
    assert 0.2 - lin.x[1] == pytest.approx(1e-3, rel=1e-9)  # the tip at F_d / k = 1 mm deep


def test_a7_through_the_elastic_drive_reproduces_the_papers_linear_model_figure():
    """The README's pole for the former A7 defaults (K_p = 400, K_v = 40, the rigid model's H, no
    twist damping) on case 3's (b) surface, from an independent derivation: +7.21 ± 134.49i."""
    scene = contact_phase_scene("case3_b_position", [1.0], {"phase.0.controller.kp": 400.0,
                                                            "phase.0.controller.kv": 40.0,
                                                            "phase.0.controller.inertia": "model"})
    dom = ContactLoop(scene).linearize().dominant
    assert dom.real == pytest.approx(7.21, abs=0.005) and abs(dom.imag) == pytest.approx(134.49, abs=0.005)


def test_the_case3_scenes_sit_inside_their_stable_regions():
    """The scenes' own gains (no twist damping): every dominant pole in the left half-plane."""
    for name in ("case3_b_position", "case3_a_position", "case3_b_force", "case3_a_force"):
        assert ContactLoop(contact_phase_scene(name, [1.0])).linearize().dominant.real < -2.0, name


def growth_in_run(kp: float, kv: float, duration: float, t_fit: float, scene: str = "case3_b_position"
                  ) -> tuple[float, complex]:
    """Growth rate of the force error's dominant mode in a run of the press phase (from the surface, at
    rest, F_d ramping), fitted after t_fit (stability.simulated_growth: the run's own modes by matrix pencil)."""
    over = {"phase.0.controller.kp": kp, "phase.0.controller.kv": kv, "solver.rtol": 1e-9, "solver.atol": 1e-11,
            "solver.output_rate": 1000.0, "duration": duration}
    return simulated_growth(contact_phase_scene(scene, [1.0], over), t_fit)


def test_simulation_grows_at_the_unstable_side_of_the_boundary():
    """A7 on (b), link H, K_p = 1000: K_v = 100 lies beyond the boundary (+5.63 ± 134.1i); the run's
    force error grows at that rate (within 10 %) until the tip lifts off."""
    rate, dom = growth_in_run(1000.0, 100.0, 0.8, 0.45)
    assert dom.real > 0.0
    assert rate == pytest.approx(dom.real, rel=0.1)


def test_simulation_grows_at_the_rate_of_the_dominant_mode_where_a_second_one_is_close():
    """A7 on (a), link H, K_p = 1000, K_v = 100: two unstable modes, +3.07 ± 127.8i and +2.75 ± 158.8i (the
    tube's and the two-stage surface's); the envelope of the force error mixes them (−29 % with the
    former fit), the run's own mode at the dominant frequency grows at the dominant pole's rate."""
    rate, dom = growth_in_run(1000.0, 100.0, 1.2, 0.6, "case3_a_position")
    assert dom.real == pytest.approx(3.071, abs=1e-3)
    assert rate == pytest.approx(dom.real, rel=0.1)


@pytest.mark.slow
def test_simulation_decays_at_the_stable_side_of_the_boundary():
    """Same K_p, K_v = 60: just inside (−0.77 ± 132.6i); the run's force error decays at that rate."""
    rate, dom = growth_in_run(1000.0, 60.0, 2.0, 1.0)
    assert dom.real < 0.0
    assert rate == pytest.approx(dom.real, rel=0.1)


def test_the_matrix_pencil_separates_two_modes_of_close_rates_that_the_envelope_mixes():
    """y = e^(3.07 t) cos(127.77 t) + 0.8 e^(2.75 t) cos(158.8 t + 1) (case 3 on (a), K_p = 1000, K_v = 100):
    both exponents come back to 1e-8; the envelope's fit is pulled off the dominant rate."""
    t = np.arange(0.0, 0.6, 1e-3)
    y = np.exp(3.07 * t) * np.cos(127.77 * t) + 0.8 * np.exp(2.75 * t) * np.cos(158.8 * t + 1.0)
    found = modal_poles(t, y)
    upper = sorted(found[found.imag > 0], key=lambda z: z.imag)
    np.testing.assert_allclose(upper, [3.07 + 127.77j, 2.75 + 158.8j], rtol=1e-8)
    assert abs(envelope_rate(t, y, 3.07 + 127.77j) / 3.07 - 1.0) > 0.05


def test_the_matrix_pencil_refuses_a_non_uniform_grid():
    t = np.sort(np.random.default_rng(0).uniform(0.0, 1.0, 100))
    with pytest.raises(ValueError, match="uniformly spaced"):
        modal_poles(t, np.exp(-t))


@pytest.mark.slow
def test_a10_as_written_decays_at_its_dominant_rate_next_to_a_close_pole():
    """A10 as written, massless nominal, K_F = 10 on (b): −2.90 ± 136.1i with a pole at −4.60 ± 26.3i
    close by (the envelope fit read −4.43, +53 %); the run's mode at 136 rad/s decays at −2.90."""
    over = {"phase.0.controller.kf": 10.0, "phase.0.controller.cancel": "target", "solver.rtol": 1e-9,
            "solver.atol": 1e-11, "solver.output_rate": 1000.0, "duration": 2.0}
    rate, dom = simulated_growth(contact_phase_scene("case3_b_force", [1.0], over), 0.8)
    assert dom.real == pytest.approx(-2.900, abs=1e-3)
    assert rate == pytest.approx(dom.real, rel=0.1)
