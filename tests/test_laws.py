"""Laws as declared things: a stage law's and a friction law's parameters come from their declarations, their
properties (not their names) decide the physics, friction acts through one interface, each mode's path is
named, and a law changed on one path only is caught by the pipeline's check where the mode starts."""

from __future__ import annotations

import copy
import sys
import tomllib
import warnings
from pathlib import Path

import numpy as np
import pytest

from contactdyn import parse_scene, simulate
from contactdyn.cli import main
from contactdyn.errors import SceneError
from contactdyn.laws.friction_laws import FRICTION_LAWS, FrictionSpec
from contactdyn.model.paths import PIPELINE
from contactdyn.scene.keys import markdown, reference
from contactdyn.scene.scene_file import sims_dir

EXAMPLES = Path(__file__).resolve().parent.parent / "examples"
CUBIC = EXAMPLES / "cubic_press.toml"
B1 = tomllib.loads((sims_dir() / "b1.toml").read_text())


@pytest.fixture(autouse=True)
def registry(fresh_user_imports):
    """Each test imports the user's modules afresh and leaves the registries as they were (conftest)."""
    yield
    sys.modules.pop("cubic_stage", None)


def run(doc: dict, file: Path = CUBIC):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return simulate(parse_scene(copy.deepcopy(doc), file=str(file)))


def stribeck_b1(v_s: float, mu_s: float = 0.6, mu_k: float = 0.4) -> dict:
    doc = copy.deepcopy(B1)
    doc["contact"]["tip"]["tangent"] = {"model": "friction", "directions": [[1.0, 0.0, 0.0]], "law": "stribeck",
                                        "mu_s": mu_s, "mu_k": mu_k, "v_s": v_s}
    doc["duration"] = 0.5
    return doc


# ---- a stage law of the user's: declared parameter, property-driven physics ------------------------------------
def test_the_cubic_law_reads_its_declared_parameter_and_presses_where_its_spring_balances():
    doc = tomllib.loads(CUBIC.read_text())
    doc["duration"] = 2.0
    r = run(doc)
    k, k3, b = 1e5, 1e9, 300.0
    x, xd, F = r["stage.tip.n.env1.x"], r["stage.tip.n.env1.xdot"], r["stage.tip.n.env1.F"]
    np.testing.assert_allclose(F, k * x + k3 * x**3 + b * xd, rtol=0, atol=1e-9 * np.abs(F).max())
    root = np.roots([k3, 0.0, k, -40.0])  # at rest the stage carries the 40 N set-point: k x + k3 x³ = 40
    x_rest = float(root[np.isreal(root)].real[0])
    assert x[-1] == pytest.approx(x_rest, rel=1e-4)
    assert x_rest < 40.0 / k  # harder than its linear part
    (row,) = r.stats["paths"].values()
    assert (row["path"], row["why"]) == (PIPELINE, "")  # the law by address, as a built-in one


def test_the_cubic_law_with_k3_zero_is_the_linear_law():
    doc = tomllib.loads(CUBIC.read_text())
    linear = copy.deepcopy(doc)
    doc["contact"]["tip"]["normal"]["k3"] = 0.0
    del linear["contact"]["tip"]["normal"]["k3"], linear["contact"]["tip"]["normal"]["law"]
    mine, builtin = run(doc), run(linear)
    for channel in ("q", "contact.tip.F_n"):
        scale = np.abs(builtin[channel]).max()
        assert np.abs(mine[channel] - builtin[channel]).max() <= 1e-8 * scale, channel
    assert [row["path"] for row in builtin.stats["paths"].values()] == [PIPELINE]


def test_a_declared_parameter_is_checked_against_its_declaration():
    doc = tomllib.loads(CUBIC.read_text())
    doc["contact"]["tip"]["normal"]["k3"] = -1.0
    with pytest.raises(SceneError, match=r"contact\.tip\.normal\.k3.*>= 0 \[N/m\^3\]"):
        run(doc)
    doc["contact"]["tip"]["normal"]["law"] = "linear"  # k3 belongs to the cubic law only
    with pytest.raises(SceneError, match=r"contact\.tip\.normal\.k3: unknown key"):
        run(doc)


