"""The worked examples of docs/architecture.md, executed as written, against closed forms."""

from __future__ import annotations

import math
import re
from pathlib import Path

import numpy as np
import pytest

from contactdyn import parse_scene, simulate
from contactdyn.laws.controllers import CONTROLLERS
from contactdyn.laws.drive_kinds import DRIVE_KINDS
from contactdyn.laws.stage_laws import STAGE_LAWS
from contactdyn.model.paths import PIPELINE
from contactdyn.model.system import System

DOC = Path(__file__).resolve().parent.parent / "docs" / "architecture.md"
AXIS_MASS = 50.0  #: [kg] urdf/cylindrical3.urdf, link 3 (the vertical axis q3, tip z = 1.2 − q3 [m])


def example(name: str) -> dict:
    """Run the ```python block after ``<!-- example: name -->`` in the doc; return its namespace."""
    match = re.search(rf"<!-- example: {name} -->\s*```python\n(.*?)```", DOC.read_text(), re.S)
    assert match, f"{DOC.name}: no example {name!r}"
    namespace: dict = {}
    exec(compile(match.group(1), f"{DOC.name}:{name}", "exec"), namespace)
    return namespace


@pytest.fixture(autouse=True)
def _registries():
    """Examples register a law, a controller or a drive kind; leave the registries as they were."""
    saved = [(registry, dict(registry)) for registry in (STAGE_LAWS, CONTROLLERS, DRIVE_KINDS)]
    yield
    for registry, entries in saved:
        registry.clear()
        registry.update(entries)


def axis_scene(duration: float, *, normal: dict | None = None, controller: dict | None = None, v0: float = 0.0,
               push: float | None = None, drive: dict | None = None, rtol: float = 1e-10):
    """The cylindrical robot's vertical axis (1 DOF, no gravity) above a surface it touches at q3 = 1."""
    doc = {
        "duration": duration, "solver": {"rtol": rtol, "atol": 1e-13, "output_rate": 1000.0},
        "robot": {"urdf": "cylindrical3", "active_joints": ["q3"], "gravity": [0.0, 0.0, 0.0], "q0": [0.999],
                  "v0": [v0], **({"drive": drive} if drive else {})},
        "contact": {"tip": {"point": [1.0, 0.0, 0.2], "normal": {"direction": [0, 0, 1], **(normal or {})}}},
        "controller": controller or {"kind": "task_pd", "kp": 0.0, "kd": 0.0, "axes": [[1.0, 0.0, 0.0]]},
    }
    if push is not None:
        doc["phase"] = [{"name": "push", "force": [{"contact": "tip", "value": push, "kind": "step"}]}]
    return parse_scene(doc)


def test_stage_law_example_settles_at_its_static_deflection_on_the_compiled_call():
    from contactdyn.laws import abi

    example("stage_law")
    assert abi.stage_address(STAGE_LAWS["unilateral"]) != 0  # its force compiles: the chain calls it by address
    k, b, F = 1e5, 3000.0, 100.0  # [N/m], [N·s/m] (ζ ≈ 0.67 with the 50 kg axis), push [N]
    stage = {"model": "chain", "environment": [{"k": k, "b": b, "law": "unilateral"}]}
    scene = axis_scene(0.6, normal=stage, v0=0.0, push=F)
    r = simulate(scene)
    assert r["q"][-1, 0] - 1.0 == pytest.approx(F / k, rel=1e-6)  # k x = F at rest
    assert {row["path"] for row in r.stats["paths"].values()} == {PIPELINE}
    assert r.stats["compiled_modes"] >= 2  # approach and press, by address
    # in compression it is the linear law: the same run with law = "linear" (on the compiled path)
    linear = simulate(axis_scene(0.6, normal={"model": "c", "k": k, "b": b}, v0=0.0, push=F))
    np.testing.assert_allclose(r["contact.tip.F_n"], linear["contact.tip.F_n"], rtol=0, atol=1e-6 * F)


