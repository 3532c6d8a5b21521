"""A drive kind is one declared thing: a user's kind, registered in a module of theirs that the scene imports, is read
from the scene (its keys checked from its declaration), documented by the key reference and the tour, and runs: as its
built-in twin where their laws agree, within its own limit where they do not, declared off the compiled path."""

from __future__ import annotations

import math
import sys
import tomllib
import warnings
from pathlib import Path

import numpy as np
import pytest

from contactdyn import parse_scene, simulate
from contactdyn.errors import SceneError
from contactdyn.laws import DRIVE_KINDS, DriveKind, Param, register_drive_kind
from contactdyn.laws.drives import DriveSpec
from contactdyn.laws.failures import LawError
from contactdyn.model.paths import PIPELINE
from contactdyn.model.system import System
from contactdyn.scene.keys import markdown, reference
from contactdyn.scene.keytour import tour
from contactdyn.scene.scene_file import sims_dir

ROOT = Path(__file__).resolve().parent.parent
J, N = 4.52e-4, 160.0  # [kg·m²], [-] case 2's rotor and speed ratio (sec. 5.2)

#: the user's module: a motor under current control through a rigid gear, its torque limited (not affine)
MY_DRIVES = '''
"""My drive kinds."""
import math

from contactdyn.laws import DriveKind, Param, register_drive_kind


@register_drive_kind
class LimitedMotor(DriveKind):
    """A motor under current control through a rigid gear N: M = clip(tau / N, +-M_max) [N·m]."""

    name = "limited_motor"
    meaning = "motor under current control through a rigid gear, its torque limited: M = clip(tau / N, +-M_max)"
    params = (Param("J", "kg·m²", "rotor inertia", lo=0.0),
              Param("N", "-", "speed ratio, motor speed / output speed", 1.0, lo=0.0, lo_open=True),
              Param("M_max", "N·m", "largest motor torque the amplifier gives", math.inf, lo=0.0, lo_open=True,
                    example=1.0))
    motorized = True

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
        applied = spec.N * M
        return applied, 0.0, applied * qd, 0.0
'''


@pytest.fixture(autouse=True)
def registry(fresh_user_imports):
    """Each test imports the user's module afresh and leaves the registry and the key reference as they were
    (conftest)."""
    yield
    sys.modules.pop("my_drives", None)


@pytest.fixture
def scene_dir(tmp_path) -> Path:
    """A folder with the user's module, where a scene that imports it lives."""
    (tmp_path / "my_drives.py").write_text(MY_DRIVES)
    return tmp_path


def writer(scene_dir: Path, drive: dict, duration: float = 1.0, **solver):
    """Case 2's writer with motors (approach, impact, the start of the writing) and the given drive, importing
    my_drives."""
    doc = tomllib.loads((sims_dir() / "case2_writer_motors.toml").read_text())
    doc.update(imports=["my_drives"], duration=duration)
    doc["robot"]["drive"] = drive
    doc["solver"].update(solver)
    return parse_scene(doc, file=str(scene_dir / "writer.toml"))


def run(scene):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return simulate(scene)


def test_the_users_kind_is_read_from_the_scene_with_its_declared_keys(scene_dir):
    scene = writer(scene_dir, {"kind": "limited_motor", "J": J, "N": N, "M_max": [0.5, 0.25]})
    specs = System(scene).drives.specs
    assert [s.kind for s in specs] == ["limited_motor"] * 2
    assert [s.M_max for s in specs] == [0.5, 0.25] and specs[0].reflected_inertia == pytest.approx(N * N * J)
    assert writer(scene_dir, {"kind": "limited_motor", "J": J}).robot.drive.expand(2, ["q1", "q2"])[0].M_max == math.inf
    mixed = writer(scene_dir, {"kind": ["limited_motor", "dc_motor"], "J": J, "N": N, "R": 0.272, "C_M": 0.061})
    assert [s.kind for s in System(mixed).drives.specs] == ["limited_motor", "dc_motor"]  # J, N shared


