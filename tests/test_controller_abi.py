"""A controller's ABI (contactdyn.laws.controllers.abi): the impedance law by address equals its Python command; a
controller numba cannot compile is declared with its reason; the layout agrees with ControlInput's fields."""

import sys
from dataclasses import fields
from pathlib import Path

import numpy as np
import pytest

from contactdyn.laws import Controller, Param
from contactdyn.laws.controllers import abi
from contactdyn.laws.controllers.abi import (
    KEY_W,
    LAYOUT,
    NOT_IN_LAYOUT,
    PYTHON_STAGE_FIELDS,
    ControlArrays,
    buffer_of,
    layout_of,
    params_of,
)
from contactdyn.laws.controllers.base import ControlInput, DeclaredConfig
from contactdyn.model.paths import INTERPRETED, PIPELINE

EXAMPLES = Path(__file__).resolve().parent.parent / "examples"


@pytest.fixture(scope="module")
def impedance():
    """examples/my_laws.py's Impedance; the registries and imports left as they were after this module's tests."""
    import contactdyn.scene.user_laws as user_laws
    from contactdyn.laws.controllers import CONTROLLERS

    controllers, imported, state = dict(CONTROLLERS), dict(user_laws.IMPORTED), dict(user_laws._state)
    sys.path.insert(0, str(EXAMPLES))
    try:
        import my_laws
        yield my_laws.Impedance
    finally:
        sys.path.remove(str(EXAMPLES))
        sys.modules.pop("my_laws", None)
        CONTROLLERS.clear()
        CONTROLLERS.update(controllers)
        user_laws.IMPORTED.clear()
        user_laws.IMPORTED.update(imported)
        user_laws._state.update(state)


def _random_input(rng, nv: int) -> ControlInput:
    def r(*shape):
        return rng.standard_normal(shape)
    return ControlInput(rng.random(), r(nv), r(nv), r(nv, nv), r(nv), r(nv), r(3), r(3), r(3, nv), r(3), r(3), r(3),
                        r(3), {}, {}, {}, np.zeros(0), R_tip=r(3, 3), J_ang=r(3, nv), drift_ang=r(3))


@pytest.mark.parametrize("nv", [2, 6])
def test_impedance_by_address_equals_its_command(impedance, nv):
    address = abi.controller_address(impedance)
    assert address and impedance.compiled_reason == ""
    rng = np.random.default_rng(nv)
    config = DeclaredConfig("impedance", (("stiffness", 2000.0), ("damping", 100.0)))
    for _ in range(20):
        inp = _random_input(rng, nv)
        expected, _ = impedance(config, nv).command(inp)
        buffer, layout = buffer_of(inp)
        tau = np.full(nv, np.nan)
        assert abi.call_controller(address, buffer, layout, params_of(config), tau) == 1
        assert np.allclose(tau, expected, rtol=1e-13, atol=1e-13 * np.abs(expected).max())


def test_a_law_that_raises_returns_status_0(impedance):
    inp = _random_input(np.random.default_rng(0), 2)
    inp.x_d = None  # no reference: the law's x_d − p fails, as in Python
    buffer, layout = buffer_of(inp)
    tau = np.zeros(2)
    assert abi.call_controller(abi.controller_address(impedance), buffer, layout, np.array([1.0, 2.0]), tau) == 0


class _ReadsForces(Controller):
    name = "reads_forces_abi_test"
    params = (Param("gain", "1", "a gain", 1.0),)

    def command(self, inp):
        return self.config.gain * inp.forces["tip"] * inp.J[0], None


class _UsesForces(_ReadsForces):
    name = "uses_forces_abi_test"
    uses_forces = True


def test_a_controller_numba_cannot_compile_is_declared():
    assert abi.controller_address(_ReadsForces) == 0
    assert "numba cannot compile" in _ReadsForces.compiled_reason
    assert abi.controller_address(_UsesForces) == 0  # reads forces, but from the dictionary: not compiled
    assert "numba cannot compile" in _UsesForces.compiled_reason


def test_layout_and_control_arrays_agree_with_control_input():
    names = [f.name for f in fields(ControlInput)]
    in_layout = [*(name for name in names if name not in NOT_IN_LAYOUT), *ControlInput.SET_POINT_ARRAYS]
    assert [*in_layout, *PYTHON_STAGE_FIELDS] == [name for name, _, _ in LAYOUT]
    assert list(ControlArrays._fields) == in_layout
    assert set(NOT_IN_LAYOUT) <= set(names)
    layout = layout_of(3, 2, ns=2)
    assert layout[:3].tolist() == [3, 2, 2]
    assert layout[-1] == 1 + 3 + 3 + 9 + 3 + 3 + 3 + 3 + 9 + 3 + 9 + 2 + 9 + 9 + 3 + 3 + (2 + 2 + 6 + 2 + 6 + 6 + 2)
    assert layout_of(3, 2, ns=2, nk=3)[-1] == layout[-1] + 3 * KEY_W  # a Python stage's keys


