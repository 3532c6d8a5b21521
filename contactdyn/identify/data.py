"""The measured log: a CSV with a time column ``t`` [s] and one column per measured channel.

A column is named like a run's channel (``contact.tip.F_n``) or a component of a vector
channel (``tip[0]``, ``q[1]``). Columns may have gaps (empty cells or ``nan``); each keeps
only its own valid samples. The noise level of a column is given or estimated from the
data (:func:`estimate_noise`).
"""

from __future__ import annotations

import csv
import math
import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import SceneError

__all__ = ["Column", "Measurements", "read_csv", "measurements", "estimate_noise", "split_column", "NOISE_ORDER"]

NOISE_ORDER = 3  #: order of the differences that estimate the noise (the signal's share falls as (ω Δt)^order)
MIN_SAMPLES = NOISE_ORDER + 3  #: valid samples a column needs for a noise estimate
_COMPONENT = re.compile(r"^(?P<channel>[^\[\]]+)\[(?P<index>\d+)\]$")


@dataclass(frozen=True)
class Column:
    """One measured quantity: its valid samples and its noise level."""

    name: str  #: as in the CSV header, e.g. ``tip[0]``
    channel: str  #: the run's channel, e.g. ``tip``
    index: int | None  #: component of a vector channel (None: a scalar channel)
    t: np.ndarray  #: [s] times of the valid samples
    y: np.ndarray  #: measured values, in the channel's unit
    sigma: float  #: noise standard deviation, in the channel's unit
    sigma_source: str  #: "given" or "estimated"


@dataclass(frozen=True)
class Measurements:
    file: str
    columns: tuple[Column, ...]

    @property
    def t_max(self) -> float:
        """[s] the last sample time of any column."""
        return max(float(c.t[-1]) for c in self.columns)

    def until(self, t_end: float) -> Measurements:
        """The samples at t <= t_end [s] (columns left without samples are dropped)."""
        cols = [Column(c.name, c.channel, c.index, c.t[c.t <= t_end], c.y[c.t <= t_end], c.sigma, c.sigma_source)
                for c in self.columns]
        return Measurements(self.file, tuple(c for c in cols if c.t.size))

    @property
    def samples(self) -> int:
        return sum(c.t.size for c in self.columns)

    def sample_spacing(self) -> float:
        """[s] the median spacing of consecutive valid samples over all columns."""
        gaps = np.concatenate([np.diff(c.t) for c in self.columns])
        gaps = gaps[gaps > 0]
        return float(np.median(gaps)) if gaps.size else math.inf


def split_column(name: str) -> tuple[str, int | None]:
    """``tip[0]`` -> ("tip", 0); ``contact.tip.F_n`` -> ("contact.tip.F_n", None)."""
    m = _COMPONENT.match(name.strip())
    return (m["channel"], int(m["index"])) if m else (name.strip(), None)


def read_csv(path: str | Path) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    """(t [s], {column: values}) of a CSV log; empty cells are NaN; errors name the row and column."""
    path = Path(path)
    file = str(path)
    if path.exists() and not path.is_file():  # a FIFO or a device would block or never end
        raise SceneError("--data", "a regular CSV file", "a FIFO, device or folder", file)
    try:
        with path.open(newline="") as f:
            rows = list(csv.reader(f))
    except (OSError, UnicodeDecodeError) as exc:
        raise SceneError("--data", "a readable CSV file", getattr(exc, "strerror", None) or str(exc), file) from None
    except csv.Error as exc:
        raise SceneError("--data", "a CSV file", str(exc), file) from None
    rows = [r for r in rows if any(cell.strip() for cell in r)]
    if not rows:
        raise SceneError("--data", "a CSV file with a header row (t, channel columns)", "an empty file", file)
    header = [h.strip() for h in rows[0]]
    if "t" not in header:
        raise SceneError("t", "a time column named t [s] in the header", header, file)
    if len(set(header)) != len(header) or "" in header:
        raise SceneError("<header>", "distinct, non-empty column names", header, file)
    if len(header) < 2:
        raise SceneError("<header>", "t and at least one measured column", header, file)
    values = np.full((len(rows) - 1, len(header)), np.nan)
    for i, row in enumerate(rows[1:], start=2):
        if len(row) != len(header):
            raise SceneError(f"row {i}", f"{len(header)} cells like the header", f"{len(row)} cells", file)
        for j, cell in enumerate(row):
            values[i - 2, j] = _number(cell, header[j], i, file)
    t = values[:, header.index("t")]
    if t.size == 0:
        raise SceneError("t", "at least one data row", "only the header", file)
    bad = np.flatnonzero(~np.isfinite(t))
    if bad.size:
        raise SceneError("t", "a time [s] in every row", f"an empty or non-finite time in row {bad[0] + 2}", file)
    back = np.flatnonzero(np.diff(t) <= 0)
    if back.size:
        raise SceneError("t", "strictly increasing times [s]",
                         f"{t[back[0] + 1]:.9g} after {t[back[0]]:.9g} in row {back[0] + 3}", file)
    return t, {h: values[:, j] for j, h in enumerate(header) if h != "t"}


