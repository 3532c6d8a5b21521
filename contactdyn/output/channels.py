"""A run's output: the integrated segments sampled on the output grid, as named channels.

The hybrid loop (:mod:`contactdyn.hybrid.loop`) leaves a list of :class:`Segment` s, each a
smooth phase with its dense output. The output grid has ``solver.output_rate`` [Hz]
samples over the duration; at an event time the sample belongs to the segment after the
event (at the run's end too: an event there leaves a zero-length segment holding its modes).
A compiled segment gives its samples' diagnostics all at once
(:meth:`~contactdyn.hybrid.pipeline_mode.PipelineMode.samples`); another evaluates each sample fully.
Channel names and units are documented in the README (``q`` [rad or m], ``contact.<c>.F_n``
[N], ``stage.<label>.x`` [m]…).
"""

from __future__ import annotations

from dataclasses import dataclass
from itertools import groupby
from typing import Any

import numpy as np

from ..laws.controllers.sampled import SampledController
from ..laws.drives import drive_channels
from ..model.contact import ContactMode
from ..model.joint_friction import joint_friction_channels
from ..model.limits import limit_channels
from ..model.phases import Phase
from ..model.system import System
from ..numerics.dop853 import DenseSolution, dense_states
from ..numerics.held_steps import PiecewiseDense
from ..robot.free_chart import chart_a_angles
from ..robot.urdf_model import FREE_COORDINATES
from .samples import Samples

__all__ = ["Segment", "Held", "output_grid", "sample_segments", "sample_states", "channels"]


@dataclass
class Segment:
    """One smooth phase of a run: [t0, t1] [s], its modes and task phase, dense output, and what ran it (its mode's
    pipeline, :class:`~contactdyn.hybrid.pipeline_mode.PipelineMode`)."""

    t0: float
    t1: float
    modes: list[ContactMode]
    phase: Phase
    sol: Any
    runner: Any  #: what ran it: the one pipeline's mode (PipelineMode)


class Held:
    """The dense output of a zero-length segment: the state x held (the modes an event at the run's end set)."""

    def __init__(self, x: np.ndarray):
        self.x = np.asarray(x, float).copy()

    def __call__(self, t):
        return self.x.copy() if np.ndim(t) == 0 else np.repeat(self.x[:, None], len(t), axis=1)


def output_grid(duration: float, rate: float) -> np.ndarray:
    """Output times [s]: ``rate`` [Hz] samples over [0, duration], at least the two ends."""
    n_out = int(round(duration * rate))
    return np.linspace(0.0, duration, n_out + 1) if n_out > 0 else np.array([0.0, duration])


def sample_segments(system: System, segments: list[Segment], grid: np.ndarray, stats: dict[str, Any]
                    ) -> dict[str, np.ndarray]:
    """The channels of a run at the times ``grid`` (adds the compiled modes' singular solves to ``stats``)."""
    return sample_states(system, segments, grid, stats)[0]