@pytest.mark.parametrize("drive, key, words", [
    ({"kind": "limited_motor", "J": J, "M_max": -1.0}, "robot.drive.M_max", "> 0 [N·m]"),
    ({"kind": "limited_motor", "J": J, "M_max": [1.0, 2.0, 3.0]}, "robot.drive.M_max", "one value or 2"),
    ({"kind": "limited_motor", "N": N}, "robot.drive.J", "required by kind ['limited_motor']"),
    ({"kind": "limited_motor", "J": J, "R": 1.0}, "robot.drive.R", "unknown key"),
    ({"kind": "limited_motr", "J": J}, "robot.drive.kind", "limited_motor"),
])
def test_its_keys_are_checked_against_its_declaration(scene_dir, drive, key, words):
    with pytest.raises(SceneError) as info:
        System(writer(scene_dir, drive))
    assert info.value.key == key and words in str(info.value)


def test_the_key_reference_and_the_tour_document_the_users_kind(scene_dir):
    writer(scene_dir, {"kind": "limited_motor", "J": J})  # imports my_drives, which registers the kind
    documents = tour()
    assert any('drive = { kind = "limited_motor", J = 1.0, N = 1.0, M_max = 1.0 }' in d for d in documents)  # a body
    assert documents[-1].endswith('kind = "limited_motor"\nJ = 1.0\nN = 1.0\nM_max = 1.0\n')  # and a robot
    rows = {d.key: d for d in reference()}
    m_max = rows["robot.drive.M_max"]
    assert (m_max.when, m_max.unit, m_max.default, m_max.allowed) == ("kind = limited_motor", "N·m", "inf", "> 0")
    assert m_max.meaning == "largest motor torque the amplifier gives"
    assert rows["body.<body>.drive.M_max"].type == "number"
    assert rows["robot.drive.J"].when == "kind = dc_motor, elastic, limited_motor"
    assert "limited_motor" in rows["robot.drive.kind"].allowed
    assert "limited_motor: motor under current control" in rows["robot.drive.kind"].meaning
    assert "M_max" not in (ROOT / "docs" / "scenes.md").read_text()  # the committed reference: built-in kinds only
    DRIVE_KINDS.pop("limited_motor")
    reference.cache_clear()
    assert "M_max" not in markdown()


def test_below_its_limit_it_runs_as_its_dc_motor_twin(scene_dir):
    """M_max = inf: the command acts as it is, which a DC motor with N* = N and no voltage limit delivers too. Both on
    the compiled call, the energy audit's too."""
    mine = run(writer(scene_dir, {"kind": "limited_motor", "J": J, "N": N}, record_energy=True))
    twin = run(writer(scene_dir, {"kind": "dc_motor", "R": 0.272, "C_M": 0.061, "J": J, "N": N}, record_energy=True))
    assert [e["kind"] for e in mine.events] == ["touch", "phase"]
    for channel in ("q", "v", "tau", "contact.tip.F_n", "energy.work"):
        scale = np.abs(twin[channel]).max()
        assert np.abs(mine[channel] - twin[channel]).max() <= 1e-12 * scale, channel
    assert mine.meta["check_warnings"] == []  # the energy audit balances with the kind's power


def test_at_its_limit_the_torque_clips_on_the_compiled_call(scene_dir):
    """The kind runs on the compiled call by its compiled force."""
    m_max = 0.05  # [N·m]: 8 N·m on the joint, below what the approach asks
    r = run(writer(scene_dir, {"kind": "limited_motor", "J": J, "N": N, "M_max": m_max}, duration=0.5))
    tau = np.abs(r["tau"])
    assert tau.max() == pytest.approx(N * m_max, rel=1e-12) and np.mean(tau >= N * m_max * (1 - 1e-12)) > 0.05
    assert np.abs(r["tau_cmd"]).max() > 2.0 * N * m_max  # the controller asked for more
    assert {row["path"] for row in r.stats["paths"].values()} == {PIPELINE}