def test_the_key_reference_documents_a_registered_law_from_its_declaration():
    run(tomllib.loads(CUBIC.read_text()))  # imports cubic_stage, which registers the law
    rows = {d.key: d for d in reference()}
    k3 = rows["contact.<contact>.normal.environment[].k3"]
    assert (k3.unit, k3.default, k3.allowed) == ("N/m^3", "0", ">= 0")
    assert k3.meaning.startswith("cubic stiffness")
    assert "cubic" in rows["contact.<contact>.normal.law"].allowed


def test_the_committed_key_reference_has_no_user_law():
    assert "cubic" not in (Path(__file__).resolve().parent.parent / "docs" / "scenes.md").read_text()
    assert "k3" not in markdown()


def test_an_affine_law_is_used_by_its_coefficients_at_a_massless_junction(doubled_law):
    """Two stages in series with a massless junction between: allowed for an affine law, and the junction sits
    where the springs of its coefficients (K = 2k), not its k, balance."""
    doc = tomllib.loads(CUBIC.read_text())
    normal = {"direction": [0.0, 1.0, 0.0], "model": "chain", "environment": [
        {"k": 1e5, "b": 300.0, "law": doubled_law}, {"k": 5e4, "b": 150.0, "law": doubled_law}]}
    twin = copy.deepcopy(doc)
    doc["contact"]["tip"]["normal"] = normal
    twin["contact"]["tip"]["normal"] = {**normal, "environment": [{"k": 2e5, "b": 600.0}, {"k": 1e5, "b": 300.0}]}
    mine, builtin = run(doc), run(twin)
    assert np.abs(mine["contact.tip.F_n"] - builtin["contact.tip.F_n"]).max() <= 1e-9 * 40.0


# ---- friction as a law ----------------------------------------------------------------------------------------
def test_stribeck_slides_with_its_coefficient_at_the_slip_speed():
    v_s = 0.1  # [m/s], near B1's sliding speed: μ(v) well between μ_k and μ_s
    r = run(stribeck_b1(v_s), sims_dir() / "b1.toml")
    speed, F_n, F_f = np.abs(r["contact.tip.v_slip"][:, 0]), r["contact.tip.F_n"], r["contact.tip.F_f"][:, 0]
    mu = 0.4 + 0.2 * np.exp(-(speed / v_s) ** 2)
    sliding = r["contact.tip.stuck"] < 0.5
    np.testing.assert_allclose(np.abs(F_f[sliding]), (mu * F_n)[sliding], rtol=1e-9, atol=1e-9)
    assert np.ptp(mu[sliding]) > 0.01  # the coefficient did vary along the run
    assert not r.meta["check_warnings"]  # the physics checks use the same law
    assert {row["path"] for row in r.stats["paths"].values()} == {PIPELINE}  # μ(|v_t|) by address
    assert "slide: tip stuck" in r.stats["paths"]  # it stuck on the way, and slipped again


def test_stribeck_with_a_tiny_stribeck_speed_is_coulomb():
    coulomb = copy.deepcopy(stribeck_b1(1e-9))
    coulomb["contact"]["tip"]["tangent"] = {**coulomb["contact"]["tip"]["tangent"], "law": "coulomb"}
    del coulomb["contact"]["tip"]["tangent"]["v_s"]
    a, b = run(stribeck_b1(1e-9), sims_dir() / "b1.toml"), run(coulomb, sims_dir() / "b1.toml")
    assert np.abs(a["contact.tip.F_n"] - b["contact.tip.F_n"]).max() <= 1e-6 * 100.0


