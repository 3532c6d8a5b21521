"""Drives and motors in the one pipeline (contactdyn/model/pipeline/drives.py): each drive's output (applied force,
voltage, clip, power, dissipation) is the interpreted call's and its kind's own law's (``DriveKind.force`` at the
voltage the call gave), a kind enters by its address (a user's kind too), and a kind numba cannot compile is a
declared Python stage, named. The rates of the motor cases (case 1's cart, case 2's writer, case 3's elastic axis,
the real cell's clipped motors) are checked against the interpreted call (run_agreement.interpreted_evaluate) with
every other case in test_pipeline_proto.py."""

from __future__ import annotations

import sys
import tomllib
import warnings
from pathlib import Path

import numpy as np
import pytest

BENCH = Path(__file__).resolve().parent.parent / "benchmarks"
sys.path.insert(0, str(BENCH))
from pipeline_proto import agreement, case, states  # noqa: E402
from run_agreement import interpreted_evaluate  # noqa: E402

from contactdyn import parse_scene  # noqa: E402
from contactdyn.laws import DriveKind, Param, register_drive_kind  # noqa: E402
from contactdyn.model.pipeline.pack import unsupported  # noqa: E402
from contactdyn.model.pipeline.pipeline import Pipeline  # noqa: E402
from contactdyn.numerics.twins import Twins  # noqa: E402
from contactdyn.scene.scene_file import sims_dir  # noqa: E402
from contactdyn.simulate import prepare  # noqa: E402

RTOL = 1e-12  #: as test_pipeline_proto.py (compiled against interpreted: the same operations, rounding apart)


def _kind_outputs(system, u, x):
    """(applied [N·m or N], power, dissipation [W]) of each drive's own law (``DriveKind.force``, Python) at the
    voltages ``u`` [V] and the state x: what the drives deliver at those voltages."""
    drives, nQ = system.drives, system.nQ
    applied, power, dissipation = [], 0.0, 0.0
    for i, spec in enumerate(drives.specs):
        q, qd = x[drives.coords[i]], x[nQ + drives.coords[i]]
        m = drives.motor_coords[i]
        theta, omega = (x[m], x[nQ + m]) if m >= 0 else (np.nan, np.nan)
        F, _, P, D = spec.law.force(spec, u[i], q, qd, theta, omega)
        applied.append(F)
        power, dissipation = power + P, dissipation + D
    return np.array(applied), power, dissipation


@pytest.mark.parametrize("name", ["cart_motors", "writer_motors_write", "case3a_touch", "real_cell_clip"])
def test_each_drives_output_is_the_interpreted_ones(name):
    """Applied force per drive (joints, then the cart's wheel motor), voltage, clip, power and dissipation: the
    interpreted call's (the same call run as Python) and, at the voltages it gave, each kind's own law's."""
    system, modes, phase, t, x0 = case(name)
    pipe, twin = Pipeline(system, modes, phase), Pipeline(system, modes, phase, Twins())
    assert all(spec.law.motorized and spec.law.has_voltage for spec in system.drives.specs)
    clipped = 0
    for x in states(x0, 3):
        pipe.rhs(t, x)
        twin.rhs(t, x.copy())
        got, ref = pipe.values()["drives"], twin.values()["drives"]
        ev = interpreted_evaluate(system, t, x, modes, phase)
        scale = 1.0 + np.abs(ref["applied"]).max()
        np.testing.assert_allclose(got["applied"], ref["applied"], rtol=0, atol=RTOL * scale)
        np.testing.assert_allclose(got["applied"], np.concatenate((ev.tau, ev.body_force)), rtol=0, atol=RTOL * scale)
        np.testing.assert_allclose(got["u"], ref["u"], rtol=0, atol=RTOL * (1.0 + np.nanmax(np.abs(ref["u"]))))
        assert np.array_equal(got["clipped"], ref["clipped"])
        assert got["power"] == pytest.approx(ref["power"], abs=RTOL * (1.0 + abs(ref["power"])))
        assert got["dissipation"] == pytest.approx(ref["dissipation"], abs=RTOL * (1.0 + abs(ref["dissipation"])))
        applied, power, dissipation = _kind_outputs(system, got["u"], x)
        np.testing.assert_allclose(got["applied"], applied, rtol=0, atol=RTOL * scale)
        assert got["power"] == pytest.approx(power, abs=RTOL * (1.0 + abs(power)))
        assert got["dissipation"] == pytest.approx(dissipation, abs=RTOL * (1.0 + abs(dissipation)))
        clipped += int(got["clipped"].any())
    assert clipped == (3 if name == "real_cell_clip" else 0)
    assert pipe.failed_calls == 0


