"""Every run checks its own physics (contactdyn.output.physics_checks): each check sees what it claims to see.

A check is tested two ways: on every scene of ``sims/`` and ``benchmarks/hard/`` it stays
within its tolerance, and on a run whose channels are doctored by a known amount (or whose
loop is broken on purpose) it reports that amount, at the right time.
"""

from __future__ import annotations

import copy
import json
import warnings
from pathlib import Path

import numpy as np
import pytest

import contactdyn.hybrid.transitions
from contactdyn import parse_scene, simulate
from contactdyn.cli import main
from contactdyn.model.system import System
from contactdyn.output.physics_checks import CHECKS, PhysicsWarning, StartAudit, energy_residual, run_checks, violations
from contactdyn.scene.scene_file import sims_dir

ROOT = Path(__file__).resolve().parent.parent
SCENES = sorted(sims_dir().glob("*.toml")) + sorted((ROOT / "benchmarks" / "hard").glob("*.toml"))
M, G = 2.0, 9.81
W = M * G
MU_S, MU_K = 0.5, 0.4


def point_mass(phases: list[dict], duration: float = 0.6, normal: dict | None = None) -> dict:
    """The point mass on the ground (H = m I, F_n = m g), friction along x, a push set per phase."""
    return {
        "name": "checks",
        "duration": duration,
        "solver": {"rtol": 1e-10, "atol": 1e-12, "output_rate": 1000.0},
        "robot": {"urdf": "point_mass_xz", "q0": [0.0, 0.0]},
        "contact": {"ground": {"point": [0.0, 0.0, 0.0], "normal": normal or {"direction": [0.0, 0.0, 1.0]},
                               "tangent": {"model": "friction", "mu_s": MU_S, "mu_k": MU_K,
                                           "directions": [[1.0, 0.0, 0.0]]}}},
        "controller": {"kind": "task_force"},
        "phase": phases,
    }


def break_phase_starts(monkeypatch) -> None:
    """The loop as it was before issue 27: a phase start decides no modes."""
    def settle(self, t, x, modes, phase):
        return x, modes, phase

    monkeypatch.setattr(contactdyn.hybrid.transitions.Transitions, "settle", settle)


PUSH = 1.5 * MU_S * W  #: [N] a push out of the cone
STICK_THEN_PUSH = [{"name": "rest", "until": 0.25}, {"name": "push", "controller": {"force": [PUSH, 0, 0]}}]


def run(doc: dict):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", PhysicsWarning)
        return simulate(parse_scene(copy.deepcopy(doc)))


def recheck(result, doc: dict, **doctored) -> dict:
    """The checks of ``result`` with some channels replaced (no segment-start values)."""
    system = System(parse_scene(copy.deepcopy(doc)))
    channels = {**result.channels, **doctored}
    xs = np.zeros((len(result.t), system.n))
    return run_checks(system, xs, channels, StartAudit(), result.impacts)["contacts"]["ground"]


@pytest.mark.parametrize("path", SCENES, ids=lambda p: p.stem)
def test_every_scene_passes_its_own_checks(path):
    result = simulate(path)
    checks = result.meta["checks"]["contacts"]
    assert checks and all(name in checks for name in result.meta["contacts"])
    assert violations(result.meta["checks"]) == []


def test_a_stick_kept_outside_the_cone_is_reported_with_its_excess(monkeypatch):
    """The loop as it was before issue 27 (no decision at a phase start): the stick holds PUSH while the cone
    holds μ_s W; the check reports PUSH − μ_s W at the phase start, and simulate warns."""
    break_phase_starts(monkeypatch)
    with pytest.warns(PhysicsWarning, match="cone_excess"):
        r = simulate(parse_scene(point_mass(STICK_THEN_PUSH)))
    cone = r.meta["checks"]["contacts"]["ground"]["cone_excess"]
    assert cone["value"] == pytest.approx(PUSH - MU_S * W, rel=1e-9)
    assert cone["t"] == 0.25
    assert any("contact 'ground': cone_excess" in w for w in r.meta["check_warnings"])


