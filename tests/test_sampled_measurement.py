"""A sampled law's measurement off the compiled call (``PipelineMode.measurement``) against the interpreted call's
(the same call run as Python, ``mode_runner(system, compiled=False)``): the normal and interface forces [N], the
contacts' generalized force on the joints [N·m or N] (the deformable and friction forces, plus the rows' λ whose
columns reach beyond the robot) and a carrier's acceleration; and the whole input ``sample_input`` builds from the
compiled call's terms (``PipelineMode.sample_terms``) against the one it builds from Pinocchio's and the phase's own
(the interpreted call's measurement), at a few states of a touching mode.

Each quantity is held to 1e-12 relative to its largest magnitude over the states (at least 1): Pinocchio's terms are
the same quantities computed in another order, rounding apart.
"""

from __future__ import annotations

import tomllib
from pathlib import Path

import numpy as np
import pytest

from contactdyn import parse_scene
from contactdyn.hybrid.pipeline_mode import PipelineMode, mode_runner
from contactdyn.hybrid.sampling import SampledPhases
from contactdyn.model.evaluation import measures, sample_input
from contactdyn.model.pipeline.pack import unsupported
from contactdyn.model.pipeline.pipeline import Pipeline
from contactdyn.simulate import prepare

ROOT = Path(__file__).resolve().parents[1]
RTOL = 1e-12


def _rigid_on_the_cart(doc: dict) -> None:
    """case1_cart's tip on a rigid cart top with Coulomb friction: its normal row's column reaches the cart."""
    tip = doc["contact"]["tip"]
    for key in [k for k in tip if k.startswith(("normal", "tangent"))]:
        del tip[key]
    tip["normal"] = {"direction": [0.0, 0.0, 1.0], "model": "rigid"}
    tip["tangent"] = {"model": "friction", "directions": [[-1.0, 0.0, 0.0]], "mu_s": 0.6, "mu_k": 0.4}
    doc["phase"][1]["force"] = [f for f in doc["phase"][1]["force"] if f["direction"] == "n"]


#: case -> (scene, phase index, an edit of its TOML or None)
CASES = {
    "force_law": ("sims/b1_force_loop.toml", 0, None),  # hybrid A7/A10: reads F_n and τ_contact
    "real_cell": ("sims/force_loop_real_cell.toml", 0, None),  # motors, joint friction, a force law
    "no_force_law": ("sims/b1.toml", 0, None),  # task PD: reads no force
    "carrier_chains": ("sims/case1_cart.toml", 1, None),  # A7 on the cart: forces, interface, a_d
    "carrier_rigid": ("sims/case1_cart.toml", 1, _rigid_on_the_cart),  # λ of a row reaching the cart
}


def _touching_mode(case: str):
    """(system, touching modes, the sampled phase at 1 kHz, x0) of a case."""
    path, index, edit = CASES[case]
    doc = tomllib.loads((ROOT / path).read_text())
    doc.setdefault("controller", {})["sample_rate"] = 1000.0
    if edit is not None:
        edit(doc)
    system, modes, phase, x0 = prepare(parse_scene(doc, file=str(ROOT / path)))
    if index:
        phase = system.start_phase(index, phase.t_start + 1.0, x0, phase)
    modes = [m.with_(touching=True, offsets=tuple(0.0 for _ in c.tangent_chains))
             for c, m in zip(system.contacts, modes, strict=True)]
    assert unsupported(system, modes, phase) == ""
    return system, modes, phase, x0


def _states(x0: np.ndarray) -> list[np.ndarray]:
    """x0 and two perturbations of it (1e-3 relative)."""
    rng = np.random.default_rng(11)
    return [x0, *(x0 + 1e-3 * (1.0 + np.abs(x0)) * rng.normal(size=x0.size) for _ in range(2))]


def _close(got: list, ref: list, what: str) -> None:
    """Each of got matches ref to RTOL × the largest |ref| over the states (at least 1)."""
    scale = max(1.0, max(float(np.max(np.abs(r))) if np.size(r) else 0.0 for r in ref))
    for g, r in zip(got, ref, strict=True):
        np.testing.assert_allclose(g, r, rtol=0.0, atol=RTOL * scale, err_msg=what)


@pytest.mark.parametrize("case", list(CASES))
def test_the_compiled_calls_measurement_is_the_interpreted_calls(case):
    system, modes, phase, x0 = _touching_mode(case)
    mode, twin = PipelineMode(Pipeline(system, modes, phase)), mode_runner(system, compiled=False)(modes, phase)
    assert twin.interpreted and not mode.interpreted
    t = phase.t_start + 0.013
    got = [mode.measurement(t, x) for x in _states(x0)]
    ref = [twin.measurement(t, x) for x in _states(x0)]
    for c in system.contacts:
        _close([g.normal_force[c.name] for g in got], [r.normal_force[c.name] for r in ref], f"{c.name} F_n")
        assert any(abs(r.normal_force[c.name]) > 1.0 for r in ref)  # [N] the contact carries a force
    assert all(g.interface.keys() == r.interface.keys() for g, r in zip(got, ref, strict=True))
    for key in ref[0].interface:
        _close([g.interface[key] for g in got], [r.interface[key] for r in ref], key)
    if phase.controller.inner.uses_forces:
        _close([g.tau_contact for g in got], [r.tau_contact for r in ref], "tau_contact")
    if phase.carrier is not None:
        _close([g.carrier_acc for g in got], [r.carrier_acc for r in ref], "the carrier's acceleration")
        assert any(abs(r.carrier_acc) > 0.1 for r in ref)  # [m/s²] it accelerates