@pytest.mark.parametrize("kind, values", [
    ("dc_motor", {"R": 0.272, "C_M": 0.061, "J": 4.52e-4, "N": 160.0, "N_star": 65.12}),
    ("dc_motor", {"R": 1.3, "C_M": 0.5, "J": 7.9e-4, "wheel_radius": 0.1}),
    ("elastic", {"R": 0.175, "C_M": 0.0575, "J": 7.9e-4, "N": 50.0, "wheel_radius": 0.15, "c": 1.4e4, "d": 0.0196,
                 "I1": 1e-5, "I2": 2e-4, "twist_damping": 0.3}),
])
def test_each_built_in_kind_through_its_address_is_its_python_law(kind, values):
    """The compiled voltage and force (by address, the drive's values as the pipeline packs them) equal the kind's
    Python functions bit for bit."""
    from contactdyn.laws.drive_abi import call_drive_force, call_drive_voltage, drive_addresses, spec_values
    from contactdyn.laws.drives import DriveSpec

    spec = DriveSpec(kind, **values)
    law = spec.law
    v_addr, f_addr = drive_addresses(law)
    p = np.array([0.5, *spec_values(spec)])  # at an offset, as in the packed reals
    out = np.empty(4)
    for tau, q, qd, theta, omega in np.random.default_rng(3).normal(size=(5, 5)) * [20.0, 1.0, 2.0, 50.0, 100.0]:
        if law.motor_coordinate is False:
            theta = omega = np.nan
        u = call_drive_voltage(v_addr, p, 1, p.size - 1, tau, qd, omega)
        assert u == law.voltage(spec, tau, qd, omega)
        assert call_drive_force(f_addr, p, 1, p.size - 1, u, q, qd, theta, omega, out) == 1
        assert out.tolist() == list(law.force(spec, u, q, qd, theta, omega))
    assert np.isnan(call_drive_voltage(v_addr, p, 1, p.size - 2, 1.0, 0.0, 0.0))  # a wrong count: no voltage
    assert call_drive_force(f_addr, p, 1, p.size - 2, 1.0, 0.0, 0.0, 0.0, 0.0, out) == 0


def test_a_clipped_motor_delivers_the_force_of_its_limit():
    """The real cell's shoulder below its 24 V supply, its elbow clipped: the elbow's torque is eq. 51 at ±24 V, the
    shoulder's the command itself (a rigid gear unclipped delivers exactly what is asked)."""
    system, modes, phase, t, x0 = case("real_cell_clip")
    pipe = Pipeline(system, modes, phase)
    pipe.rhs(t, x0)
    got, ev = pipe.values()["drives"], interpreted_evaluate(system, t, x0, modes, phase)
    assert got["clipped"].tolist() == [False, True]
    s, qd = system.drives.specs[1], x0[system.nQ + 1]
    u = np.copysign(24.0, got["u"][1])
    assert got["u"][1] == u
    assert got["applied"][1] == pytest.approx(s.n_torque * s.C_M / s.R * (u - s.C_E * s.n_speed * qd), rel=1e-14)
    assert got["applied"][0] == pytest.approx(ev.tau_cmd[0], rel=1e-13)
    assert abs(ev.tau_cmd[1]) > abs(got["applied"][1])  # it asked for more


def test_a_voltage_controllers_voltages_act_as_they_are():
    """Case 2's motors under open-loop voltages (30, −2) V, a 28 V limit: the shoulder's clips, the elbow's acts as
    it is; each motor's torque is eq. 51 at its voltage (28 and −2 V), the rates the interpreted call's."""
    from contactdyn.model.pipeline.drives import DI_BY_VOLTAGE, drive_table

    system, modes, phase, t, x0 = case("writer_motors_voltage")
    rows, _, _ = drive_table(system, phase)
    assert rows[:, DI_BY_VOLTAGE].tolist() == [1, 1]
    pipe = Pipeline(system, modes, phase)
    for x in states(x0, 2):
        xdot = pipe.rhs(t, x)
        got, ev = pipe.values()["drives"], interpreted_evaluate(system, t, x, modes, phase)
        assert got["u"].tolist() == [28.0, -2.0] and got["clipped"].tolist() == [True, False]
        ref = [s.n_torque * s.C_M / s.R * (u - s.C_E * s.n_speed * x[system.nQ + i])  # eq. 51
               for i, (s, u) in enumerate(zip(system.drives.specs, (28.0, -2.0), strict=True))]
        np.testing.assert_allclose(got["applied"], ref, rtol=0, atol=RTOL * np.abs(ref).max())
        assert np.abs(xdot - ev.xdot).max() <= RTOL * np.abs(ev.xdot).max()


