"""``fit(scene, data, params)``: estimate scene parameters from a measured log."""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import ContactdynError, SceneError
from ..scene.scene_file import Scene, load_scene, parse_scene
from .data import Measurements, measurements, read_csv
from .model import Failure, FitModel, FitSettings, check_columns, read_channel
from .params import Parameter, parse_params
from .solver import Stage, StartOutcome, solve_in_stages, start_points
from .uncertainty import ChannelFit, Estimate, channel_fits, estimates

__all__ = ["FitResult", "fit"]


@dataclass
class FitResult:
    scene: str  #: scene name
    scene_file: str | None
    data_file: str
    document: dict[str, Any]  #: the scene document the fit started from (after --set)
    estimates: list[Estimate]
    correlation: np.ndarray
    chi2_red: float  #: Σr²/(m − n) at the optimum
    dof: int
    channels: list[ChannelFit]
    starts: list[StartOutcome]
    failures: list[Failure]
    runs: int  #: simulations in the whole fit
    wall_s: float  #: [s]
    settings: FitSettings
    stages: tuple[Stage, ...] = ()
    series: list[dict[str, np.ndarray]] = field(default_factory=list)  #: per column: t, data, start, fitted

    @property
    def values(self) -> dict[str, float]:
        return {e.key: e.value for e in self.estimates}

    @property
    def undetermined(self) -> list[Estimate]:
        return [e for e in self.estimates if not e.determined]


def fit(scene: Scene | str | Path, data: str | Path | Measurements, params: str | list[str], *,
        overrides: dict[str, Any] | None = None, noise: dict[str, float] | None = None, starts: int = 1,
        seed: int = 0, workers: int = 0, stages: int = 6, rtol: float = FitSettings.rtol,
        atol: float = FitSettings.atol, max_runs: int | None = None) -> FitResult:
    """Fit the scene keys ``params`` (``"KEY[=LOW:HIGH],..."``) to the log ``data`` (a CSV path).

    ``noise``: σ per column (others are estimated from the data); ``starts``: solver starts
    (the scene's values first, then random points in the bounds); ``workers``: processes
    for the runs (0: this process); ``stages``: continuation in time (the first stage fits
    the first 1/2^(stages−1) of the log, each next one twice as much). Bad input raises
    SceneError naming the key or column.
    """
    wall0 = time.perf_counter()
    if not isinstance(scene, Scene):
        scene = load_scene(scene, overrides)
    elif overrides:
        scene = parse_scene(scene.document, overrides, scene.file)
    if starts < 1:
        raise SceneError("--starts", "an integer >= 1", starts)
    if stages < 1:
        raise SceneError("--stages", "an integer >= 1", stages)
    if workers < 0:
        raise SceneError("--workers", "an integer >= 0 (0: this process)", workers)
    parameters = parse_params(params, scene.document, scene.file)
    if not isinstance(data, Measurements):
        try:
            data = measurements(data, noise, scene.duration)
        except SceneError:
            _check_names(scene, data)  # a column naming no channel is the first thing to say
            raise
    settings = FitSettings(rtol, atol, workers)
    model = FitModel(scene.document, scene.file, parameters, data, settings)
    start_series = _first_run(model, parameters)
    pool = _pool(workers)
    model.pool = pool
    try:
        solution = solve_in_stages(model, start_points(model, starts, seed), stages,
                                   **({"max_runs": max_runs} if max_runs else {}))
    except BaseException:
        if pool is not None:
            from ..sweep import stop_pool

            stop_pool(pool)
        raise
    if pool is not None:
        pool.shutdown(wait=True)
    est, corr, chi2_red, dof = estimates(parameters, solution.z, solution.jacobian, solution.residuals,
                                         solution.at_bound)
    series, k = [], 0
    for col, start in zip(data.columns, start_series, strict=True):
        fitted = solution.residuals[k:k + col.y.size] * col.sigma + col.y
        k += col.y.size
        series.append({"t": col.t, "data": col.y, "start": start, "fitted": fitted})
    return FitResult(scene.name, scene.file, data.file, scene.document, est, corr, chi2_red, dof,
                     channel_fits(model, solution.residuals), solution.starts, model.failures, model.runs,
                     time.perf_counter() - wall0, settings, solution.stages, series)


def _first_run(model: FitModel, parameters: list[Parameter]) -> list[np.ndarray]:
    """Run the scene's values here: check the columns against its channels; its values at the data times."""
    from ..simulate import simulate

    values = {p.key: p.start for p in parameters}
    model.runs += 1
    try:
        result = simulate(parse_scene(model.document, {**model.fixed, **values}, model.file))
    except ContactdynError as exc:
        raise ContactdynError(f"the run at the scene's values {values} failed: {exc}") from None
    if result.meta.get("check_warnings"):
        raise ContactdynError(f"the run at the scene's values {values} breaks its own physics, so a fit cannot "
                              f"trust it: {'; '.join(result.meta['check_warnings'])}")
    check_columns(result.channels, [c.name for c in model.data.columns], model.data.file)
    return [read_channel(result.channels, c.channel, c.index, c.t) for c in model.data.columns]


def _check_names(scene: Scene, path) -> None:
    """Raise if a column of the log at ``path`` names no channel of the scene's run (a 1 ms run gives the
    names); say nothing if the log cannot be read."""
    from ..simulate import simulate

    try:
        _, raw = read_csv(path)
        channels = simulate(parse_scene(scene.document, {"duration": 1e-3}, scene.file)).channels
    except ContactdynError:
        return
    check_columns(channels, list(raw), str(path))


def _pool(workers: int):
    if workers == 0:
        return None
    from ..sweep import process_pool

    return process_pool(workers, preload=("contactdyn.identify.model", "contactdyn.simulate"))
