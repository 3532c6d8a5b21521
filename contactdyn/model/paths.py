"""Which path runs each contact mode of a run: the one pipeline's call compiled or interpreted.

Every mode runs on the one pipeline (:mod:`contactdyn.model.pipeline`: one compiled call per right-hand side, the
laws by address; :class:`LivePipelines`, the path ``PIPELINE``). What it cannot pack
(:func:`~contactdyn.model.pipeline.pack.unsupported`: nothing a scene reaches today) stops the run with the reason.
The compiled call and the interpreted one run the same functions (``tests/test_both_ways.py`` holds every scene to
that).
A stage law, friction law, drive kind or user controller numba cannot compile does not keep its mode off the
pipeline: it runs there as a declared Python stage (called back through ctypes, :mod:`contactdyn.laws.abi`), named
in its row.
A run may take the pipeline interpreted instead (``twins``: a scene kind's first run, while its compiled code is
built in the background, :mod:`contactdyn.first_run`; the path ``INTERPRETED``): the same functions run as their
Python twins (:mod:`contactdyn.numerics.twins`).

Which path each mode of a run took (:func:`path_of`), and which law or part kept it off the compiled one or ran
in it as a Python stage, is in ``Result.stats["paths"]`` (:class:`PathLog`); ``contactdyn run`` prints each such
mode once.
"""

from __future__ import annotations

from collections.abc import Callable
from contextlib import nullcontext

from ..numerics.native_call import giving_handles
from ..numerics.twins import Twins, run_as
from .contact import structure
from .pipeline.pack import unsupported
from .pipeline.pipeline import Pipeline

__all__ = ["PIPELINE", "INTERPRETED", "path_of", "mode_label", "PathLog", "slower_paths", "LivePipelines"]

PIPELINE = "compiled call"  #: the path of a mode on the one pipeline
INTERPRETED = "interpreted call"  #: the path of a mode on the one pipeline run as its twins (numerics.twins)


class LivePipelines:
    """The one pipeline (:class:`~contactdyn.model.pipeline.pipeline.Pipeline`) for the modes of a run that
    :func:`~contactdyn.model.pipeline.pack.unsupported` accepts: one per modes' structure and phase (every turn of a
    2-D slide reuses it: the reference direction is data), kept wrapped by ``wrap`` (the loop's: its event values,
    compiled steps and output samples, :class:`~contactdyn.hybrid.pipeline_mode.PipelineMode`). ``twins``
    (:class:`~contactdyn.numerics.twins.Twins`): the pipelines run interpreted (the path ``INTERPRETED``); so do they
    where ``use`` is False (the class's: the tests' and benchmarks' switch)."""

    use = True  #: False: every run's pipelines interpreted (the tests' and benchmarks' compiled-against-source switch)

    def __init__(self, system, wrap: Callable = lambda pipe: pipe, use: bool = True, twins=None) -> None:
        if twins is None and not (use and type(self).use):
            twins = Twins()
        self.system, self.wrap, self.twins = system, wrap, twins
        self.pipes: dict[tuple, object] = {}  #: (structure(modes), phase.key()) -> its pipeline (wrapped)
        self.declines: dict[tuple, str] = {}  #: the same keys -> pack.unsupported's reason ("": it packs them)

    def declined(self, modes, phase) -> str:
        """Why the pipeline does not run (modes, phase) ("" when it does)."""
        key = (structure(modes), phase.key())
        if key not in self.declines:
            with giving_handles() if self.twins is not None else nullcontext():  # (interpreted: nothing compiled)
                self.declines[key] = run_as(self.twins, unsupported)(self.system, modes, phase)
        return self.declines[key]

    def count(self) -> int:
        """How many modes run on the pipeline (packed)."""
        return len(self.pipes)

    def built(self, modes, phase) -> bool:
        """Is the pipeline of (modes, phase) packed already?"""
        return (structure(modes), phase.key()) in self.pipes

    def mode(self, modes, phase):
        """The pipeline of a mode :meth:`declined` lets it run, wrapped."""
        key = (structure(modes), phase.key())
        pipe = self.pipes.get(key)
        if pipe is None:
            pipe = self.pipes[key] = self.wrap(Pipeline(self.system, modes, phase, self.twins))
        pipe.use(modes)  # a turn's new reference direction r: data of the same packed mode
        return pipe


def path_of(mode) -> tuple[str, str]:
    """(path, why it is slower: "" when nothing makes it so) of a mode's runner: ``PIPELINE`` (one compiled call per
    right-hand side; why: its declared Python stages, the laws numba cannot compile, called back from it) or
    ``INTERPRETED`` (the same call run as its twins)."""
    return (INTERPRETED if getattr(mode, "interpreted", False) else PIPELINE), mode.reason


def mode_label(system, modes, phase) -> str:
    """``press: tip sliding, wall free``: the phase and what each contact does."""
    def state(c, m) -> str:
        if not m.touching:
            return "free"
        if c.friction is None or not len(c.tangents):
            return "touching"
        return "stuck" if m.stuck else "sliding"

    return f"{phase.spec.name}: " + ", ".join(f"{c.name} {state(c, m)}" for c, m in zip(system.contacts, modes,
                                                                                     strict=True))


class PathLog:
    """Per mode of a run (its label): the path it ran on, why not a faster one, and its segments."""

    def __init__(self) -> None:
        self.rows: dict[str, dict] = {}

    def record(self, system, modes, phase, mode) -> None:
        label = mode_label(system, modes, phase)
        row = self.rows.get(label)
        if row is None:
            path, why = path_of(mode)
            row = self.rows[label] = {"path": path, "why": why, "segments": 0}
        row["segments"] += 1

    def table(self) -> dict[str, dict]:
        return {label: dict(row) for label, row in self.rows.items()}


def slower_paths(paths: dict[str, dict]) -> list[str]:
    """One line per mode that a law kept off the compiled paths or slowed there (a Python stage), saying which path
    it ran on and why."""
    return [f"{label}: {row['path']} ({row['why']})" for label, row in paths.items() if row["why"]]