def sample_states(system: System, segments: list[Segment], grid: np.ndarray, stats: dict[str, Any]
                  ) -> tuple[dict[str, np.ndarray], np.ndarray]:
    """The channels of a run at the times ``grid`` (increasing) and its states there, (len(grid), n)."""
    # the segment of each sample: the last starting at or before it (at an event time, the one after)
    t0 = np.array([seg.t0 for seg in segments])
    idx = np.maximum(np.searchsorted(t0, grid, side="right") - 1, 0)
    bounds = np.searchsorted(idx, np.arange(len(segments) + 1)).tolist()  # segment i's samples: bounds[i]:bounds[i + 1]
    xs = np.empty((len(grid), system.n))
    runs = _same_mode_runs(segments, sorted(set(idx.tolist())))  # segments split at corners: one batch
    modes_of: list[list[ContactMode]] = []
    phases_of: list[Phase] = []
    for run in runs:
        seg, n = segments[run[0]], bounds[run[-1] + 1] - bounds[run[0]]
        modes_of += [seg.modes] * n
        phases_of += [seg.phase] * n
    parts: list[Samples] = []
    rows: list[np.ndarray] = []
    counted: list = []
    for group in _mode_groups(segments, runs):  # the runs of one compiled mode, wherever they are: one batch
        seg = segments[group[0][0]]
        at = [np.arange(bounds[run[0]], bounds[run[-1] + 1]) for run in group]
        seg.runner.use(seg.modes)  # the interpolants' extra stages all at once
        derivatives = getattr(seg.runner.rhs, "derivatives", None)
        rest = group
        if seg.runner not in counted:  # one serves several modes (every turn): count it once,
            _run_states(segments, group[0], bounds, grid, xs, derivatives)  # after its first run's states
            counted.append(seg.runner)
            stats["singular_solves"] += seg.runner.singular
            stats["holds_split"] += seg.runner.holds_split
            rest = group[1:]
        _run_states(segments, [i for run in rest for i in run], bounds, grid, xs, derivatives)
        at_all = np.concatenate(at)
        # (it serves every turn: this group's r)
        parts.append(seg.runner.samples(grid[at_all], xs[at_all], seg.modes, runs=[len(a) for a in at]))
        rows.append(at_all)
    samples = parts[0] if len(parts) == 1 else Samples.scattered(parts, rows, system)
    out = channels(system, grid, xs, samples, modes_of)
    if system.limits.limits:
        out.update(limit_channels(system, phases_of, samples))
    if system.joint_friction.any:
        out.update(joint_friction_channels(system, phases_of, samples))
    out.update(drive_channels(system, xs, samples))
    if "tau_cmd" not in out and any(isinstance(c, SampledController) for c in system.controllers):
        out["tau_cmd"] = samples.tau_cmd  # a sampled law's held command (with motors: the drives' channel)
    return out, xs


def _same_mode_runs(segments: list[Segment], used: list[int]) -> list[list[int]]:
    """The used segments' indices in runs of consecutive segments on the same modes, phase and runner."""
    runs: list[list[int]] = []
    for i in used:
        seg = segments[i]
        if runs and runs[-1][-1] == i - 1 and _same_mode(segments[i - 1], seg):
            runs[-1].append(i)
        else:
            runs.append([i])
    return runs


def _run_states(segments: list[Segment], run: list[int], bounds: list[int], grid: np.ndarray, xs: np.ndarray,
                derivatives) -> None:
    """xs at the samples of a run of segments (segment i's: bounds[i]:bounds[i + 1] of ``grid``): the compiled
    DOP853's dense outputs (their pieces') all at once, their interpolants built in one batch (``derivatives``:
    the mode's right-hand side at many states, :func:`~contactdyn.hybrid.steps.derivatives`), others each alone."""
    dense: list[tuple[DenseSolution, np.ndarray]] = []
    where: list[np.ndarray] = []
    for i in run:
        at = np.arange(bounds[i], bounds[i + 1])
        sol = segments[i].sol
        if isinstance(sol, PiecewiseDense):
            for part, k in sol.split(grid[at]):
                dense.append((part, grid[at[k]]))
                where.append(at[k])
        elif isinstance(sol, DenseSolution):
            dense.append((sol, grid[at]))
            where.append(at)
        else:
            xs[at] = np.atleast_2d(sol(grid[at]).T) if len(at) > 1 else sol(grid[at[0]])
    for at, y in zip(where, dense_states(dense, derivatives), strict=True):
        xs[at] = y


def _mode_groups(segments: list[Segment], runs: list[list[int]]) -> list[list[list[int]]]:
    """The runs grouped by mode's pipeline and modes, groups in order of first appearance: a mode's samples and
    interpolants are its call's per state, whatever else is in the batch."""
    groups: list[list[list[int]]] = []
    of_mode: dict[tuple, list[list[int]]] = {}  # (runner, modes): its group
    for run in runs:
        seg = segments[run[0]]
        key = (seg.runner, tuple(seg.modes))
        if key in of_mode:
            of_mode[key].append(run)
        else:
            groups.append(of_mode.setdefault(key, [run]))
    return groups


def _same_mode(a: Segment, b: Segment) -> bool:
    return a.runner is b.runner and a.phase is b.phase and a.modes == b.modes


