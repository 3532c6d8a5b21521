"""Uncertainty at the optimum: standard errors, 95 % intervals, correlations, and what is not determined.

Linearised least squares: with J the Jacobian of the weighted residuals in solver
coordinates, cov(z) = s² (JᵀJ)⁻¹, s² = Σr²/(m − n) (the reduced χ², ≈ 1 when the model
fits and the noise levels are right; scaling by it keeps the intervals honest when an
estimated noise level is off). Directions of JᵀJ with no information (singular values
below 1e-10 of the largest) get an infinite variance. A log-scale parameter's interval is
exp(z ± t σ_z) (asymmetric in p), its standard error p σ_z (first order).

A parameter is reported as *not determined* when its 95 % interval is wider than its value,
when it is correlated above 0.99 with another, or when its variance is infinite.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .params import Parameter

__all__ = ["Estimate", "ChannelFit", "estimates", "channel_fits", "CORRELATION_LIMIT", "LEVEL"]

CORRELATION_LIMIT = 0.99  #: |correlation| above this: the pair is not separately determined
LEVEL = 0.95  #: confidence level of the intervals
POOR_FIT = 1.5  #: residual RMS above this many noise levels: the fitted run misses the channel
SINGULAR = 1e-10  #: singular values of J below this fraction of the largest carry no information


@dataclass(frozen=True)
class Estimate:
    key: str
    value: float  #: fitted value
    start: float  #: the scene's value
    se: float  #: standard error (inf: not determined at all)
    low: float  #: 95 % interval
    high: float
    log: bool  #: fitted on a log scale
    bounds: tuple[float, float]
    at_bound: bool
    warnings: tuple[str, ...]  #: why the value is not determined (empty: determined)

    @property
    def determined(self) -> bool:
        return not self.warnings


@dataclass(frozen=True)
class ChannelFit:
    name: str  #: data column
    samples: int
    sigma: float  #: noise level used as the weight
    sigma_source: str  #: "given" or "estimated"
    rms: float  #: residual RMS at the optimum, same unit

    @property
    def ratio(self) -> float:
        """RMS / σ: ≈ 1 when the model explains the data down to its noise."""
        return self.rms / self.sigma

    @property
    def warning(self) -> str:
        if self.ratio <= POOR_FIT:
            return ""
        return (f"the fitted run misses {self.name} by {self.ratio:.2g} noise levels: a local minimum (try --starts, "
                "--stages) or a model that cannot represent the data")


def covariance(J: np.ndarray, residuals: np.ndarray) -> tuple[np.ndarray, float, int]:
    """(cov of z, reduced χ², degrees of freedom)."""
    m, n = J.shape
    dof = max(m - n, 1)
    chi2_red = float(residuals @ residuals) / dof
    _, s, vt = np.linalg.svd(J, full_matrices=False)
    keep = s > SINGULAR * (s[0] if s.size else 0.0)
    cov = (vt[keep].T / s[keep] ** 2) @ vt[keep] * chi2_red
    lost = np.any(np.abs(vt[~keep]) > 1e-6, axis=0) if (~keep).any() else np.zeros(n, bool)
    cov[lost, :] = np.nan
    cov[:, lost] = np.nan
    cov[lost, lost] = np.inf
    return cov, chi2_red, dof


def estimates(params: list[Parameter], z: np.ndarray, J: np.ndarray, residuals: np.ndarray,
              at_bound: np.ndarray) -> tuple[list[Estimate], np.ndarray, float, int]:
    """(estimates, correlation matrix, reduced χ², degrees of freedom)."""
    from scipy.stats import t as student

    cov, chi2_red, dof = covariance(J, residuals)
    sd = np.sqrt(np.diag(cov))
    with np.errstate(invalid="ignore", divide="ignore"):
        corr = cov / np.outer(sd, sd)
    np.fill_diagonal(corr, 1.0)
    q = float(student.ppf(0.5 + LEVEL / 2, dof))
    out = []
    for i, p in enumerate(params):
        value = p.value(float(z[i]))
        if p.log:
            se = value * sd[i]
            low, high = (_exp(z[i] - q * sd[i]), _exp(z[i] + q * sd[i])) if math.isfinite(sd[i]) else (0.0, math.inf)
        else:
            se = sd[i]
            low, high = value - q * sd[i], value + q * sd[i]
        warnings = _warnings(params, i, value, low, high, corr, bool(at_bound[i]))
        out.append(Estimate(p.key, value, p.start, float(se), float(low), float(high), p.log, (p.low, p.high),
                            bool(at_bound[i]), tuple(warnings)))
    return out, corr, chi2_red, dof


def _exp(x: float) -> float:
    """exp without overflow (a huge interval is infinite)."""
    return math.exp(x) if x < 700.0 else math.inf


def _warnings(params: list[Parameter], i: int, value: float, low: float, high: float, corr: np.ndarray,
              at_bound: bool) -> list[str]:
    out = []
    if not math.isfinite(high - low):
        out.append("not determined: the data carry no information on it (its runs do not change the channels)")
    elif high - low > abs(value):
        out.append(f"not determined: its 95 % interval [{low:.4g}, {high:.4g}] is wider than its value {value:.4g}")
    for j, other in enumerate(params):
        if j != i and math.isfinite(corr[i, j]) and abs(corr[i, j]) > CORRELATION_LIMIT:
            out.append(f"not determined separately from {other.key} (correlation {corr[i, j]:+.4f}): the data "
                       "fix a combination of the two; its interval holds only as far as the model is exact")
    if at_bound:
        out.append(f"not determined: it ended on a bound [{params[i].low:g}, {params[i].high:g}] (the interval "
                   "assumes an inner optimum)")
    return out


def channel_fits(model, residuals: np.ndarray) -> list[ChannelFit]:
    """Residual RMS per data column (the weighted residuals times σ)."""
    out, k = [], 0
    for c in model.data.columns:
        r = residuals[k:k + c.y.size] * c.sigma
        k += c.y.size
        out.append(ChannelFit(c.name, int(c.y.size), c.sigma, c.sigma_source, float(np.sqrt(np.mean(r * r)))))
    return out