def test_the_rotors_reflect_on_the_mass_matrix():
    """Case 2's writer: its rotors, N N* J = 4.7 kg·m² per joint, are on M's diagonal (the interpreted rates); the
    packed reflection zeroed, the pipeline's joint accelerations change by far more than the tolerance."""
    from contactdyn.model.pipeline.pack import R_REFLECTED

    system, modes, phase, t, x0 = case("writer_motors_approach")
    pipe = Pipeline(system, modes, phase)
    s, nv, nQ = system.drives.specs[0], system.nv, system.nQ
    assert s.reflected_inertia == pytest.approx(160.0 * 65.12 * 0.000452)
    np.testing.assert_allclose(system.rotor_inertias, [s.reflected_inertia] * nv)
    ref = interpreted_evaluate(system, t, x0, modes, phase).xdot
    assert np.abs(pipe.rhs(t, x0) - ref).max() <= RTOL * np.abs(ref).max()
    at = pipe.packed.ints[R_REFLECTED]
    pipe.packed.reals[at:at + nv] = 0.0  # the true system's reflection only (the controller's stays)
    qdd = pipe.rhs(t, x0)[nQ:nQ + nv]
    assert np.abs(qdd - ref[nQ:nQ + nv]).max() > 0.1 * np.abs(ref[nQ:nQ + nv]).max()


# ---- a user's drive kinds: one that compiles runs by its address, one that does not is declined by name -------

class Geared(DriveKind):
    """A current-controlled motor through a rigid gear N, its torque limited: M = clip(τ / N, ±M_max) [N·m]."""

    name, motorized = "geared_test", True
    params = (Param("J", "kg·m²", "rotor inertia", lo=0.0),
              Param("N", "-", "speed ratio, motor speed / output speed", 1.0, lo=0.0, lo_open=True),
              Param("M_max", "N·m", "largest motor torque", np.inf, lo=0.0, lo_open=True, example=1.0))

    @staticmethod
    def n_speed(spec):
        return spec.N

    n_torque = n_speed

    @staticmethod
    def motor_inertia(spec):
        return spec.J

    @staticmethod
    def force(spec, command, q, qd, theta, omega):
        M = min(max(command / spec.N, -spec.M_max), spec.M_max)  # [N·m]
        return spec.N * M, 0.0, spec.N * M * qd, 0.0


def _python_helper(command):
    return command


class Opaque(Geared):
    """The same, its law through a plain Python helper numba cannot compile."""

    name = "opaque_test"

    @staticmethod
    def force(spec, command, q, qd, theta, omega):
        return _python_helper(command), 0.0, command * qd, 0.0


def _writer(drive: dict):
    doc = tomllib.loads((sims_dir() / "case2_writer_motors.toml").read_text())
    doc["robot"]["drive"] = drive
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return prepare(parse_scene(doc, file=str(sims_dir() / "case2_writer_motors.toml")))


def test_a_users_kind_runs_by_its_address(fresh_user_imports):
    register_drive_kind(Geared)
    system, modes, phase, x0 = _writer({"kind": "geared_test", "J": 4.52e-4, "N": 160.0, "M_max": 0.05})
    assert unsupported(system, modes, phase) == ""
    pipe = Pipeline(system, modes, phase)
    t = phase.t_start + 0.0123
    worst, _ = agreement(pipe, system, modes, phase, t, states(x0, 3))
    assert worst <= RTOL and pipe.failed_calls == 0
    assert np.abs(pipe.values()["drives"]["applied"]).max() == pytest.approx(160.0 * 0.05)  # at its limit


def test_a_kind_numba_cannot_compile_is_a_declared_python_stage(fresh_user_imports):
    """Its force called back in Python from the compiled call (laws.drive_abi.python_drive_addresses), named with
    numba's reason; the rates the interpreted call's."""
    register_drive_kind(Opaque)
    system, modes, phase, x0 = _writer({"kind": "opaque_test", "J": 4.52e-4, "N": 160.0})
    assert unsupported(system, modes, phase) == ""
    pipe = Pipeline(system, modes, phase)
    assert pipe.python_stages[0].startswith("drive kind 'opaque_test' of q1 is a Python stage (numba cannot compile")
    assert "_python_helper" in pipe.python_stages[0] and len(pipe.python_stages) == 2  # q1 and q2
    worst, _ = agreement(pipe, system, modes, phase, phase.t_start + 0.0123, states(x0, 3))
    assert worst <= RTOL and pipe.failed_calls == 0