def test_a_kind_is_checked_when_it_registers():
    class OtherJ(DriveKind):
        name, motorized = "other_j", True
        params = (Param("J", "g·cm²", "rotor inertia in other units", lo=0.0),)

    with pytest.raises(ValueError, match="'J' is declared otherwise by kind 'dc_motor'"):
        register_drive_kind(OtherJ)

    class Gain(DriveKind):
        name = "gain"
        params = (Param("gain", "-", "gain on the command", 1.0),)

        @staticmethod
        def force(spec, command, q, qd, theta, omega):
            return spec.gain * command, 0.0, spec.gain * command * qd, 0.0

    with pytest.raises(ValueError, match="needs motorized = True"):
        register_drive_kind(Gain)
    Gain.motorized = True
    register_drive_kind(Gain)
    assert DriveSpec("gain", gain=1.0).gain == 1.0  # (its slope is the default command_gain, 1)
    with pytest.raises(LawError, match="gives 2 of force on its coordinate per unit force command .* not its "
                                       "command_gain 1: declare command_gain"):
        DriveSpec("gain", gain=2.0)  # (a force-reading controller's fold would take half its force)
    Gain.command_gain = staticmethod(lambda spec: spec.gain)
    assert DriveSpec("gain", gain=2.0).gain == 2.0
    with pytest.raises(TypeError, match="no parameter"):
        DriveSpec("gain", R=1.0)


_GAIN = {"s": 1.0}  #: a Python dict: numba cannot type it, so the kind below does not compile


class _PythonLimitedMotor(DriveKind):
    """limited_motor's law reading a dict: numba cannot compile it (a declared Python stage of the compiled call)."""

    name = "python_limited_motor"
    meaning = "limited_motor in Python only (the test's)"
    params = (Param("J", "kg·m²", "rotor inertia", lo=0.0),
              Param("N", "-", "speed ratio, motor speed / output speed", 1.0, lo=0.0, lo_open=True),
              Param("M_max", "N·m", "largest motor torque the amplifier gives", math.inf, lo=0.0, lo_open=True,
                    example=1.0))
    motorized = True

    @staticmethod
    def n_speed(spec):
        return spec.N

    n_torque = n_speed

    @staticmethod
    def motor_inertia(spec):
        return spec.J

    @staticmethod
    def force(spec, command, q, qd, theta, omega):
        M = min(max(_GAIN["s"] * command / spec.N, -spec.M_max), spec.M_max)  # [N·m]
        applied = spec.N * M
        return applied, 0.0, applied * qd, 0.0


def test_a_kind_numba_cannot_compile_runs_in_the_compiled_call_as_a_python_stage(scene_dir):
    """The kind's force called back in Python from the compiled call: the run of its compiled twin (limited_motor,
    the same law; to 1e-12, the energy audit's too), every mode on the compiled call naming it per joint."""
    register_drive_kind(_PythonLimitedMotor)
    drive = {"J": J, "N": N, "M_max": 0.05}
    mine = run(writer(scene_dir, {"kind": "python_limited_motor", **drive}, duration=0.3, record_energy=True))
    twin = run(writer(scene_dir, {"kind": "limited_motor", **drive}, duration=0.3, record_energy=True))
    assert {row["path"] for row in mine.stats["paths"].values()} == {PIPELINE}
    for row in mine.stats["paths"].values():
        assert row["why"].startswith("drive kind 'python_limited_motor' of q1 is a Python stage (numba cannot compile")
        assert "; drive kind 'python_limited_motor' of q2 is a Python stage" in row["why"]
    for channel in ("q", "v", "tau", "contact.tip.F_n", "energy.work"):
        scale = np.abs(twin[channel]).max()
        assert np.abs(mine[channel] - twin[channel]).max() <= 1e-12 * scale, channel
