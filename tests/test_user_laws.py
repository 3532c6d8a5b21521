"""A researcher's own law, first-class: imported from the user's module by the scene, in run, sweep, fit, view.

The worked example of the README (examples/my_laws.py: an impedance controller, and
examples/impedance_press.toml using it) runs here: from the command line, in a sweep's worker
processes, against its built-in twin, and refused by --no-imports.
"""

from __future__ import annotations

import copy
import os
import sys
import tomllib
import warnings
from importlib.metadata import EntryPoint
from pathlib import Path

import numpy as np
import pytest

import contactdyn.scene.user_laws as user_laws
from contactdyn import parse_scene, simulate
from contactdyn.cli import main
from contactdyn.errors import SceneError
from contactdyn.laws.controllers import CONTROLLERS

EXAMPLES = Path(__file__).resolve().parent.parent / "examples"
SCENE = EXAMPLES / "impedance_press.toml"
K, D, DEPTH, K_SURFACE = 2000.0, 100.0, 0.02, 1e5


@pytest.fixture(autouse=True)
def registry(monkeypatch):
    """Each test imports the user's modules afresh and leaves the registries and policies as they were."""
    monkeypatch.setattr(user_laws, "_state", {"allowed": True, "entry_points": False})
    monkeypatch.setattr(user_laws, "IMPORTED", {})
    saved = dict(CONTROLLERS)
    yield
    CONTROLLERS.clear()
    CONTROLLERS.update(saved)
    for name in ("my_laws", "packaged_laws"):
        sys.modules.pop(name, None)


def run(doc: dict, file: Path = SCENE):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return simulate(parse_scene(copy.deepcopy(doc), file=str(file)))


def test_the_run_imports_the_users_module_says_so_and_presses_as_the_closed_form(capsys, tmp_path):
    assert main(["run", str(SCENE), "--out", str(tmp_path / "r")]) == 0
    out = capsys.readouterr().out
    assert f"imported my_laws from {EXAMPLES / 'my_laws.py'}" in out
    from contactdyn import load_result

    F = load_result(tmp_path / "r")["contact.tip.F_n"][-1]
    assert F == pytest.approx(K * DEPTH / (1.0 + K / K_SURFACE), rel=1e-4)  # at rest: K (d − F/k) = F
    assert main(["view", str(tmp_path / "r"), "--html", str(tmp_path / "r.html")]) == 0  # view finds it again


def test_the_users_law_is_its_built_in_twin():
    """With a resting reference, τ = Jᵀ(K (x_d − x) − D ẋ) + g is the task PD with kp = K, kd = D: the same run."""
    doc = tomllib.loads(SCENE.read_text())
    mine = run(doc)
    twin = copy.deepcopy(doc)
    twin["controller"] = {"kind": "task_pd", "kp": K, "kd": D, "feedforward": "gravity"}
    builtin = run(twin)
    for channel in ("q", "contact.tip.F_n", "tau"):
        scale = np.abs(builtin[channel]).max()
        assert np.abs(mine[channel] - builtin[channel]).max() <= 1e-9 * scale, channel


def test_a_sweep_runs_the_users_law_in_every_worker(tmp_path):
    import pandas as pd

    assert main(["sweep", str(SCENE), "--grid", "controller.stiffness=1000,2000", "--workers", "2",
                 "--out", str(tmp_path / "sw"), "--quiet"]) == 0
    table = pd.read_parquet(tmp_path / "sw" / "summary.parquet").sort_values("controller.stiffness")
    assert list(table["status"]) == ["ok", "ok"]
    F = table["contact.tip.F_final"].to_numpy()
    assert F == pytest.approx([k * DEPTH / (1.0 + k / K_SURFACE) for k in (1000.0, 2000.0)], rel=2e-3)


def test_no_imports_refuses_a_scene_that_names_modules(capsys):
    assert main(["run", str(SCENE), "--no-imports"]) == 2
    assert "imports: expected no modules to import (--no-imports" in capsys.readouterr().err


@pytest.mark.parametrize("imports, piece", [(["../evil"], "a list of module names"),
                                            (["/tmp/x.py"], "a list of module names"),
                                            ("my_laws", "a list of module names"),
                                            (["no_such_module_here"], "no_such_module_here: ModuleNotFoundError")])
def test_imports_name_modules_only_and_a_missing_one_is_named(imports, piece):
    doc = tomllib.loads(SCENE.read_text())
    doc["imports"] = imports
    with pytest.raises(SceneError, match="imports") as info:
        parse_scene(doc, file=str(SCENE))
    assert piece in str(info.value)


def test_an_installed_package_of_laws_is_found_by_its_entry_point(monkeypatch, tmp_path):
    (tmp_path / "packaged_laws.py").write_text((EXAMPLES / "my_laws.py").read_text().replace(
        '"impedance"', '"packaged_impedance"'))
    monkeypatch.syspath_prepend(str(tmp_path))
    point = EntryPoint(name="mine", value="packaged_laws", group="contactdyn.laws")
    monkeypatch.setattr("importlib.metadata.entry_points", lambda group=None: [point] if group == "contactdyn.laws"
                        else [])
    doc = tomllib.loads(SCENE.read_text())
    doc.pop("imports")
    doc["controller"]["kind"] = "packaged_impedance"
    r = run(doc)
    assert r["contact.tip.F_n"][-1] == pytest.approx(K * DEPTH / (1.0 + K / K_SURFACE), rel=1e-4)
    assert "packaged_laws" in user_laws.IMPORTED


