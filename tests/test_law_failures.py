"""A user's law that fails in a run gives one error naming it (contactdyn.laws.failures.LawError): its kind, name,
file and line, its own exception (chained, for API users) or the non-finite value it returned and its inputs, and
the simulated time; the command line prints it as one line (``--json``: its record), a sweep records it in the
failed run's row. Compiled, as a declared Python stage (numba cannot compile it) and interpreted."""

from __future__ import annotations

import json
import math
import re
import tomllib
import warnings
from pathlib import Path

import pandas as pd
import pytest

from contactdyn import parse_scene, simulate
from contactdyn.cli import EXIT_FAILED, main
from contactdyn.laws.drive_kinds import DriveKind, register_drive_kind
from contactdyn.laws.failures import LawError, kinetic_coefficient
from contactdyn.laws.friction_laws import FrictionLaw, FrictionSpec, register_friction_law
from contactdyn.laws.params import Param
from contactdyn.laws.stage_laws import StageLaw, register_stage_law

pytestmark = pytest.mark.usefixtures("fresh_user_imports")  # (each test's law modules imported afresh)

ROOT = Path(__file__).resolve().parent.parent

#: a user's impedance controller (examples/my_laws.py's) that fails past t = 0.02 s; {uncompilable}: a Python dict
#: read in its command (numba cannot compile it: a declared Python stage)
CONTROLLER = '''import math

import numpy as np

from contactdyn.laws import Controller, Param, register

_GAIN = {{"k": 1.0}}


@register
class Failing(Controller):
    name = "{name}"
    needs_gravity = True
    params = (Param("stiffness", "N/m", "K", 1000.0), Param("damping", "N·s/m", "D", 50.0))

    def command(self, inp):
        c = self.config
        tau = inp.J.T @ (c.stiffness * (inp.x_d - inp.p_tip) - c.damping * inp.v_tip) + inp.gravity
        if inp.t > 0.02:
            {failure}
        return {gain}tau, None
'''
RAISE = "raise ValueError('my controller gave up')"
SCENE = '''imports = ["{module}"]
name = "failing_press"
duration = 0.05

[solver]
rtol = 1e-10
atol = 1e-12
output_rate = 500.0

[robot]
urdf = "planar2r_b1"
tip = "tip"
gravity = [0.0, 0.0, 0.0]
q0 = [0.337307481430, -1.318116071653]

[contact.tip]
point = [0.0, -0.15, 0.0]
normal.direction = [0.0, 1.0, 0.0]
bonded = true
normal.model = "b"
normal.k = 1e5
normal.b = 1.0
normal.m = 10.0

[controller]
kind = "{name}"
stiffness = 2000.0
damping = 100.0

[[phase]]
name = "press"
[phase.reference]
start = [0.45, -0.17, 0.0]
'''


def _controller_scene(folder: Path, module: str, failure: str = RAISE, compiles: bool = False) -> tuple[Path, int]:
    """(the scene file, the line of the failure in the module) of a controller ``module`` in ``folder``."""
    text = CONTROLLER.format(name=module, failure=failure, gain="" if compiles else '_GAIN["k"] * ')
    (folder / f"{module}.py").write_text(text)
    (folder / f"{module}.toml").write_text(SCENE.format(module=module, name=module))
    return folder / f"{module}.toml", text.splitlines().index(f"            {failure}") + 1


def _one_line(err: str) -> str:
    lines = [line for line in err.splitlines() if line.startswith("contactdyn: error:")]
    assert len(lines) == 1 and "Traceback" not in err, err
    return lines[0]


@pytest.mark.parametrize("compiles, path", [(False, "compiled"), (True, "compiled"), (False, "interpreted"),
                                            (True, "interpreted")],
                         ids=["python_stage", "compiled", "python_stage_interpreted", "interpreted"])
def test_a_controllers_exception_is_one_line_naming_it(capsys, tmp_path, compiles, path):
    """Before: a raw traceback (a Python stage, interpreted), or "the law gave no finite command at this state"
    (compiled: its own message lost); --json printed nothing."""
    module = f"failing_ctl_{int(compiles)}_{path}"
    scene, line = _controller_scene(tmp_path, module, compiles=compiles)
    assert main(["run", str(scene), "--path", path]) == EXIT_FAILED
    said = _one_line(capsys.readouterr().err)
    assert re.fullmatch(rf"contactdyn: error: t = 0\.020\d* s: controller '{module}' \({module}\.py, line {line}\) "
                        r"raised ValueError: my controller gave up", said), said
    assert main(["run", str(scene), "--path", path, "--json"]) == EXIT_FAILED
    out, err = capsys.readouterr()
    assert json.loads(out) == {"status": "failed", "error": said.removeprefix("contactdyn: error: "),
                               "exit_code": EXIT_FAILED}