def test_the_segment_start_is_checked_between_output_samples(monkeypatch):
    """The same broken loop with the phase start off the output grid (0.2505 s) and samples every 0.1 s: only
    the check at the segment's start sees the stick outside the cone there (no sample before 0.3 s is stuck and
    outside)."""
    break_phase_starts(monkeypatch)
    doc = point_mass([{"name": "rest", "until": 0.2505}, STICK_THEN_PUSH[1]])
    doc["solver"]["output_rate"] = 10.0
    r = run(doc)
    cone = r.meta["checks"]["contacts"]["ground"]["cone_excess"]
    assert cone["t"] in (0.2505, 0.3) and cone["value"] == pytest.approx(PUSH - MU_S * W, rel=1e-9)


def test_a_slide_off_the_kinetic_law_and_against_the_slip_is_reported():
    """Doctored sliding friction: 10 % too large gives slide_deviation = 0.1 μ_k W; the same force turned along
    the slip gives a dissipation gap of 2 μ_k W |v| at the fastest sliding sample."""
    doc = point_mass(STICK_THEN_PUSH)
    r = run(doc)
    sliding = (r["contact.ground.stuck"] == 0) & (r["contact.ground.touching"] == 1)
    assert sliding.sum() > 100
    F_f = r["contact.ground.F_f"].copy()
    F_f[sliding] *= 1.1
    assert recheck(r, doc, **{"contact.ground.F_f": F_f})["slide_deviation"]["value"] == \
        pytest.approx(0.1 * MU_K * W, rel=1e-9)
    F_f = r["contact.ground.F_f"].copy()
    F_f[sliding] *= -1.0
    gap = recheck(r, doc, **{"contact.ground.F_f": F_f})["dissipation_gap"]
    speed = np.abs(r["contact.ground.v_slip"][sliding, 0])
    assert gap["value"] == pytest.approx(2 * MU_K * W * speed.max(), rel=1e-9)
    assert gap["t"] == r.t[sliding][np.argmax(speed)]


def test_a_pulling_contact_and_a_creeping_stick_are_reported():
    doc = point_mass(STICK_THEN_PUSH)
    r = run(doc)
    F_n, v = r["contact.ground.F_n"].copy(), r["contact.ground.v_slip"].copy()
    F_n[50], v[20] = -3.0, 1e-5  # sample 20 is stuck (t = 0.02 s)
    checks = recheck(r, doc, **{"contact.ground.F_n": F_n, "contact.ground.v_slip": v})
    assert checks["pull"] == {"value": 3.0, "t": r.t[50], "tol": checks["pull"]["tol"]}
    assert checks["stick_speed"]["value"] == 1e-5 and checks["stick_speed"]["t"] == r.t[20]


def test_a_rigid_contacts_penetration_drift_and_complementarity_are_reported():
    """The ground is rigid (its normal bonded at touch): a doctored gap of −1 µm while touching at F_n = m g."""
    doc = point_mass(STICK_THEN_PUSH)
    r = run(doc)
    assert "penetration" in r.meta["checks"]["contacts"]["ground"]
    gap = r["contact.ground.gap"].copy()
    gap[30] = -1e-6
    checks = recheck(r, doc, **{"contact.ground.gap": gap})
    assert checks["penetration"]["value"] == pytest.approx(1e-6) and checks["drift"]["value"] == pytest.approx(1e-6)
    assert checks["complementarity"]["value"] == pytest.approx(1e-6 * W, rel=1e-9)


def test_a_compliant_contact_has_no_rigid_checks_and_no_cone_checks_without_friction():
    doc = point_mass([{"name": "rest"}], 0.2, normal={"direction": [0.0, 0.0, 1.0], "model": "c", "k": 1e5, "b": 50.0})
    doc["contact"]["ground"]["tangent"] = {"model": "free"}
    checks = run(doc).meta["checks"]["contacts"]["ground"]
    assert set(checks) == {"pull"}