class _ForceIntegral(Controller):
    """τ = gain · (F_d − F) J[0] per set-point 0, ż = F_d − F (a force-reading law with a state, over the arrays)."""

    name = "force_integral_abi_test"
    uses_forces = True
    n_states = 1
    params = (Param("gain", "1", "a gain", 1.0),)

    def command(self, inp):
        error = inp.force_set[0] - inp.force_read[0] + inp.touch[0] * inp.surface_p[0, 1] + inp.tau_contact[0]
        return self.config.gain * error * inp.J[0], np.array([error * inp.force_dir[0, 1] + inp.z[0]])


def test_a_force_reading_law_with_states_by_address_equals_its_command():
    """The set-points' arrays (ControlInput.SET_POINT_ARRAYS) in the buffer, ż the signature's second output."""
    inp = _random_input(np.random.default_rng(3), 2)
    inp.z = np.array([0.25])
    inp.forces, inp.force_d, inp.normals = {"tip": 3.0}, {"tip": (5.0, 1.0)}, {"tip": np.array([0.0, 1.0, 0.0])}
    inp.tau_contact, inp.surfaces, inp.touching = np.array([0.5, -0.5]), {"tip": (np.ones(3), np.zeros(3))}, \
        {"tip": True}
    config = DeclaredConfig(_ForceIntegral.name, (("gain", 2.0),))
    expected, rates = _ForceIntegral(config, 2).command(inp)
    buffer, layout = buffer_of(inp, nz=1)
    tau, zdot = np.zeros(2), np.zeros(1)
    assert abi.call_controller(abi.controller_address(_ForceIntegral), buffer, layout, params_of(config), tau,
                               zdot) == 1
    assert np.array_equal(tau, expected) and np.array_equal(zdot, rates)
    assert rates[0] == (5.0 - 3.0 + 1.0 + 0.5) + 0.25


def test_impedance_press_runs_in_the_compiled_call_as_on_the_python_path(impedance, monkeypatch):
    """examples/impedance_press.toml: the mode on the compiled call (the law by address), its run the one of the
    law's Python command (the address forced to 0: the compiled call runs it as a declared Python stage) and the
    interpreted run's (every mode on the same call interpreted) to 1e-9."""
    import warnings

    from contactdyn import load_scene, simulate

    def run():
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            return simulate(load_scene(EXAMPLES / "impedance_press.toml"))

    new = run()
    assert [row["path"] for row in new.stats["paths"].values()] == [PIPELINE]
    monkeypatch.setattr(abi, "controller_address", lambda cls: 0)
    from contactdyn.model.pipeline import pack
    monkeypatch.setattr(pack, "controller_address", lambda cls: 0)
    python_stage = run()
    assert [row["path"] for row in python_stage.stats["paths"].values()] == [PIPELINE]
    assert "is a Python stage" in next(iter(python_stage.stats["paths"].values()))["why"]
    from contactdyn.model.paths import LivePipelines
    monkeypatch.setattr(LivePipelines, "use", False)
    old = run()
    assert [row["path"] for row in old.stats["paths"].values()] == [INTERPRETED]
    for channel in ("q", "contact.tip.F_n"):
        scale = np.abs(old[channel]).max()
        assert np.abs(new[channel] - old[channel]).max() <= 1e-9 * scale, channel
        assert np.abs(python_stage[channel] - old[channel]).max() <= 1e-9 * scale, channel


def test_a_controller_that_reads_its_own_config_is_declared():
    from contactdyn.laws.controllers.pd import JointPD, TaskPD

    for cls in (JointPD, TaskPD):  # their own read (a staticmethod)
        assert abi.controller_address(cls) == 0
        assert "reads its own config" in cls.compiled_reason


class _Gravity(Controller):
    """τ = g(q) without asking for it (needs_gravity false): the compiled buffer has no gravity field."""

    name = "gravity_unasked_abi_test"
    params = (Param("gain", "1", "a gain", 1.0),)

    def command(self, inp):
        return self.config.gain * inp.gravity[:2].copy(), None


def test_a_field_the_input_lacks_fails_the_compiled_call_instead_of_reading_other_memory():
    inp = _random_input(np.random.default_rng(1), 2)
    inp.gravity = None  # not asked for: an empty field in the buffer
    buffer, layout = buffer_of(inp)
    tau = np.zeros(2)
    assert abi.call_controller(abi.controller_address(_Gravity), buffer, layout, np.array([1.0]), tau) == 0


class _Gains(Controller):
    name = "gains_abi_test"
    params = (Param("a", "1", "first gain", 1.0), Param("b", "1", "second gain", 1.0))

    def command(self, inp):
        return np.full(inp.q.size, self.config.a + 10.0 * self.config.b), None


class _SwappedGains(_Gains):
    """The same command, its parameters declared in the other order."""

    name = "swapped_gains_abi_test"
    params = (_Gains.params[1], _Gains.params[0])


def test_a_subclass_sharing_its_command_gets_code_of_its_own():
    inp = _random_input(np.random.default_rng(2), 2)
    buffer, layout = buffer_of(inp)
    got = []
    for cls in (_Gains, _SwappedGains):
        tau = np.zeros(2)
        assert abi.call_controller(abi.controller_address(cls), buffer, layout, np.array([1.0, 2.0]), tau) == 1
        got.append(tau[0])
    assert got == [1.0 + 10.0 * 2.0, 2.0 + 10.0 * 1.0]  # each class's params: (a, b) = (1, 2), then (2, 1)