def test_friction_laws_share_one_interface():
    for name, law in FRICTION_LAWS.items():
        spec = FrictionSpec(0.6, 0.4, 0.0, name, tuple(p.sample() for p in law.params))
        speeds = np.array([1e-6, 1e-3, 1.0, 1e3])
        mu = spec.mu(speeds)
        assert np.all((0.4 - 1e-12 <= mu) & (mu <= 0.6 + 1e-12)), name  # between μ_k and μ_s
        assert float(spec.mu(1e3)) == pytest.approx(0.4), name  # fast: the kinetic coefficient
        assert spec.constant == bool(np.ptp(mu) == 0.0), name


# ---- the paths ---------------------------------------------------------------------------------------------------
def test_the_run_prints_the_modes_a_python_stage_slows(capsys, uncompilable_law):
    """A stage law numba cannot compile runs as a declared Python stage of the compiled call: each such mode is
    printed once, naming the law and numba's reason."""
    assert main(["run", "b1", "--set", "duration=0.2", "--set", f"contact.tip.normal.law={uncompilable_law.name}"]) == 0
    out = capsys.readouterr().out
    assert out.count("compiled call (stage law 'uncompilable' of tip.n is a Python stage (numba cannot compile") \
        == 1, out
    assert "readable model" not in out, out
    assert main(["run", str(CUBIC)]) == 0  # a user's law: compiled, nothing to say
    assert "path of" not in capsys.readouterr().out


def test_a_sweep_runs_the_users_stage_law_in_every_worker(tmp_path):
    import pandas as pd

    assert main(["sweep", str(CUBIC), "--grid", "contact.tip.normal.k3=0,1e10", "--workers", "2",
                 "--out", str(tmp_path / "sw"), "--quiet"]) == 0
    table = pd.read_parquet(tmp_path / "sw" / "summary.parquet")
    assert list(table["status"]) == ["ok", "ok"]


def test_new_writes_a_users_laws_with_their_declared_parameters(tmp_path, monkeypatch, capsys):
    (tmp_path / "cubic_stage.py").write_text((EXAMPLES / "cubic_stage.py").read_text())
    out = tmp_path / "mine.toml"
    assert main(["new", "mine", "--imports", "cubic_stage", "--law", "cubic", "--friction-law", "stribeck",
                 "--out", str(out)]) == 0
    assert f"imported cubic_stage from {tmp_path / 'cubic_stage.py'}" in capsys.readouterr().out
    doc = tomllib.loads(out.read_text())
    assert doc["imports"] == ["cubic_stage"]
    assert (doc["contact"]["table"]["normal"]["law"], doc["contact"]["table"]["normal"]["k3"]) == ("cubic", 1e9)
    assert doc["contact"]["table"]["tangent"]["v_s"] == 0.01  # Stribeck's declared example value
    scene = parse_scene(copy.deepcopy(doc), file=str(out))  # it reads as written
    assert scene.contacts["table"].friction.law == "stribeck"
    assert main(["new", "other", "--law", "cubic_x", "--out", str(tmp_path / "o.toml")]) == 2
    assert "--law" in capsys.readouterr().err


def test_a_controllers_declared_parameters_are_read_checked_and_documented():
    import contactdyn.laws.controllers as controllers

    saved = dict(controllers.CONTROLLERS)
    try:
        doc = tomllib.loads((EXAMPLES / "impedance_press.toml").read_text())
        scene = parse_scene(copy.deepcopy(doc), file=str(EXAMPLES / "impedance_press.toml"))
        config = scene.phases[0].controller
        assert (config.kind, config.stiffness, config.damping) == ("impedance", 2000.0, 100.0)
        doc["controller"]["damping"] = -1.0
        with pytest.raises(SceneError, match=r"controller\.damping.*>= 0 \[N·s/m\]"):
            parse_scene(copy.deepcopy(doc), file=str(EXAMPLES / "impedance_press.toml"))
        rows = {d.key: d for d in reference()}
        assert (rows["controller.stiffness"].when, rows["controller.stiffness"].unit) == ("kind = impedance", "N/m")
        assert rows["controller.damping"].meaning == "D of the impedance law"
    finally:
        controllers.CONTROLLERS.clear()
        controllers.CONTROLLERS.update(saved)
        sys.modules.pop("my_laws", None)