def test_the_energy_residual_closes_on_an_elastic_chain_and_sees_a_leak():
    """Case 1's two-sided chains with the energy audit: the residual is within its tolerance; a doctored
    dissipation of 1 mJ from the middle on is seen as 1 mJ."""
    robot_q0 = [0.5, np.pi / 6]
    chain = {"environment": [{"k": 1e4, "b": 10.0}, {"m": 10.0}, {"k": 1e4, "b": 10.0}]}
    doc = {
        "duration": 0.5,
        "solver": {"rtol": 1e-11, "atol": 1e-13, "output_rate": 500.0, "record_energy": True},
        "robot": {"urdf": "arm2r_cart", "gravity_compensation": 0.7, "q0": robot_q0, "v0": [0.1, -0.2]},
        "body": {"cart": {"mass": 100.0, "axis": [1, 0, 0], "velocity0": 0.25, "servo": {"velocity": 0.25,
                                                                                        "gain": 500.0}}},
        "contact": {"tip": {"body": "cart", "point": [0.0, 0.0, 0.0], "bonded": True,
                            "normal": {"direction": [0, 0, 1], **chain}}},
        "controller": {"kind": "joint_pd", "kp": 2000.0, "kd": 100.0},
        "phase": [{"name": "hold", "reference": {"space": "joint", "start": robot_q0}}],
    }
    from contactdyn.robot.robot import Robot

    doc["contact"]["tip"]["point"] = Robot.load("arm2r_cart").frame_position(np.array(robot_q0), "tip").tolist()
    r = run(doc)
    energy = r.meta["checks"]["energy_residual"]
    assert 0.0 <= energy["value"] <= energy["tol"]
    assert np.ptp(r["energy.dissipated"]) > 1e-3  # the audit has something to balance
    system = System(parse_scene(copy.deepcopy(doc)))
    lost = r["energy.dissipated"].copy()
    lost[len(lost) // 2:] += 1e-3
    xs = _states(r, system)
    leak = energy_residual(system, xs, {**r.channels, "energy.dissipated": lost}, r.impacts)
    assert leak["value"] == pytest.approx(1e-3, rel=1e-3)


def _states(result, system: System) -> np.ndarray:
    """The run's states at its samples, rebuilt from its channels (robot, cart, chain masses; no drives)."""
    nQ, nv = system.nQ, system.nv
    xs = np.zeros((len(result.t), system.n))
    xs[:, :nv], xs[:, nQ:nQ + nv] = result["q"], result["v"]
    for name, i in system.body_channels:
        xs[:, i], xs[:, nQ + i] = result[f"body.{name}.x"], result[f"body.{name}.v"]
    k = nv + len(system.body_channels)
    for label in system.mass_labels:
        xs[:, k], xs[:, nQ + k] = result[f"mass.{label}.x"], result[f"mass.{label}.v"]
        k += 1
    return xs


def test_contactdyn_run_prints_one_line_per_violated_check_and_stores_them(monkeypatch, tmp_path, capsys):
    break_phase_starts(monkeypatch)
    scene = tmp_path / "broken.toml"
    from contactdyn.scene.toml_writer import dumps

    scene.write_text(dumps(point_mass(STICK_THEN_PUSH)))
    assert main(["run", str(scene), "--out", str(tmp_path / "out")]) == 0
    err = capsys.readouterr().err
    lines = [line for line in err.splitlines() if "physics check" in line]
    assert len(lines) == 1 and "cone_excess" in lines[0] and "t = 0.25 s" in lines[0]
    sidecar = json.loads((tmp_path / "out.json").read_text())
    assert sidecar["meta"]["check_warnings"] == [lines[0].removeprefix("contactdyn: warning: ")]
    assert set(sidecar["meta"]["checks"]["contacts"]["ground"]) <= set(CHECKS)


def test_a_sweep_has_a_column_per_check_and_counts_the_violations(monkeypatch, tmp_path):
    """In-process sweep (--workers 0) of the broken loop over two pushes: one inside the cone (no violation), one
    outside (one)."""
    import pandas as pd

    from contactdyn.scene.toml_writer import dumps

    break_phase_starts(monkeypatch)
    monkeypatch.chdir(tmp_path)
    (tmp_path / "broken.toml").write_text(dumps(point_mass(STICK_THEN_PUSH, duration=0.4)))
    grid = f"phase.1.controller.force=[{0.5 * PUSH}, 0.0, 0.0],[{PUSH}, 0.0, 0.0]"
    assert main(["sweep", "broken.toml", "--grid", grid, "--out", "s", "--workers", "0"]) == 0
    table = pd.read_parquet(tmp_path / "s" / "summary.parquet")
    assert {f"contact.ground.{c}" for c in CHECKS if c != "energy_residual"} <= set(table.columns)
    assert sorted(table["check_violations"]) == [0.0, 1.0]
    assert table["contact.ground.cone_excess"].max() == pytest.approx(PUSH - MU_S * W, rel=1e-9)


def test_a_fit_refuses_a_run_that_breaks_its_physics_and_says_why(monkeypatch):
    from contactdyn.identify.model import predict

    break_phase_starts(monkeypatch)
    doc = point_mass(STICK_THEN_PUSH, duration=0.4)
    answer = predict(doc, None, {}, [("contact.ground.F_n", None, np.array([0.1]))])
    assert isinstance(answer, str) and answer.startswith("refused: physics check") and "cone_excess" in answer
    fine = predict(doc, None, {"phase.1.controller.force": [0.5 * PUSH, 0.0, 0.0]},
                   [("contact.ground.F_n", None, np.array([0.1]))])
    assert fine[0] == pytest.approx([W], rel=1e-12)


def test_an_impacts_friction_impulse_outside_the_cone_is_reported():
    """A sliding impact of the point mass on the ground from 1 m/s down, 0.5 m/s along x: friction impulse
    μ_k FΔt (inside μ_s); the same impact doctored to twice μ_s FΔt is reported as the excess μ_s FΔt."""
    doc = point_mass([{"name": "fall"}], 0.1)
    doc["robot"]["q0"], doc["robot"]["v0"] = [0.0, 0.01], [0.5, -1.0]
    r = run(doc)
    (imp,) = r.impacts
    checks = r.meta["checks"]["contacts"]["ground"]
    assert checks["impulse_excess"]["value"] == 0.0 and imp["normal_impulse"] > 1.0
    system = System(parse_scene(copy.deepcopy(doc)))
    doctored = [{**imp, "friction_impulse": [-2 * MU_S * imp["normal_impulse"]]}]
    worst = run_checks(system, np.zeros((len(r.t), system.n)), r.channels, StartAudit(), doctored)
    excess = worst["contacts"]["ground"]["impulse_excess"]
    assert excess["value"] == pytest.approx(MU_S * imp["normal_impulse"], rel=1e-12) and excess["t"] == imp["t"]


def test_a_joint_limit_impact_without_a_contact_closes_the_energy_balance(tmp_path):
    """The pendulum of test_joint_limits hits its limit (13 J lost, no contact): the audit subtracts the limit's
    loss from its event, so the residual stays within its tolerance."""
    from test_joint_limits import pendulum

    doc = dict(pendulum(tmp_path).document)
    doc["solver"] = dict(doc["solver"], record_energy=True)
    r = run(doc)
    assert [e["energy_loss"] > 1.0 for e in r.events if e["kind"] == "limit"] == [True]
    energy = r.meta["checks"]["energy_residual"]
    assert energy["value"] <= energy["tol"] and r.meta["check_warnings"] == []
