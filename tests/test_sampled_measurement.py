"""A sampled law's measurement off the compiled call (``PipelineMode.measurement``) against the interpreted call's
(the same call run as Python, ``mode_runner(system, compiled=False)``): the normal and interface forces [N], the
contacts' generalized force on the joints [N·m or N] (the deformable and friction forces, plus the rows' λ whose
columns reach beyond the robot) and a carrier's acceleration; and the command a sample computes on it (the law's own
controller stage on the compiled call's reading, ``hybrid.sampled_law``) against the readable law's ``command`` on the
input built here from Pinocchio's terms, the phase's own reference and set-points and the interpreted call's
measurement, at a few states of a touching mode.

Each quantity is held to 1e-12 relative to its largest magnitude over the states (at least 1): Pinocchio's terms are
the same quantities computed in another order, rounding apart (a command's too).
"""

from __future__ import annotations

import tomllib
from pathlib import Path

import numpy as np
import pytest

from contactdyn import parse_scene
from contactdyn.hybrid.pipeline_mode import PipelineMode, mode_runner
from contactdyn.hybrid.sampled_law import SampledLaw
from contactdyn.hybrid.sampling import SampledPhases
from contactdyn.laws.controllers import ControlInput
from contactdyn.laws.sensors import quantise
from contactdyn.model.evaluation import measures, surface_keys
from contactdyn.model.phases import reference_at
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


def _readable_input(system, t, x, modes, phase, resolution, measured) -> ControlInput:
    """What the phase's law reads at (t [s], x), built the readable way: Pinocchio's terms at the joint positions
    quantised to ``resolution`` [rad or m], the phase's own reference and set-points, the forces, τ_contact and a
    carrier's acceleration of ``measured`` (a law that reads no force sees none), the surfaces by the contacts' own
    ``surface`` and the chains' anchors."""
    nQ, nv, law = system.nQ, system.nv, phase.controller.inner
    xq = x.copy()
    xq[:nv] = quantise(x[:nv], resolution) if resolution > 0.0 else x[:nv]
    robot = system.robot
    robot.update(xq[:nv], xq[nQ:nQ + nv])
    ft = robot.frame_terms(system.tip_fid)
    x_d, v_d, a_d = reference_at(system, phase, t, xq)
    z = xq[2 * nQ + phase.z_slice.start + phase.controller.inner_states.start: 2 * nQ + phase.z_slice.stop]
    forces = {**measured.normal_force, **measured.interface} if law.uses_forces else {}
    inp = ControlInput(t, xq[:nv], xq[nQ:nQ + nv], np.array(system.controller_inertia(robot.H)), np.array(robot.h),
                       robot.gravity_torque(xq[:nv]) if law.needs_gravity else None, ft.position, ft.velocity,
                       np.array(ft.jacobian), ft.drift, x_d, v_d, a_d, forces,
                       {name: ramp.at(t) for name, ramp in phase.forces.items()}, system.force_directions, z,
                       R_tip=ft.rotation, J_ang=np.array(ft.angular_jacobian), drift_ang=ft.angular_drift)
    if a_d is not None and phase.carrier is not None:
        inp.a_d = a_d + phase.carrier[1] * measured.carrier_acc
    if law.uses_forces:
        inp.tau_contact = measured.tau_contact
        points = []
        for c, m in zip(system.contacts, modes, strict=True):
            p_env, v_env = c.surface(xq, nQ)
            points += [(p_env, v_env), *((p_env + dc.u * m.offsets[i], v_env) for i, dc in enumerate(c.tangent_chains))]
        inp.surfaces = dict(zip(surface_keys(system), points, strict=True))
        inp.touching = {c.name: m.touching for c, m in zip(system.contacts, modes, strict=True)}
    return inp


@pytest.mark.parametrize("resolution", [0.0, 1e-4])  # [rad] exact joint positions, and encoders' counts
@pytest.mark.parametrize("case", list(CASES))
def test_a_samples_command_on_the_laws_stage_is_the_readable_laws_on_pinocchios_terms(case, resolution):
    """The command and rates a sample computes (the law's own controller stage on the compiled call's reading) against
    the readable law's ``command`` on the input built from Pinocchio's terms and the interpreted call's measurement:
    τ and ż to 1e-12 of their largest magnitudes. The reading has forces exactly where the law reads them."""
    system, modes, phase, x0 = _touching_mode(case)
    mode, twin = PipelineMode(Pipeline(system, modes, phase)), mode_runner(system, compiled=False)(modes, phase)
    law = SampledLaw(mode)
    t = phase.t_start + 0.013
    got, ref = [], []
    for x in _states(x0):
        reading = law.reading(t, x, resolution)
        assert bool(reading.forces) == phase.controller.inner.uses_forces
        assert resolution == 0.0 or np.any(reading.x[:system.nv] != x[:system.nv])  # (quantised)
        got.append(law.command(reading, x[law.states]))
        measured = twin.measurement(t, x) if measures(phase) else None
        tau, zdot = phase.controller.inner.command(_readable_input(system, t, x, modes, phase, resolution, measured))
        ref.append((np.asarray(tau, float), np.zeros(0) if zdot is None else np.asarray(zdot, float)))
    for k, what in enumerate(("tau", "zdot")):
        scale = max(1.0, max(float(np.max(np.abs(r[k]), initial=0.0)) for r in ref))
        for g, r in zip(got, ref, strict=True):
            np.testing.assert_allclose(g[k], r[k], rtol=0.0, atol=RTOL * scale, err_msg=f"{case} {what}")
    assert max(float(np.max(np.abs(r[0]))) for r in ref) > 1.0  # [N·m] the law commands something


def test_a_sample_measures_on_the_runner_only_where_the_law_needs_a_solved_call():
    """take asks the mode's call for a measurement for a force-reading law (and a carrier), never for one that
    reads none."""
    asked = []

    class Counted(PipelineMode):
        def measurement(self, t, x):
            asked.append(t)
            return super().measurement(t, x)

    for case, expected in (("no_force_law", 0), ("force_law", 1)):
        system, modes, phase, x0 = _touching_mode(case)
        mode = Counted(Pipeline(system, modes, phase))
        assert measures(phase) == bool(expected)
        sampled = SampledPhases(system, {}, lambda modes_, phase_, mode=mode: mode)  # (the run's runner)
        x = sampled.start(0.0, x0, modes, phase, None)
        asked.clear()
        sampled.take(1e-3, x, phase, mode)
        assert len(asked) == expected


@pytest.mark.parametrize("case", ["force_law", "real_cell", "carrier_chains"])
def test_a_delayed_reading_gives_its_own_command_after_the_next_samples(case):
    """A delayed law computes on the reading of d samples ago: its command is the one that reading gave when it was
    taken, bitwise, after later readings (other forces, another state) went through the same law."""
    system, modes, phase, x0 = _touching_mode(case)
    law = SampledLaw(PipelineMode(Pipeline(system, modes, phase)))
    x1, x2 = _states(x0)[1:]
    first = law.reading(0.01, x1)
    tau1, zdot1 = law.command(first, x1[law.states])
    second = law.reading(0.011, x2)
    tau2, _ = law.command(second, x2[law.states])
    assert np.abs(tau2 - tau1).max() > 1e-6 * np.abs(tau1).max()  # (another state: another command)
    again = law.command(first, x1[law.states])
    np.testing.assert_array_equal(again[0], tau1)
    np.testing.assert_array_equal(again[1], zdot1)