def test_friction_law_example_slides_with_its_coefficient_at_the_slip_speed():
    import tomllib

    from contactdyn.laws import abi
    from contactdyn.laws.friction_laws import FRICTION_LAWS
    from contactdyn.scene.scene_file import sims_dir

    example("friction_law")
    law = FRICTION_LAWS["weakening"]
    assert abi.friction_address(law) != 0 and law.compiled_reason == ""  # its coefficient compiles
    try:
        doc = tomllib.loads((sims_dir() / "b1.toml").read_text())
        doc["duration"] = 0.3
        doc["contact"]["tip"]["tangent"] = {"model": "friction", "directions": [[1.0, 0.0, 0.0]],
                                            "law": "weakening", "mu_s": 0.6, "mu_k": 0.4, "w": 1.0}
        r = simulate(parse_scene(doc, file=str(sims_dir() / "b1.toml")))
    finally:
        del FRICTION_LAWS["weakening"]
    sliding = r["contact.tip.stuck"] < 0.5
    speed = np.abs(r["contact.tip.v_slip"][sliding, 0])
    mu = np.maximum(0.4, 0.6 - 1.0 * speed)  # the example's law, written again here
    np.testing.assert_allclose(np.abs(r["contact.tip.F_f"][sliding, 0]), mu * r["contact.tip.F_n"][sliding],
                               rtol=1e-9)
    assert np.ptp(mu) > 0.01  # the slip speed moved the coefficient
    assert r.stats["paths"]["slide: tip sliding"]["path"] == PIPELINE  # its μ(|v_t|) called by address


def test_controller_example_brakes_the_axis_exponentially_on_the_compiled_path():
    example("controller")
    kd, v0, T = 20.0, -0.5, 0.5  # [N·s/m], [m/s] (moving up, away from the surface), [s]
    r = simulate(axis_scene(T, controller={"kind": "joint_damping", "kd": kd}, v0=v0))
    assert r["v"][-1, 0] == pytest.approx(v0 * math.exp(-kd * T / AXIS_MASS), rel=1e-8)  # m v̇ = −k_d v
    assert r.stats["compiled_modes"] >= 1 and {row["path"] for row in r.stats["paths"].values()} == {PIPELINE}


def test_drive_example_reflects_its_rotor_and_runs_compiled_as_its_dc_motor_twin():
    import copy
    import tomllib

    from contactdyn.scene.scene_file import sims_dir

    example("drive")
    J, N = 4.52e-4, 160.0  # [kg·m²], [-] case 2's rotor and speed ratio
    system = System(axis_scene(0.1, drive={"kind": "current_motor", "J": J, "N": N}))
    x, _ = system.initial_state()
    system.robot.update(x[:1], x[system.nQ:system.nQ + 1])
    reflected = system.mass_matrix()[0, 0] - system.robot.H[0, 0]
    assert reflected == pytest.approx(N * N * J, rel=1e-12)  # N² J [kg]
    # case 2's writer through its approach and impact; the twin: a DC motor with N* = N and no voltage limit
    doc = tomllib.loads((sims_dir() / "case2_writer_motors.toml").read_text())
    doc["duration"] = 1.0
    twin = copy.deepcopy(doc)
    twin["robot"]["drive"].update(N_star=N, J=J, N=N)
    doc["robot"]["drive"] = {"kind": "current_motor", "J": J, "N": N}
    mine, builtin = simulate(parse_scene(doc)), simulate(parse_scene(twin))
    assert [e["kind"] for e in mine.events] == ["touch", "phase"]  # the impact, with the rotors in the momentum law
    for channel in ("q", "v", "tau", "contact.tip.F_n"):
        scale = np.abs(builtin[channel]).max()
        assert np.abs(mine[channel] - builtin[channel]).max() <= 1e-12 * scale, channel
    assert {row["path"] for row in mine.stats["paths"].values()} == {PIPELINE}
