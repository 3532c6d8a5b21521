"""Test helpers that hold the compiled call to a reference: two whole runs of one scene (the compiled call's against
the same call interpreted, its Python source) and the readable model's output samples (``dynamics.evaluate``, the
tests' independent reference while it lasts)."""

from __future__ import annotations

import numpy as np

from contactdyn.model.dynamics import evaluate as readable_evaluate
from contactdyn.model.paths import INTERPRETED, PIPELINE
from contactdyn.output.samples import Samples

RUN_RTOL = 1e-9  #: each channel to RUN_RTOL of its largest magnitude (plus 1e-12 in SI units)
EVENT_ATOL = 1e-9  #: [s] the events' times


def assert_runs_agree(fast, interpreted) -> None:
    """Every mode of ``fast`` on the compiled call, of ``interpreted`` on the same call interpreted (a run with
    ``LivePipelines.use`` off); the same channels and events (RUN_RTOL; the events' times to EVENT_ATOL)."""
    assert {row["path"] for row in fast.stats["paths"].values()} == {PIPELINE}, fast.stats["paths"]
    assert {row["path"] for row in interpreted.stats["paths"].values()} == {INTERPRETED}
    assert set(fast.channels) == set(interpreted.channels)
    for key, ref in interpreted.channels.items():
        ref, got = np.asarray(ref, float), np.asarray(fast.channels[key], float)
        if ref.size and not np.all(np.isnan(ref)):
            assert float(np.nanmax(np.abs(got - ref))) <= RUN_RTOL * float(np.nanmax(np.abs(ref))) + 1e-12, key
    assert [(e["kind"], e["name"]) for e in fast.events] == [(e["kind"], e["name"]) for e in interpreted.events]
    np.testing.assert_allclose([e["t"] for e in fast.events], [e["t"] for e in interpreted.events], rtol=0,
                               atol=EVENT_ATOL)


def readable_samples(system, ts: np.ndarray, X: np.ndarray, modes, phase) -> Samples:
    """The output samples at the states X[k] (times ts[k]) from the readable model, one evaluation each."""
    S = Samples(len(ts), system)
    for k, (t, x) in enumerate(zip(ts, X, strict=True)):
        _fill(S, k, readable_evaluate(system, t, x, modes, phase, full=True))
    return S


def _fill(S: Samples, k: int, ev) -> None:
    """Row k of S from a full readable Evaluation."""
    S.tau[k], S.tau_cmd[k], S.u[k], S.tip[k], S.body_force[k] = ev.tau, ev.tau_cmd, ev.u, ev.p_tip, ev.body_force
    for i, value in ev.limit_torque.items():
        S.limit_torque[k, i] = value
    if ev.joint_friction is not None:
        S.joint_friction[k] = ev.joint_friction
    if ev.x_d is not None and len(ev.x_d) == 3:
        S.x_d[k], S.has_x_d = ev.x_d, True
    for key, value in ev.force_d.items():
        S.F_d[key][k], S.has_F_d[key] = value, True
    for name in S.F_n:
        S.F_n[name][k], S.gap[name][k] = ev.normal_force[name], ev.gap[name]
        if name in ev.friction:
            S.F_f[name][k] = ev.friction[name]
        if name in ev.slip:
            S.v_slip[name][k] = ev.slip[name]
    for key in S.iface:
        S.iface[key][k] = ev.interface.get(key, 0.0)
    for label in S.stages:
        S.stages[label][k] = ev.stages.get(label, (0.0, 0.0, 0.0))