def _number(cell: str, column: str, row: int, file: str) -> float:
    text = cell.strip()
    if not text:
        return math.nan
    try:
        return float(text)
    except ValueError:
        raise SceneError(column, "a number or an empty cell", f"{text!r} in row {row}", file) from None


def estimate_noise(y: np.ndarray) -> float:
    """Noise standard deviation of a sampled smooth signal from its differences.

    The ``NOISE_ORDER``-th differences of consecutive samples remove a smooth signal (its
    share falls like (ω Δt)^order) and leave white noise with variance C(2k, k) σ²; the
    median absolute deviation makes kinks (impacts, steps) harmless.
    """
    d = np.diff(y, n=NOISE_ORDER)
    mad = float(np.median(np.abs(d - np.median(d))))
    return 1.482602218505602 * mad / math.sqrt(math.comb(2 * NOISE_ORDER, NOISE_ORDER))


def measurements(path: str | Path, noise: dict[str, float] | None = None, duration: float | None = None
                 ) -> Measurements:
    """Read and check a log; ``noise`` gives σ for some columns (the others are estimated)."""
    file = str(path)
    t, raw = read_csv(path)
    noise = dict(noise or {})
    for name in noise:
        if name not in raw:
            raise SceneError("--noise", f"a column of the data ({', '.join(raw)})", name, file)
    if duration is not None:
        _check_times(t, raw, duration, file)
    columns = []
    for name, y in raw.items():
        ok = np.isfinite(y)
        channel, index = split_column(name)
        if not ok.any():
            raise SceneError(name, "at least one number in the column", "no valid sample", file)
        if name in noise:
            sigma, source = float(noise[name]), "given"
            if not (math.isfinite(sigma) and sigma > 0):
                raise SceneError(f"--noise {name}", "a noise level > 0", noise[name], file)
        else:
            if ok.sum() < MIN_SAMPLES:
                raise SceneError(name, f"at least {MIN_SAMPLES} valid samples to estimate its noise "
                                 "(or give it: --noise COLUMN=SIGMA)", int(ok.sum()), file)
            sigma, source = estimate_noise(y[ok]), "estimated"
            if not sigma > 0:
                raise SceneError(name, "noisy samples to estimate the noise level from "
                                 "(or give it: --noise COLUMN=SIGMA)", "a noise estimate of 0", file)
        columns.append(Column(name, channel, index, t[ok], y[ok], sigma, source))
    return Measurements(file, tuple(columns))


def _check_times(t: np.ndarray, raw: dict[str, np.ndarray], duration: float, file: str) -> None:
    """Every valid sample must lie inside the simulated interval [0, duration]."""
    slack = 1e-9 * max(1.0, duration)
    for name, y in raw.items():
        outside = np.flatnonzero(np.isfinite(y) & ((t < -slack) | (t > duration + slack)))
        if outside.size:
            i = outside[0]
            raise SceneError(name, f"samples within the scene's duration [0, {duration:g}] s "
                             "(shorten the log or set duration)", f"t = {t[i]:.9g} s in row {i + 2}", file)