def channels(system: System, t: np.ndarray, xs: np.ndarray, smp: Samples,
             modes_of: list[list[ContactMode]]) -> dict[str, np.ndarray]:
    """The Result's named channels at the output times t [s] (names documented in the README)."""
    nQ, nv = system.nQ, system.nv
    ch: dict[str, np.ndarray] = {"t": t, "q": xs[:, :nv], "v": xs[:, nQ:nQ + nv], "tau": smp.tau, "tip": smp.tip}
    if smp.has_x_d:
        ch["tip_ref"] = smp.x_d
    for k, (name, idx) in enumerate(system.body_channels):  # per body coordinate
        ch[f"body.{name}.x"] = xs[:, idx]
        ch[f"body.{name}.v"] = xs[:, nQ + idx]
        ch[f"body.{name}.force"] = smp.body_force[:, k]
    ch.update(free_body_channels(system, xs))
    for i, c in enumerate(system.contacts):
        p = f"contact.{c.name}"
        ch[f"{p}.F_n"] = smp.F_n[c.name]
        ch[f"{p}.gap"] = smp.gap[c.name]
        ch[f"{p}.touching"] = _per_sample(modes_of, lambda m, i=i: m[i].touching)
        ch[f"{p}.F_d"] = smp.F_d[c.name]
        if c.friction is not None and len(c.tangents):
            ch[f"{p}.F_f"] = smp.F_f[c.name]
            ch[f"{p}.v_slip"] = smp.v_slip[c.name]
            ch[f"{p}.stuck"] = _per_sample(modes_of, lambda m, i=i: m[i].stuck)
        for dc in c.tangent_chains:
            ch[f"{p}.{dc.label}.F"] = smp.iface[f"{c.name}.{dc.label}"]
        for k in range(len(c.tangents)):
            key = f"{c.name}.t{k + 1}"
            if smp.has_F_d.get(key):
                ch[f"{p}.t{k + 1}.F_d"] = smp.F_d[key]
    for label in system.stage_labels:
        ch[f"stage.{label}.x"], ch[f"stage.{label}.xdot"], ch[f"stage.{label}.F"] = smp.stages[label].T
    k = 0
    for c in system.contacts:
        for dc in c.chains:
            for node in dc.chain.nodes:
                if node.coord >= 0:
                    label = system.mass_labels[k]
                    ch[f"mass.{label}.x"] = xs[:, node.coord]
                    ch[f"mass.{label}.v"] = xs[:, nQ + node.coord]
                    k += 1
    if system.energy_slot >= 0:
        ch["energy.work"] = xs[:, 2 * nQ + system.energy_slot]
        ch["energy.dissipated"] = xs[:, 2 * nQ + system.energy_slot + 1]
    return ch


def free_body_channels(system: System, xs: np.ndarray) -> dict[str, np.ndarray]:
    """A free body's angle channels in chart A whatever chart ran (:mod:`contactdyn.robot.free_chart`): yaw, pitch,
    roll [rad] of its world rotation (as integrated in chart A; from R in chart B, pitch in [−π/2, π/2]) and their
    rates [rad/s] (unbounded near pitch ±90°); and its angular velocity ω [rad/s] in the world, ``omega_x`` ...
    (chart-free); its chart, ``chart`` (0: A, 1: B). The angles' channels replace the coordinates' own."""
    nQ, out = system.nQ, {}
    for name, body in system.articulated.items():
        if not body.free:
            continue
        sl = slice(body.first + 3, body.first + 6)
        chart = xs[:, body.chart_index].astype(int)  # (ArticulatedBody.chart_of per sample: 0 A, 1 B)
        rows = [chart_a_angles(x[sl], x[nQ:][sl], c) for x, c in zip(xs, chart.tolist(), strict=True)]
        a, ad, w = (np.array([r[k] for r in rows]).reshape(len(xs), 3) for k in range(3))  # (none: (0, 3))
        for k, angle in enumerate(FREE_COORDINATES[3:]):  # its joints' names (urdf_model.add_free_joints)
            out[f"body.{name}.{angle}.x"], out[f"body.{name}.{angle}.v"] = a[:, k], ad[:, k]
        for k, axis in enumerate("xyz"):
            out[f"body.{name}.omega_{axis}"] = w[:, k]
        out[f"body.{name}.chart"] = chart.astype(float)
    return out


def _per_sample(modes_of: list[list[ContactMode]], value) -> np.ndarray:
    """float(value(modes)) per sample, evaluated once per run of samples sharing one modes list."""
    values, counts = [], []
    for _, run in groupby(modes_of, key=id):
        same = list(run)
        values.append(float(value(same[0])))
        counts.append(len(same))
    return np.repeat(np.array(values), counts)