def test_the_api_gets_the_law_error_with_the_exception_chained(tmp_path):
    scene, line = _controller_scene(tmp_path, "failing_ctl_api", compiles=True)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        with pytest.raises(LawError) as info:
            simulate(str(scene))
    error = info.value
    assert (error.kind, error.name, Path(error.file).name, error.line) == \
        ("controller", "failing_ctl_api", "failing_ctl_api.py", line)
    assert 0.02 < error.t < 0.021
    assert isinstance(error.__cause__, ValueError) and str(error.__cause__) == "my controller gave up"


def test_a_controller_called_with_the_wrong_signature_is_named(tmp_path):
    """The error is raised calling the law (no frame of its code in the traceback): named by the law called."""
    scene, _ = _controller_scene(tmp_path, "failing_ctl_signature")
    path = tmp_path / "failing_ctl_signature.py"
    path.write_text(path.read_text().replace("def command(self, inp):", "def command(self, inp, extra):"))
    with pytest.raises(LawError, match=r"t = 0 s: controller 'failing_ctl_signature' \(failing_ctl_signature\.py\) "
                                       r"raised TypeError: .*command\(\) missing 1 required positional argument"):
        _quiet(str(scene))


def test_a_sweep_records_the_laws_error_and_goes_on(capsys, tmp_path):
    """Past t = 0.02 s the law raises: the 0.05 s run fails with the law's error in its row; the 0.015 s run is ok."""
    scene, line = _controller_scene(tmp_path, "failing_ctl_sweep")
    out = tmp_path / "sw"
    assert main(["sweep", str(scene), "--grid", "duration=0.015,0.05", "--workers", "0", "--out", str(out),
                 "--quiet"]) == EXIT_FAILED
    rows = pd.read_parquet(out / "summary.parquet").set_index("duration")
    assert rows.loc[0.015, "status"] == "ok" and rows.loc[0.05, "status"] == "failed"
    assert re.fullmatch(rf"LawError: t = 0\.020\d* s: controller 'failing_ctl_sweep' \(failing_ctl_sweep\.py, line "
                        rf"{line}\) raised ValueError: my controller gave up", rows.loc[0.05, "error"])


# ---- a law that returns NaN: named, with what it returned and where (before: the step budget's advice about
# stiffness, or "the model has no finite answer at this state") -----------------------------------------------
class NanPast(StageLaw):
    """F = k x + b ẋ up to 0.1 mm of compression, NaN past it (numba compiles it)."""

    name = "nan_past_test"

    @staticmethod
    def force(k, b, p, x, xdot):
        return k * x + b * xdot if x < 1e-4 else math.nan


class NanWhenSliding(FrictionLaw):
    """μ_k at rest, NaN while sliding faster than 1 cm/s."""

    name = "nan_when_sliding_test"

    @staticmethod
    def coefficient(mu_s, mu_k, p, speed):
        return mu_k if speed < 0.01 else math.nan


def _quiet(scene, **options):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return simulate(scene, **options)


def _axis_on_chain(law: str, k: float, rtol: float, atol: float):
    """The cylindrical robot's axis at 0.5 m/s onto a one-stage chain (k [N/m], b = 1500 N·s/m) of stage law ``law``,
    for 0.05 s, no gains."""
    return parse_scene({
        "duration": 0.05, "solver": {"rtol": rtol, "atol": atol},
        "robot": {"urdf": "cylindrical3", "active_joints": ["q3"], "gravity": [0.0, 0.0, 0.0], "q0": [0.999],
                  "v0": [0.5]},
        "contact": {"tip": {"point": [1.0, 0.0, 0.2], "normal": {
            "direction": [0, 0, 1], "model": "chain", "environment": [{"k": k, "b": 1500.0, "law": law}]}}},
        "controller": {"kind": "task_pd", "kp": 0.0, "kd": 0.0}})


