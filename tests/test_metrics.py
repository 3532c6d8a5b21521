"""Key metrics of a Result, on hand-made channels with known answers."""

from __future__ import annotations

import math

import numpy as np
import pytest

from contactdyn.output.metrics import CONTACT_METRICS, metrics
from contactdyn.output.result import Result


def _result() -> Result:
    t = np.linspace(0.0, 0.4, 5)
    tip = np.zeros((5, 3))
    tip_ref = np.array([[np.nan] * 3, [0.3, 0.4, 0.0], [0.0, 0.0, 0.0], [0.0, 0.0, 0.0], [0.0, 0.0, 0.0]])
    channels = {
        "t": t, "tip": tip, "tip_ref": tip_ref,
        "contact.a.F_n": np.array([0.0, 10.0, 30.0, 20.0, 25.0]),
        "contact.a.F_d": np.array([np.nan, np.nan, 20.0, 20.0, 20.0]),  # errors 10, 0, 5
        "contact.b.F_n": np.array([0.0, 0.0, 0.0, 0.0, -1.0]),
        "contact.b.F_d": np.full(5, np.nan),
        "stage.a.n.env1.x": np.array([0.0, -0.002, 0.001, 0.0, 0.0]),
        "stage.a.t1.rob1.x": np.array([0.0, 0.0, 0.0, 0.003, 0.0]),
        "stage.a.n.env1.F": np.array([0.0, 99.0, 0.0, 0.0, 0.0]),  # a force, not a deformation
    }
    impacts = [{"t": 0.1, "contact": "a", "normal_impulse": 2.0, "friction_impulse": [0.3, 0.4]},
               {"t": 0.3, "contact": "a", "normal_impulse": 0.5, "friction_impulse": [0.0, 0.0]}]
    return Result(channels, events=[{}] * 3, impacts=impacts, stats={"events": 3},
                  meta={"contacts": ["a", "b"]})


def test_metrics_closed_forms():
    m = metrics(_result())
    assert m["contact.a.F_peak"] == 30.0 and m["contact.a.F_final"] == 25.0
    assert m["contact.a.impacts"] == 2.0
    assert m["contact.a.impulse_n"] == 2.5 and m["contact.a.impulse_n_first"] == 2.0
    assert m["contact.a.impulse_t"] == pytest.approx(0.5, abs=1e-15)  # |(0.3, 0.4)| + 0
    assert m["contact.a.force_rms"] == pytest.approx(math.sqrt((100 + 0 + 25) / 3), rel=1e-15)
    assert m["tracking_rms"] == pytest.approx(math.sqrt(0.25 / 4), rel=1e-15)  # |(0.3, 0.4)| = 0.5 once in 4
    assert m["max_deformation"] == 0.003
    assert m["events"] == 3.0


def test_undefined_metrics_are_nan():
    m = metrics(_result())
    assert m["contact.b.impacts"] == 0.0 and m["contact.b.impulse_n"] == 0.0
    assert math.isnan(m["contact.b.impulse_n_first"]) and math.isnan(m["contact.b.force_rms"])
    assert set(CONTACT_METRICS) == {k.split(".", 2)[2] for k in m if k.startswith("contact.b.")}
    r = _result()
    for k in [k for k in r.channels if k.startswith(("stage.", "tip_ref"))]:
        del r.channels[k]
    m = metrics(r)
    assert math.isnan(m["tracking_rms"]) and math.isnan(m["max_deformation"])


def test_every_metric_has_its_unit():
    from contactdyn.output.metrics import CONTACT_METRICS, RUN_METRICS, UNITS

    assert set(UNITS) == set(CONTACT_METRICS) | set(RUN_METRICS)
    assert UNITS["F_peak"] == "N" and UNITS["impulse_n"] == "N·s" and UNITS["events"] == ""
