"""Bounded non-linear least squares on full simulations, from one or several starts.

scipy's trust-region-reflective ``least_squares`` moves the solver coordinates z (ln p for
log-scale parameters) within their bounds. Its Jacobian is built here by forward
differences, all columns' runs at once on the process pool; a step that would leave the
bounds, or whose run fails, is taken backwards instead. A trial point whose run fails gets
non-finite residuals, which makes the solver shrink its trust region and try closer in.

Continuation in time (``stages``): an oscillation fitted over many periods has a cost with
a local minimum every period of phase error, so a start 20 % off in frequency is lost. The
fit therefore first matches the first 1/2^(stages−1) of the log (a few periods, simulated
only that long), then doubles the window, each stage starting where the last ended.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..errors import ContactdynError
from .model import FitModel

__all__ = ["StartOutcome", "Stage", "Solution", "solve", "solve_in_stages", "start_points", "FD_STEP"]

FD_STEP = 1e-4  #: forward-difference step in solver coordinates, times the parameter's x_scale
MAX_RUNS_PER_START = 60  #: residual evaluations (not counting Jacobian runs) per start
MIN_STAGE_SAMPLES = 20  #: a continuation stage with fewer data samples is skipped


@dataclass(frozen=True)
class StartOutcome:
    start: dict[str, float]  #: starting values
    cost: float  #: ½ Σ r² at its end (inf: failed)
    values: dict[str, float]  #: where it ended
    evaluations: int  #: residual evaluations
    status: str  #: the solver's message, or why the start failed


@dataclass(frozen=True)
class Stage:
    """One continuation stage: the log up to ``window`` [s] (None: all of it, the scene's duration)."""

    window: float | None
    samples: int
    cost: float
    values: dict[str, float]
    runs: int  #: simulations in this stage (residuals and Jacobians)


@dataclass(frozen=True)
class Solution:
    z: np.ndarray  #: best solver coordinates
    residuals: np.ndarray  #: weighted residuals there
    jacobian: np.ndarray  #: d residuals / dz there
    at_bound: np.ndarray  #: bool per parameter: ended on a bound
    starts: list[StartOutcome]
    stages: tuple[Stage, ...] = ()


class _StartFailed(ContactdynError):
    pass


def start_points(model: FitModel, starts: int, seed: int) -> list[np.ndarray]:
    """The scene's values, then ``starts - 1`` points drawn uniformly (in solver coordinates) in the bounds."""
    rng = np.random.default_rng(seed)
    first = np.array([p.internal(p.start) for p in model.params])
    points = [first]
    for _ in range(starts - 1):
        z = []
        for p, z0 in zip(model.params, first, strict=True):
            lo, hi = p.internal_bounds
            lo = lo if math.isfinite(lo) else z0 - 2.0 * p.scale
            hi = hi if math.isfinite(hi) else z0 + 2.0 * p.scale
            z.append(rng.uniform(lo, hi))
        points.append(np.array(z))
    return points


def solve(model: FitModel, starts: list[np.ndarray], max_runs: int = MAX_RUNS_PER_START) -> Solution:
    """Run the solver from each start; the lowest cost wins. Raises if every start failed."""
    best: tuple[float, np.ndarray, np.ndarray, np.ndarray, np.ndarray] | None = None
    outcomes = []
    for z0 in starts:
        try:
            res = _solve_one(model, z0, max_runs)
        except _StartFailed as exc:
            outcomes.append(StartOutcome(model.values(z0), math.inf, model.values(z0), 0, str(exc)))
            continue
        outcomes.append(StartOutcome(model.values(z0), float(res.cost), model.values(res.x), int(res.nfev),
                                     str(res.message)))
        if best is None or res.cost < best[0]:
            best = (float(res.cost), res.x, res.fun, res.jac, res.active_mask != 0)
    if best is None:
        details = "; ".join(f"start {o.start}: {o.status}" for o in outcomes)
        raise ContactdynError(f"the fit failed from every start ({details})")
    _, z, r, J, at_bound = best
    return Solution(z, r, np.asarray(J), at_bound, outcomes)


def solve_in_stages(model: FitModel, starts: list[np.ndarray], stages: int,
                    max_runs: int = MAX_RUNS_PER_START) -> Solution:
    """:func:`solve` on growing windows of the log; the starts compete in the first stage."""
    full = model.data
    done: list[Stage] = []
    first: Solution | None = None
    solution: Solution | None = None
    try:
        for k in range(stages):
            last = k == stages - 1
            window = full.t_max * 0.5 ** (stages - 1 - k)
            model.data, model.duration = (full, None) if last else (full.until(window), window)
            if not last and model.data.samples < MIN_STAGE_SAMPLES:
                continue
            runs0 = model.runs
            solution = solve(model, starts if first is None else [solution.z], max_runs)  # type: ignore[union-attr]
            first = first or solution
            done.append(Stage(None if last else window, model.data.samples, float(solution.residuals @
                              solution.residuals) / 2, model.values(solution.z), model.runs - runs0))
    finally:
        model.data, model.duration = full, None
    assert solution is not None and first is not None
    return Solution(solution.z, solution.residuals, solution.jacobian, solution.at_bound, first.starts, tuple(done))


def _solve_one(model: FitModel, z0: np.ndarray, max_runs: int):
    from scipy.optimize import least_squares

    lo = np.array([p.internal_bounds[0] for p in model.params])
    hi = np.array([p.internal_bounds[1] for p in model.params])
    scale = np.array([p.scale for p in model.params])
    z0 = np.clip(z0, lo + 1e-12 * scale, hi - 1e-12 * scale)  # least_squares wants a strictly inner start
    seen: dict[bytes, np.ndarray] = {}

    def fun(z: np.ndarray) -> np.ndarray:
        r = model.evaluate([z])[0]
        if r is None:
            if not seen:
                raise _StartFailed(f"the run at the start failed: {model.failures[-1].error}")
            return np.full(next(iter(seen.values())).shape, np.nan)
        seen[z.tobytes()] = r
        return r

    def jac(z: np.ndarray, *_) -> np.ndarray:
        return _jacobian(model, z, seen[z.tobytes()], lo, hi, FD_STEP * scale)

    return least_squares(fun, z0, jac=jac, bounds=(lo, hi), x_scale=scale, method="trf", max_nfev=max_runs)


def _jacobian(model: FitModel, z: np.ndarray, r0: np.ndarray, lo: np.ndarray, hi: np.ndarray,
              steps: np.ndarray) -> np.ndarray:
    """Forward differences, every column's run at once; backwards where forward leaves the bounds or fails."""
    n = len(z)
    h = np.where(z + steps <= hi, steps, -steps)
    J = np.empty((r0.size, n))
    pending = list(range(n))
    for _ in range(2):  # forward, then backward for the failed columns
        points = []
        for i in pending:
            zi = z.copy()
            zi[i] += h[i]
            points.append(zi)
        outs = model.evaluate(points)
        retry = []
        for i, r in zip(pending, outs, strict=True):
            if r is None:
                retry.append(i)
            else:
                J[:, i] = (r - r0) / h[i]
        if not retry:
            return J
        h[retry] = -h[retry]
        pending = retry
    keys = ", ".join(model.params[i].key for i in pending)
    raise _StartFailed(f"runs near {model.values(z)} failed both ways along {keys}: {model.failures[-1].error}")