@pytest.mark.parametrize("compiled", [True, False], ids=["compiled", "interpreted"])
def test_a_stage_law_that_returns_nan_is_named_with_its_inputs(compiled, monkeypatch):
    """The cylindrical robot's axis falls onto a one-stage chain of the law: every step past 0.1 mm of compression
    is rejected (NaN rates), the steps shrink against it: named once they are 1e-9 of the segment's longest (before:
    once the run's step budget was spent, bounded to 500 steps here, as it still is)."""
    import contactdyn.hybrid.loop as loop

    monkeypatch.setattr(loop, "step_budget", lambda *args: 500)
    register_stage_law(NanPast)
    scene = _axis_on_chain(NanPast.name, 5e4, 1e-10, 1e-13)
    with pytest.raises(LawError) as info:
        _quiet(scene, compiled=compiled, interpreted=not compiled)
    said = str(info.value)
    assert re.match(r"t = \S+ s: stage law 'nan_past_test' \(test_law_failures\.py\) returned F = nan N at "
                    r"x = (\S+) m, ẋ = \S+ m/s \(k = 50000 N/m, b = 1500 N·s/m\)", said), said
    assert float(re.search(r"x = (\S+) m", said).group(1)) >= 1e-4
    assert re.search(r"; the run stalled there: its steps shrank from \S+ s to \S+ s against it$", said), said


#: a user's cubic stage law (examples/cubic_stage.py's) that fails on the cubic press (examples/cubic_press.toml,
#: which settles at 0.4 mm of compression): {failure}
CUBIC = '''import math

from contactdyn.laws import Param, StageLaw, register_stage_law


@register_stage_law
class Cubic(StageLaw):
    name = "{name}"
    params = (Param("k3", "N/m^3", "cubic stiffness of the cubic law F = k x + k3 x^3 + b x'", 0.0, lo=0.0,
                    example=1e9),)

    @staticmethod
    def force({signature}):
        {body}
'''
STALLS = ("k, b, p, x, xdot", "return k * x + p[0] * x**3 + b * xdot if x < 2e-4 else math.nan")  #: NaN past 0.2 mm


def _cubic_press(folder: Path, module: str, signature: str, body: str) -> Path:
    """The cubic press (examples/cubic_press.toml) on stage law ``module`` in ``folder``, of that signature and body."""
    (folder / f"{module}.py").write_text(CUBIC.format(name=module, signature=signature, body=body))
    text = (ROOT / "examples" / "cubic_press.toml").read_text()
    text = text.replace('imports = ["cubic_stage"]', f'imports = ["{module}"]').replace('law = "cubic"',
                                                                                      f'law = "{module}"')
    (folder / f"{module}.toml").write_text(text)
    return folder / f"{module}.toml"


def test_a_stage_law_that_stalls_the_run_is_named_at_once(capsys, tmp_path):
    """The stalled cubic press: past 0.2 mm the law's NaN rejects every longer step, the steps shrink to 1e-15 s at
    t = 0.0487 s (before: on until the run's step budget, 720001 right-hand-side calls, ~40 s, then named)."""
    scene = _cubic_press(tmp_path, "stalled_cubic", *STALLS)
    assert main(["run", str(scene), "--path", "compiled"]) == EXIT_FAILED
    said = _one_line(capsys.readouterr().err)
    assert re.fullmatch(r"contactdyn: error: t = 0\.0487\d* s: stage law 'stalled_cubic' \(stalled_cubic\.py\) "
                        r"returned F = nan N at x = 0\.0002 m, ẋ = \S+ m/s \(k = 100000 N/m, b = 300 N·s/m, "
                        r"k3 = 1e\+09\); the run stalled there: its steps shrank from \S+ s to \S+ s against it",
                        said), said


def test_a_crawl_with_its_law_unchecked_stops_where_it_crawled_and_blames_no_controller(monkeypatch, tmp_path):
    """The stalled cubic press with its stall watch off (events.LawStall) and a budget of 300 steps: the calls' budget
    is spent at t = 0.0487 s, where the run crawled (before: "stopped at t = 0 s", the compiled steps recording no
    state, and the report's own look at the modes there, at a state the law fails at, blamed the controller: "the
    law gave no finite command")."""
    import contactdyn.hybrid.loop as loop

    monkeypatch.setattr(loop, "STALL_STEPS", 10**9)
    monkeypatch.setattr(loop, "step_budget", lambda *args: 300)
    scene = _cubic_press(tmp_path, "crawling_cubic", *STALLS)
    with pytest.raises(LawError) as caught:
        _quiet(str(scene))
    said = str(caught.value)
    assert re.search(r"; the run then stopped: \S+: stopped at t = 0\.0487\d* s of 0\.5 s after \d+ right-hand-side "
                     r"calls", said), said
    assert "no finite command" not in said


