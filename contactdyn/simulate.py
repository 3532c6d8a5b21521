"""Run a scene: the public entry points of the simulator.

    result = simulate("b1")                      # a scene in sims/, a path, or a Scene
    result = simulate("b1", {"contact.tip.normal.k": 1e4})

Where the pieces are (see ``docs/architecture.md`` for the module map):

- the hybrid loop (smooth phase → event → transition → next phase): :mod:`contactdyn.hybrid.loop`;
- the events (touch, separate, stop, reverse, turn, slip) and the storm guard:
  :mod:`contactdyn.hybrid.events`; what each event does to the modes: :mod:`contactdyn.hybrid.transitions`;
- the right-hand side: the one pipeline, :mod:`contactdyn.model.pipeline` (one call for every mode and law, compiled
  or interpreted; ``Result.stats["paths"]`` says which mode ran where and which laws ran as Python stages);
- friction and the stick band: :mod:`contactdyn.model.friction`; impacts: :mod:`contactdyn.model.impact`;
- the output channels: :mod:`contactdyn.output.channels`.
"""

from __future__ import annotations

import time
import warnings
from contextlib import contextmanager, nullcontext
from pathlib import Path
from typing import Any

import numpy as np

from .hybrid.loop import HybridRun
from .hybrid.progress import Progress
from .model.contact import ContactMode
from .model.phases import Phase
from .model.system import System
from .numerics import notice
from .numerics.twins import running
from .output.physics_checks import PhysicsWarning
from .output.result import Result
from .scene.sanity import SanityWarning
from .scene.scene_file import Scene, load_scene

__all__ = ["simulate", "run_system", "prepare", "without_warning_lines"]


@contextmanager
def without_warning_lines():
    """Inside, Python prints none of the sanity and physics checks' warnings: a run keeps them in ``Result.meta``
    (``warnings``, ``check_warnings``), which the command line prints in its own words, a sweep's runs save, and a
    fit reads (a run that fails its checks is no evidence)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", SanityWarning)
        warnings.simplefilter("ignore", PhysicsWarning)
        yield


def simulate(scene: Scene | str | Path, overrides: dict[str, Any] | None = None, *, progress: bool = False,
             compiled: bool = True, interpreted: bool = False) -> Result:
    """Run a scene (an object, a path, or a name in ``sims/``) and return its Result; ``progress``: show the
    simulated time on stderr once the run has taken a couple of seconds (:mod:`contactdyn.hybrid.progress`);
    ``interpreted=True``: the compiled call's modes run interpreted, as its Python twins, only its small leaves
    compiled (:mod:`contactdyn.numerics.twins`; a scene kind's first run, :mod:`contactdyn.first_run`); so does
    ``compiled=False``."""
    if not isinstance(scene, Scene):
        scene = load_scene(scene, overrides)
    elif overrides:
        from .scene.scene_file import parse_scene

        scene = parse_scene(scene.document, overrides, scene.file)
    wall0 = time.perf_counter()
    system = System(scene)
    loop = HybridRun(system, compiled, interpreted)
    with running(loop.pipelines.twins):  # (interpreted: the checks' calls of the model's numba functions too)
        notes = sanity_warnings(system)
    if progress:
        loop.progress = Progress(scene.name, scene.duration)
    if interpreted or not compiled:
        about = notice.about("the leaves the interpreted call runs compiled (rigid-body algorithms, linear algebra)")
    else:
        about = nullcontext()
    try:
        with about:
            result = loop.run(wall0)
    finally:
        if loop.progress is not None:
            loop.progress.done()
    result.meta["warnings"] = notes + outcome_notes(system, result)
    check_warnings(result)
    return result


def outcome_notes(system: System, result: Result) -> list[str]:
    """The run's :mod:`~contactdyn.output.outcome` warnings (what it did not do), issued as SanityWarning."""
    from .output.outcome import outcome_warnings
    from .scene.sanity import SanityWarning

    notes = outcome_warnings(system.scene, result)
    _issue(system.scene.name, notes, SanityWarning)
    return notes


def check_warnings(result: Result) -> None:
    """Issue the run's violated :mod:`~contactdyn.output.physics_checks` as PhysicsWarning (never fatal)."""
    from .output.physics_checks import PhysicsWarning

    _issue(result.meta["name"], result.meta.get("check_warnings", []), PhysicsWarning)


def _issue(name: str, notes: list[str], category: type[Warning]) -> None:
    """Each note as a Python warning of ``category``, prefixed with the scene's name (the caller's caller's line)."""
    import warnings

    for note in notes:
        warnings.warn(f"{name}: {note}", category, stacklevel=4)


def sanity_warnings(system: System) -> list[str]:
    """The scene's :mod:`~contactdyn.scene.sanity` warnings, issued as SanityWarning (never fatal)."""
    from .scene.sanity import SanityWarning, scene_warnings, system_warnings

    notes = scene_warnings(system.scene) + system_warnings(system)
    _issue(system.scene.name, notes, SanityWarning)
    return notes


def prepare(scene: Scene) -> tuple[System, list[ContactMode], Phase, np.ndarray]:
    """The system, consistent initial modes, first phase and initial state of a scene (for benchmarks)."""
    system = System(scene)
    x, modes, phase = HybridRun(system).start()
    return system, modes, phase, x


def run_system(system: System) -> Result:
    """Simulate an already built system (its wall time excludes loading the scene and robot)."""
    return HybridRun(system).run(time.perf_counter())