FIELDS = ("q", "v", "H", "h", "gravity", "p_tip", "v_tip", "J", "drift", "R_tip", "J_ang", "drift_ang", "x_d", "v_d",
          "a_d", "z", "tau_contact")  #: the ControlInput's arrays


def _copied(inp):
    """The input with its arrays copied (Pinocchio's H, h and Jacobians are its buffers, rewritten at the next
    state)."""
    for name in FIELDS:
        if getattr(inp, name) is not None:
            setattr(inp, name, np.array(getattr(inp, name)))
    return inp


@pytest.mark.parametrize("resolution", [0.0, 1e-4])  # [rad] exact joint positions, and encoders' counts
@pytest.mark.parametrize("case", list(CASES))
def test_the_input_a_sample_builds_on_the_compiled_call_is_the_one_on_pinocchios_terms(case, resolution):
    """sample_input with the compiled call's measurement and terms (at the quantised joint positions) against
    sample_input on the interpreted call's measurement and Pinocchio's and the phase's own terms: every field the law
    reads (the forces, τ_contact, the set-points, a_d with the carrier's acceleration, H, h, g, the tip's
    kinematics). Without a measurement a law that measures is refused."""
    system, modes, phase, x0 = _touching_mode(case)
    mode, twin = PipelineMode(Pipeline(system, modes, phase)), mode_runner(system, compiled=False)(modes, phase)
    t = phase.t_start + 0.013
    got = [_copied(sample_input(system, t, x, modes, phase, resolution, mode.measurement(t, x), mode.sample_terms))
           for x in _states(x0)]
    ref = [_copied(sample_input(system, t, x, modes, phase, resolution, twin.measurement(t, x)))
           for x in _states(x0)]
    if measures(phase):
        with pytest.raises(ValueError, match="pass its Measurement"):
            sample_input(system, t, x0, modes, phase, resolution)
    for name in FIELDS:
        if getattr(ref[0], name) is None:
            assert all(getattr(g, name) is None for g in got), name
            continue
        _close([getattr(g, name) for g in got], [getattr(r, name) for r in ref], name)
    for name in ("forces", "force_d"):
        assert all(getattr(g, name).keys() == getattr(r, name).keys() for g, r in zip(got, ref, strict=True))
        for key in getattr(ref[0], name):
            _close([getattr(g, name)[key] for g in got], [getattr(r, name)[key] for r in ref], f"{name} {key}")
    assert bool(ref[0].forces) == phase.controller.inner.uses_forces  # a law that reads no force sees none
    assert (ref[0].gravity is not None) == phase.controller.inner.needs_gravity
    assert resolution == 0.0 or np.any(ref[0].q != x0[:system.nv])  # (quantised)


def test_a_sample_measures_on_the_runner_only_where_the_law_needs_a_solved_call():
    """take asks the mode's call for a measurement for a force-reading law (and a carrier), never for one that
    reads none."""
    asked = []

    class Runner:
        def measurement(self, t, x):
            asked.append(t)
            return self.mode.measurement(t, x)

    for case, expected in (("no_force_law", 0), ("force_law", 1)):
        system, modes, phase, x0 = _touching_mode(case)
        Runner.mode = PipelineMode(Pipeline(system, modes, phase))
        Runner.sample_terms = Runner.mode.sample_terms
        assert measures(phase) == bool(expected)
        sampled = SampledPhases(system, {}, lambda modes_, phase_: Runner())  # (the run's runner: its first sample)
        x = sampled.start(0.0, x0, modes, phase, None)
        asked.clear()
        sampled.take(1e-3, x, modes, phase, Runner())
        assert len(asked) == expected


@pytest.mark.parametrize("case", ["force_law", "real_cell"])  # (without motors H is Pinocchio's too; with, h only)
def test_a_sample_keeps_its_own_H_and_h_after_the_next_samples(case):
    """A delayed law computes on the input of d samples ago: its H and h are those of that sample's state, not
    rewritten by the next sample's (Pinocchio's H and h are its buffers)."""
    system, modes, phase, x0 = _touching_mode(case)
    mode = PipelineMode(Pipeline(system, modes, phase))
    x1, x2 = _states(x0)[1:]
    for terms_at in (None, mode.sample_terms):
        first = sample_input(system, 0.01, x1, modes, phase, 0.0, mode.measurement(0.01, x1), terms_at)
        H1, h1 = first.H.copy(), first.h.copy()
        second = sample_input(system, 0.011, x2, modes, phase, 0.0, mode.measurement(0.011, x2), terms_at)
        assert np.abs(second.h - h1).max() > 1e-6 * np.abs(h1).max()  # (another state: another h)
        np.testing.assert_array_equal(first.H, H1)
        np.testing.assert_array_equal(first.h, h1)