class InfPastRate(StageLaw):
    """F = k x + b ẋ, +inf past 2 m/s of stage rate: the stage's rate stays below 0.5 m/s, a trial state of a step
    too long for its stiff relaxation (k / b = 3333 1/s) goes past (numba compiles it)."""

    name = "inf_past_rate_test"

    @staticmethod
    def force(k, b, p, x, xdot):
        return k * x + b * xdot if abs(xdot) < 2.0 else math.inf


@pytest.mark.parametrize("compiled", [True, False], ids=["compiled", "interpreted"])
def test_a_law_overflowing_at_trial_states_only_lets_the_run_go_on(compiled):
    """The trial states of the steps too long overflow the law, their steps are rejected, shorter ones pass: the run
    ends, as before."""
    register_stage_law(InfPastRate)
    scene = _axis_on_chain(InfPastRate.name, 5e6, 1e-6, 1e-9)
    r = _quiet(scene, compiled=compiled, interpreted=not compiled)
    assert r.stats["singular_solves"] > 0  # (the calls with no answer: the trial states past 2 m/s)
    assert r["t"][-1] == pytest.approx(0.05)


def _b1_sliding_on(law: str) -> dict:
    """B1 (sims/b1.toml) for 0.02 s, its tip sliding on friction law ``law`` (mu_s 0.6, mu_k 0.4)."""
    doc = tomllib.loads((ROOT / "sims" / "b1.toml").read_text())
    doc["duration"] = 0.02
    doc["contact"]["tip"]["tangent"] = {"model": "friction", "directions": [[1.0, 0.0, 0.0]], "law": law,
                                        "mu_s": 0.6, "mu_k": 0.4}
    return doc


def test_a_friction_law_that_returns_nan_is_named_with_its_inputs():
    """B1's tip slides at 0.15 m/s from the start: the law's μ is NaN there, which stops the run at that call as a
    negative μ does, named with its contact (before: "t = 0 s: the model has no finite answer at this state (its
    contact system is not finite there)"; then the law without its contact, once the run failed)."""
    register_friction_law(NanWhenSliding)
    doc = _b1_sliding_on(NanWhenSliding.name)
    with pytest.raises(LawError) as info:
        _quiet(parse_scene(doc))
    assert re.fullmatch(r"t = 0 s: friction law 'nan_when_sliding_test' \(test_law_failures\.py\) returned μ = nan "
                        r"at slip speed 0\.15\d* m/s \(mu_s = 0\.6, mu_k = 0\.4\) on contact 'tip': expected a finite "
                        r"coefficient >= 0 \(friction opposes the slip\)", str(info.value)), str(info.value)


def test_a_non_finite_coefficient_is_refused_where_an_impact_reads_it_too():
    """kinetic_coefficient, the one check of a law's μ (the call's stop and an impact's), refuses NaN and ±inf as it
    refuses μ < 0, at a finite slip speed; at a speed that is not finite (an overflowed trial state) μ is given."""
    register_friction_law(NanWhenSliding)
    spec = FrictionSpec(0.6, 0.4, 0.0, NanWhenSliding.name, ())
    with pytest.raises(LawError, match=r"^t = 0\.3 s: friction law 'nan_when_sliding_test' .* returned μ = nan at slip "
                       r"speed 0\.15 m/s .* on contact 'tip': expected a finite coefficient >= 0"):
        kinetic_coefficient(spec, "tip", 0.15, 0.3)
    assert kinetic_coefficient(spec, "tip", 0.0, 0.3) == 0.4
    assert math.isnan(kinetic_coefficient(spec, "tip", math.inf, 0.3))


def test_a_controller_that_returns_nan_is_named_with_its_command(capsys, tmp_path):
    scene, _ = _controller_scene(tmp_path, "failing_ctl_nan", "return tau * math.nan, None", compiles=True)
    assert main(["run", str(scene)]) == EXIT_FAILED
    said = _one_line(capsys.readouterr().err)
    assert re.fullmatch(r"contactdyn: error: t = 0\.020\d* s: controller 'failing_ctl_nan' \(failing_ctl_nan\.py\) "
                        r"gave no finite command: τ = \[nan, nan\] at q = \[\S+, \S+\], v = \[\S+, \S+\]", said), said