def test_no_imports_holds_for_its_own_command_only(capsys):
    assert main(["run", str(SCENE), "--no-imports", "--quiet"]) == 2
    assert main(["run", str(SCENE), "--quiet"]) == 0  # the next command in the process decides again


def test_a_saved_run_is_drawn_without_importing_its_modules(tmp_path, monkeypatch):
    """view/plot of a run received from someone never runs its code: the scene is read without its imports and
    controller tables (a module of the same name beside the saved run is not imported)."""
    assert main(["run", str(SCENE), "--out", str(tmp_path / "r"), "--quiet"]) == 0
    (tmp_path / "my_laws.py").write_text("raise RuntimeError('this must not run')\\n")
    sys.modules.pop("my_laws", None)
    CONTROLLERS.pop("impedance", None)
    monkeypatch.chdir(tmp_path)
    assert main(["view", str(tmp_path / "r"), "--html", str(tmp_path / "r.html")]) == 0
    assert "my_laws" not in sys.modules


def test_a_law_under_a_name_another_module_holds_is_refused():
    """A scene names its law by name alone: a second module's law under a taken name (two users' files with the same
    law name; a built-in's name) is refused, both files named (before: it replaced the first, and scenes that named
    the first ran the second, silently: in a sweep over two law files, every later run). The same module registering
    anew (its file imported again) replaces its own."""
    from contactdyn.laws import register
    from contactdyn.laws.controllers import Controller
    from contactdyn.laws.stage_laws import STAGE_LAWS, StageLaw, register_stage_law

    def law(module: str, base: type = Controller, name: str = "twice") -> type:
        return type("Law", (base,), {"name": name, "__module__": module})

    register(law("first_laws"))
    with pytest.raises(ValueError, match=r"controller 'twice' of second_laws is already registered by first_laws: "
                                         r"give it another name"):
        register(law("second_laws"))
    again = law("first_laws")
    register(again)
    assert CONTROLLERS["twice"] is again
    with pytest.raises(ValueError, match=r"stage law 'linear' of my_stage_laws is already registered by "
                                         r".*contactdyn/laws/stage_laws.py"):
        register_stage_law(law("my_stage_laws", StageLaw, "linear"))
    assert STAGE_LAWS["linear"].__module__ == "contactdyn.laws.stage_laws"


def test_a_controller_that_returns_a_bare_torque_is_an_error_naming_it():
    """A law's command returns (τ, ż): a bare τ of the two joints was taken apart as two numbers and the first applied
    to both joints, silently (the run's torques wrong); now the run stops with the law's name and what it must
    return, on the compiled path (the law a declared Python stage) and the interpreted one."""
    from contactdyn.errors import SimulationError
    from contactdyn.laws import register
    from contactdyn.laws.controllers import Controller

    class Bare(Controller):
        name = "bare_torque"

        def command(self, inp):
            return inp.J.T @ np.array([0.0, -50.0, 0.0])

    register(Bare)
    doc = tomllib.loads(SCENE.read_text())
    doc.pop("imports")
    doc["controller"] = {"kind": "bare_torque"}
    doc["duration"] = 0.01
    for compiled in (True, False):
        with pytest.raises(SimulationError, match=r"controller 'bare_torque': its command must return \(τ, ż\): τ 2 "
                                                  r"numbers \[N·m, N or V\], ż 0 numbers or None; it returned "
                                                  r"ndarray \(2,\)"):
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                simulate(parse_scene(copy.deepcopy(doc), file=str(SCENE)), compiled=compiled)


def test_a_broken_installed_package_of_laws_names_its_own_file_and_line(monkeypatch, tmp_path):
    """An entry point's package that raises while it imports, installed (its files among the installed packages',
    which are not the user's code): the error names the package's file and line, from the package on (before: no
    file and line, every frame being an installed package's)."""
    package = tmp_path / "broken_laws"
    package.mkdir()
    (package / "__init__.py").write_text("from . import friction\n")
    (package / "friction.py").write_text("MU = 0.3\n\nraise ValueError('mu table missing')\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    not_users = user_laws._not_users()
    monkeypatch.setattr(user_laws, "_not_users", lambda: (*not_users, str(tmp_path) + os.sep))  # (as site-packages)
    point = EntryPoint(name="broken", value="broken_laws", group="contactdyn.laws")
    monkeypatch.setattr("importlib.metadata.entry_points", lambda group=None: [point] if group == "contactdyn.laws"
                        else [])
    with pytest.raises(SceneError) as info:
        user_laws.load_entry_points()
    message = str(info.value)
    assert "entry point broken" in message and "ValueError: mu table missing" in message
    assert "(broken_laws/friction.py, line 3)" in message
