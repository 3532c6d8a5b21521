"""Key metrics of a run, one flat row per :class:`~contactdyn.output.result.Result`.

Used by sweeps (one summary row per run) and by ``contactdyn run --json``. Every metric is
a plain float (NaN where it is not defined, e.g. a force error without a force
set-point), so rows of different runs stack into one table. Names and units:

========================================  ======  ==============================================
``contact.<c>.F_peak``                    N       largest normal contact force
``contact.<c>.F_final``                   N       normal contact force at the last sample
``contact.<c>.impacts``                   -       number of impacts (plastic, at touch)
``contact.<c>.impulse_n``                 N·s     sum of the normal impulses FΔt of its impacts
``contact.<c>.impulse_n_first``           N·s     normal impulse of the first impact
``contact.<c>.impulse_t``                 N·s     sum of the friction impulse magnitudes |F_fΔt|
``contact.<c>.force_rms``                 N       RMS of F_n − F_d over the samples with a set-point
``tracking_rms``                          m       RMS of |tip − tip_ref| over the samples with a reference
``max_deformation``                       m       largest |x| over every deformation stage
``events``                                -       number of mode-switch events
``contact.<c>.<check>``                   *       a physics check's value (:mod:`~contactdyn.output.physics_checks`:
                                                  ``cone_excess`` [N], ``pull`` [N], ``drift`` [m]...),
                                                  NaN where it does not apply to the contact
``energy_residual``                       J       the energy audit's residual (NaN without one)
``check_violations``                      -       number of checks above their tolerance
``warnings``                              -       number of sanity and outcome warnings (a set-point that
                                                  never touched, a touch that never came...)
========================================  ======  ==============================================

RMS values weigh the samples equally (``solver.output_rate`` is uniform).
"""

from __future__ import annotations

import math

import numpy as np

from .physics_checks import CHECKS
from .physics_checks import UNITS as CHECK_UNITS
from .result import Result

__all__ = ["metrics", "is_metric", "CONTACT_METRICS", "RUN_METRICS", "UNITS"]

#: metric suffixes under ``contact.<name>.``
CONTACT_CHECKS = tuple(name for name in CHECKS if name != "energy_residual")  #: the physics checks per contact
CONTACT_METRICS = ("F_peak", "F_final", "impacts", "impulse_n", "impulse_n_first", "impulse_t", "force_rms",
                   *CONTACT_CHECKS)
#: metrics of the whole run
RUN_METRICS = ("tracking_rms", "max_deformation", "events", "energy_residual", "check_violations", "warnings")
#: unit of each metric (by its last name part; "" : a count), as in the table above
UNITS = {"F_peak": "N", "F_final": "N", "impacts": "", "impulse_n": "N·s", "impulse_n_first": "N·s",
         "impulse_t": "N·s", "force_rms": "N", "tracking_rms": "m", "max_deformation": "m", "events": "",
         **CHECK_UNITS, "check_violations": "", "warnings": ""}


def is_metric(name: str) -> bool:
    """Whether a column name is one of the metrics (not a scene key)."""
    parts = name.split(".")
    return name in RUN_METRICS or (len(parts) == 3 and parts[0] == "contact" and parts[2] in CONTACT_METRICS)


def metrics(result: Result) -> dict[str, float]:
    """The key metrics of ``result`` as ``{name: value}`` (see the module docstring)."""
    out: dict[str, float] = {}
    ch = result.channels
    for name in result.meta.get("contacts", []):
        p = f"contact.{name}"
        F = np.asarray(ch[f"{p}.F_n"], float)
        out[f"{p}.F_peak"] = float(np.max(F)) if F.size else math.nan  # [N]
        out[f"{p}.F_final"] = float(F[-1]) if F.size else math.nan  # [N]
        hits = [imp for imp in result.impacts if imp.get("contact") == name]
        out[f"{p}.impacts"] = float(len(hits))
        out[f"{p}.impulse_n"] = float(sum(imp["normal_impulse"] for imp in hits))  # [N·s]
        out[f"{p}.impulse_n_first"] = float(hits[0]["normal_impulse"]) if hits else math.nan  # [N·s]
        out[f"{p}.impulse_t"] = float(sum(np.linalg.norm(np.asarray(imp.get("friction_impulse", []), float))
                                          for imp in hits))  # [N·s]
        F_d = np.asarray(ch.get(f"{p}.F_d", np.full_like(F, np.nan)), float)
        out[f"{p}.force_rms"] = _rms((F - F_d)[np.isfinite(F_d)])  # [N]
        checks = result.meta.get("checks", {}).get("contacts", {}).get(name, {})
        for check in CONTACT_CHECKS:
            out[f"{p}.{check}"] = float(checks[check]["value"]) if check in checks else math.nan
    if "tip_ref" in ch:
        err = np.asarray(ch["tip"], float) - np.asarray(ch["tip_ref"], float)
        rows = np.all(np.isfinite(err), axis=1)
        out["tracking_rms"] = _rms(np.linalg.norm(err[rows], axis=1))  # [m]
    else:
        out["tracking_rms"] = math.nan
    stages = [np.abs(np.asarray(v, float)) for k, v in ch.items() if k.startswith("stage.") and k.endswith(".x")]
    out["max_deformation"] = float(max(np.max(s) for s in stages if s.size)) if any(s.size for s in stages) \
        else math.nan  # [m]
    out["events"] = float(result.stats.get("events", len(result.events)))
    energy = result.meta.get("checks", {}).get("energy_residual")
    out["energy_residual"] = float(energy["value"]) if energy and energy["value"] is not None else math.nan  # [J]
    out["check_violations"] = float(len(result.meta.get("check_warnings", [])))
    out["warnings"] = float(len(result.meta.get("warnings", [])))  # sanity and outcome (contactdyn.output.outcome)
    return out


def _rms(values: np.ndarray) -> float:
    return float(np.sqrt(np.mean(np.square(values)))) if values.size else math.nan
