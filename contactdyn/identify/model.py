"""The fitted model: full simulations at given parameter values, read at the measured times.

Every evaluation is a whole event-driven run of the scene (``simulate``) with the fit's
parameters and solver settings set as overrides; a channel is read at the data's sample
times by linear interpolation of the run's output grid (the fit runs at an output rate at
least the data's sampling rate, so a log sampled on the same grid is read exactly).
Runs go to a process pool (``workers`` > 0) or run in this process.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..errors import ContactdynError, SceneError, close_matches
from ..scene.scene_file import SolverSpec
from .data import Measurements, split_column
from .params import Parameter

__all__ = ["FitModel", "FitSettings", "Failure", "predict", "check_columns"]

MAX_OUTPUT_RATE = 1e5  #: [Hz] cap of the fit runs' output rate


@dataclass(frozen=True)
class FitSettings:
    rtol: float = 1e-10  #: relative tolerance of every fit run (well below a 1e-3 noise level)
    atol: float = 1e-12  #: absolute tolerance of every fit run
    workers: int = 0  #: pool processes for the Jacobian's runs (0: this process)


@dataclass(frozen=True)
class Failure:
    """A run that failed inside the fit: its parameter values and the error."""

    values: dict[str, float]
    error: str


def predict(document: dict[str, Any], file: str | None, overrides: dict[str, Any],
            targets: list[tuple[str, int | None, np.ndarray]]) -> list[np.ndarray] | str:
    """Simulate with ``overrides``; each (channel, index, times) read at its times, or the error text.

    Runs in a pool worker: only plain data goes in and out.
    """
    from ..scene.scene_file import parse_scene
    from ..simulate import simulate, without_warning_lines
    from ..sweep import NUMERICAL

    try:
        with without_warning_lines():  # (a run whose checks fail is refused below, in its own words)
            result = simulate(parse_scene(document, overrides, file))
    except (ContactdynError, *NUMERICAL) as exc:
        return f"{type(exc).__name__}: {exc}"
    if result.meta.get("check_warnings"):  # a run that breaks its own physics is no evidence
        return f"refused: {result.meta['check_warnings'][0]}"
    return [read_channel(result.channels, channel, index, t) for channel, index, t in targets]


def read_channel(channels: dict[str, np.ndarray], channel: str, index: int | None, t: np.ndarray) -> np.ndarray:
    values = channels[channel] if index is None else channels[channel][:, index]
    return np.interp(t, channels["t"], values)


def check_columns(channels: dict[str, np.ndarray], names: list[str], file: str) -> None:
    """Each column must name a scalar channel or a component of a vector channel of the run."""
    for name in names:
        channel, index = split_column(name)
        if channel not in channels:
            close = close_matches(channel, channels)
            hint = f" (close: {', '.join(close)})" if close else ""
            raise SceneError(name, f"a channel of the run{hint}; channels: {', '.join(sorted(channels))}",
                             "no such channel", file)
        shape = channels[channel].shape
        if index is None and len(shape) > 1:
            raise SceneError(name, f"a component {channel}[0] ... {channel}[{shape[1] - 1}] "
                             "of this vector channel", name, file)
        if index is not None and (len(shape) == 1 or index >= shape[1]):
            size = "a scalar channel (no [i])" if len(shape) == 1 else f"an index < {shape[1]}"
            raise SceneError(name, size, index, file)


@dataclass
class FitModel:
    """Weighted residuals r = (run − data)/σ per column, from runs at solver coordinates z."""

    document: dict[str, Any]
    file: str | None
    params: list[Parameter]
    data: Measurements
    settings: FitSettings
    pool: Any = None  #: a concurrent.futures executor, or None (this process)
    duration: float | None = None  #: [s] simulate only this long (a continuation stage; None: the scene's)
    runs: int = 0  #: simulations started
    failures: list[Failure] = field(default_factory=list)

    @property
    def fixed(self) -> dict[str, Any]:
        """Overrides every fit run gets: tight tolerances and an output grid at least the data's rate."""
        solver = self.document.get("solver", {})
        rate = float(solver.get("output_rate", SolverSpec.output_rate)) if isinstance(solver, dict) \
            else SolverSpec.output_rate  # [Hz] the scene's, else the scene default
        spacing = self.data.sample_spacing()
        if math.isfinite(spacing):
            rate = min(max(rate, 1.0 / spacing), MAX_OUTPUT_RATE)
        fixed = {"solver.rtol": self.settings.rtol, "solver.atol": self.settings.atol, "solver.output_rate": rate}
        if self.duration is None:
            return fixed
        return {**fixed, "duration": math.ceil(self.duration * rate - 1e-9) / rate}  # whole output steps

    def values(self, z: np.ndarray) -> dict[str, float]:
        return {p.key: p.value(float(zi)) for p, zi in zip(self.params, z, strict=True)}

    def targets(self) -> list[tuple[str, int | None, np.ndarray]]:
        return [(c.channel, c.index, c.t) for c in self.data.columns]

    def weighted(self, predictions: list[np.ndarray]) -> np.ndarray:
        return np.concatenate([(p - c.y) / c.sigma for p, c in zip(predictions, self.data.columns, strict=True)])

    def evaluate(self, points: list[np.ndarray]) -> list[np.ndarray | None]:
        """Weighted residuals at each point (None where the run failed; the failure is recorded)."""
        fixed, targets = self.fixed, self.targets()
        jobs = [(self.document, self.file, {**fixed, **self.values(z)}, targets) for z in points]
        if self.pool is None:
            outs = [predict(*job) for job in jobs]
        else:
            outs = self._on_pool(jobs)
        self.runs += len(jobs)
        residuals: list[np.ndarray | None] = []
        for z, out in zip(points, outs, strict=True):
            if isinstance(out, str):
                self.failures.append(Failure(self.values(z), out))
                residuals.append(None)
            else:
                residuals.append(self.weighted(out))
        return residuals

    def _on_pool(self, jobs: list[tuple]) -> list[list[np.ndarray] | str]:
        from concurrent.futures.process import BrokenProcessPool

        futures = [self.pool.submit(predict, *job) for job in jobs]
        try:
            return [f.result() for f in futures]
        except BrokenProcessPool:  # a library crashed a worker (a segfault, the OOM killer): the pool is gone
            tried = "; ".join(str({p.key: job[2][p.key] for p in self.params}) for job in jobs)
            raise ContactdynError(f"a worker process died while simulating the fit's runs at {tried}; "
                                  "run again with --workers 0 to see the run's own error") from None