@pytest.mark.parametrize("path", ["compiled", "interpreted"])
def test_a_stage_law_with_a_wrong_signature_is_named(capsys, tmp_path, path):
    """force(k, b, p, x): the call raises TypeError before the law's code runs (no frame of it in the traceback).
    Before, interpreted: the raw TypeError's traceback (compiled, numba cannot compile it: a Python stage, named)."""
    module = f"wrong_cubic_{path}"
    scene = _cubic_press(tmp_path, module, "k, b, p, x", "return k * x + p[0] * x**3")
    assert main(["run", str(scene), "--path", path]) == EXIT_FAILED
    said = _one_line(capsys.readouterr().err)
    assert re.fullmatch(rf"contactdyn: error: t = 0 s: stage law '{module}' \({module}\.py\) raised TypeError: "
                        r"\S*force\(\) takes 4 positional arguments but 5 were given", said), said


class WrongSignature(FrictionLaw):
    """μ_k, but its coefficient takes no slip speed."""

    name = "wrong_signature_test"

    @staticmethod
    def coefficient(mu_s, mu_k, p):
        return mu_k


@pytest.mark.parametrize("compiled", [True, False], ids=["compiled", "interpreted"])
def test_a_friction_law_with_a_wrong_signature_is_named(compiled):
    register_friction_law(WrongSignature)
    doc = _b1_sliding_on(WrongSignature.name)
    with pytest.raises(LawError) as info:
        _quiet(parse_scene(doc), compiled=compiled, interpreted=not compiled)
    assert re.fullmatch(r"t = 0 s: friction law 'wrong_signature_test' \(test_law_failures\.py\) raised TypeError: "
                        r"\S*coefficient\(\) takes 3 positional arguments but 4 were given", str(info.value)), \
        str(info.value)


class NanForce(DriveKind):
    """A torque source behind a law (motorized, no gear): the force its command, NaN past ``tau_nan``."""

    name = "nan_force_test"
    params = (Param("tau_nan", "N·m", "the command past which the force is NaN", 1e3, lo=0.0),)
    motorized = True

    @staticmethod
    def force(spec, command, q, qd, theta, omega):
        force = command if abs(command) < spec.tau_nan else math.nan
        return force, 0.0, force * qd, 0.0


class NanVoltage(NanForce):
    """The same by a voltage (1 V per N·m), NaN past ``tau_nan``."""

    name = "nan_voltage_test"
    has_voltage = True

    @staticmethod
    def voltage(spec, tau, qd, omega):
        return tau if abs(tau) < spec.tau_nan else math.nan

    @staticmethod
    def force(spec, command, q, qd, theta, omega):
        return command, 0.0, command * qd, 0.0


@pytest.mark.parametrize("compiled", [True, False], ids=["compiled", "interpreted"])
@pytest.mark.parametrize("kind, said", [
    (NanForce, r"returned force = nan N·m or N at command = (\S+) N·m or N, q = \S+, q̇ = \S+"),
    (NanVoltage, r"returned u = nan V for τ = (\S+) N·m or N at q̇ = \S+")], ids=["force", "voltage"])
def test_a_drive_kind_that_returns_nan_is_named_with_its_inputs(monkeypatch, kind, said, compiled):
    """B1's shoulder asks 51.5 N·m at t = 0.0386 s (49.5 to 51.9 N·m over its first 0.05 s) of a drive kind whose law
    is NaN past it (before: "b1: integration failed at t = 0.0385546558 s (DOP853C): DOP853C: step size becomes too
    small", the kind not named)."""
    import contactdyn.hybrid.loop as loop

    monkeypatch.setattr(loop, "step_budget", lambda *args: 2000)
    register_drive_kind(kind)
    doc = tomllib.loads((ROOT / "sims" / "b1.toml").read_text())
    doc["duration"] = 0.05
    doc["robot"]["drive"] = {"kind": kind.name, "tau_nan": 51.5}
    with pytest.raises(LawError) as info:
        _quiet(parse_scene(doc), compiled=compiled, interpreted=not compiled)
    error = str(info.value)
    assert re.fullmatch(rf"t = 0\.03\d* s: drive kind '{kind.name}' \(test_law_failures\.py\) {said} "
                        r"\(tau_nan = 51\.5\); the run stalled there: its steps shrank from \S+ s to \S+ s against it",
                        error), error
    assert abs(float(re.search(said, error).group(1))) >= 51.5
