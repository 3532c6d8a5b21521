"""``contactdyn fit`` (contactdyn/identify/): recovery, uncertainty, failures, bad input.

Fast cases: B1 shortened to 0.1–0.2 s, one or two parameters. The full validation (2 s,
three parameters, 20 noise realisations, the closed-form model) is benchmarks/fit.py.
"""

from __future__ import annotations

import csv
import json
import math
import tomllib
from pathlib import Path

import numpy as np
import pytest

import contactdyn
from contactdyn.cli import main
from contactdyn.identify.data import estimate_noise
from contactdyn.identify.params import Parameter
from contactdyn.identify.solver import solve
from contactdyn.scene.scene_file import load_scene, sims_dir
from contactdyn.scene.toml_writer import dumps

K, M, MU, B = "contact.tip.normal.k", "contact.tip.normal.m", "contact.tip.tangent.mu", "contact.tip.normal.b"


def write_log(path: Path, overrides: dict, sigma: dict[str, float], seed: int = 0, duration: float = 0.1,
              every: int = 1) -> Path:
    """B1 run with ``overrides`` (tight tolerance), Gaussian noise σ per column, every ``every``-th sample."""
    r = contactdyn.simulate("b1", {**overrides, "duration": duration, "solver.rtol": 1e-11, "solver.atol": 1e-13})
    cols = {"contact.tip.F_n": r["contact.tip.F_n"], "tip[0]": r["tip"][:, 0], "tip[1]": r["tip"][:, 1]}
    rng = np.random.default_rng(seed)
    noisy = {k: v + rng.normal(0.0, sigma[k], v.size) for k, v in cols.items() if k in sigma}
    with path.open("w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["t", *noisy])
        for i in range(0, r.t.size, every):
            w.writerow([repr(float(r.t[i])), *(repr(float(v[i])) for v in noisy.values())])
    return path


SIGMA = {"contact.tip.F_n": 1.0, "tip[0]": 1e-3}  #: [N], [m]


@pytest.fixture(scope="module")
def log(tmp_path_factory) -> Path:
    """0.1 s of B1 with μ = 0.3 and k = 1.2e5 (the scene: 0.4, 1e5)."""
    return write_log(tmp_path_factory.mktemp("fit") / "log.csv", {MU: 0.3, K: 1.2e5}, SIGMA)


# ---- pieces --------------------------------------------------------------------------------
def test_noise_estimate_of_a_fast_sine_with_steps():
    """σ from third differences: a 15 Hz, 20 N sine sampled at 1 kHz with a step adds < 5 % to σ = 1."""
    rng = np.random.default_rng(3)
    t = np.arange(0, 2, 1e-3)
    signal = 100 + 20 * np.sin(2 * np.pi * 15 * t) + 30 * (t > 1)
    sigma = estimate_noise(signal + rng.normal(0, 1.0, t.size))
    assert sigma == pytest.approx(1.0, rel=0.05)
    assert estimate_noise(signal) < 0.02  # the signal alone reads as (almost) no noise


@pytest.mark.parametrize("path", sorted(sims_dir().glob("*.toml")), ids=lambda p: p.stem)
def test_toml_writer_round_trips_every_scene(path):
    doc = tomllib.loads(path.read_text())
    assert tomllib.loads(dumps(doc, "a header\nof two lines")) == doc


def test_log_scale_parameter_maps_both_ways():
    p = Parameter("k", 1e5, 1e2, 1e8, True)
    assert p.value(p.internal(3.7e4)) == pytest.approx(3.7e4, rel=1e-14)
    assert p.internal_bounds == pytest.approx((math.log(1e2), math.log(1e8)))


# ---- fits ------------------------------------------------------------------------------------
def test_fit_recovers_friction_and_stiffness_within_their_intervals(log, tmp_path):
    """CLI end to end: estimates within 2 % and their 95 % intervals, report files, fitted scene."""
    scene_out = tmp_path / "fitted.toml"
    code = main(["fit", "b1", "--set", "duration=0.1", "--data", str(log), "--params", f"{MU},{K}=1e4:1e7",
                 "--noise", "contact.tip.F_n=1.0", "--out", str(tmp_path / "rep"), "--save-scene", str(scene_out),
                 "--stages", "2", "--quiet"])
    assert code == 0
    doc = json.loads((tmp_path / "rep" / "fit.json").read_text())
    truth = {MU: 0.3, K: 1.2e5}
    for e in doc["estimates"]:
        assert e["value"] == pytest.approx(truth[e["key"]], rel=0.02)
        assert e["ci95"][0] <= truth[e["key"]] <= e["ci95"][1]
        assert e["determined"], e["warnings"]
    noise = {c["column"]: c for c in doc["channels"]}
    assert noise["contact.tip.F_n"]["noise_source"] == "given"
    assert noise["tip[0]"]["noise"] == pytest.approx(1e-3, rel=0.15)  # estimated from the data
    assert all(0.8 < c["rms_over_noise"] < 1.2 for c in doc["channels"])
    assert (tmp_path / "rep" / "fit.png").stat().st_size > 10_000
    assert "| `contact.tip.tangent.mu` |" in (tmp_path / "rep" / "fit.md").read_text()
    fitted = load_scene(scene_out)  # the saved scene is a valid scene with the fitted values
    values = {e["key"]: e["value"] for e in doc["estimates"]}
    assert fitted.contacts["tip"].friction.mu_k == pytest.approx(values[MU], rel=1e-12)
    assert fitted.document["contact"]["tip"]["normal"]["k"] == pytest.approx(values[K], rel=1e-12)


def test_unexcited_damping_is_reported_not_determined(tmp_path):
    """b's effect in 0.1 s is far below 1 N of noise: a wide interval, flagged, not a precise number."""
    data = write_log(tmp_path / "mu.csv", {MU: 0.3}, SIGMA)
    res = contactdyn.fit("b1", data, [MU, B], overrides={"duration": 0.1}, stages=1)
    b = next(e for e in res.estimates if e.key == B)
    assert not b.determined
    assert any(w.startswith("not determined") for w in b.warnings)
    mu = next(e for e in res.estimates if e.key == MU)
    assert mu.determined and mu.value == pytest.approx(0.3, rel=0.02)


def test_pool_gives_the_same_fit_as_this_process(tmp_path):
    """Jacobian runs on the sweep's process pool: bit-identical estimates, same number of runs."""
    data = write_log(tmp_path / "short.csv", {MU: 0.33}, SIGMA, duration=0.05)
    here = contactdyn.fit("b1", data, MU, overrides={"duration": 0.05}, stages=1)
    pooled = contactdyn.fit("b1", data, MU, overrides={"duration": 0.05}, stages=1, workers=2)
    assert pooled.values == here.values and pooled.runs == here.runs
    assert pooled.values[MU] == pytest.approx(0.33, rel=0.02)


def test_sparse_log_with_gaps(tmp_path):
    """Samples every 5 ms with a gap in one column: each column is read at its own valid times."""
    data = write_log(tmp_path / "sparse.csv", {MU: 0.3}, SIGMA, duration=0.2, every=5)
    rows = list(csv.reader(data.open()))
    for row in rows[10:20]:
        row[1] = ""  # F_n missing there
    with data.open("w", newline="") as f:
        csv.writer(f).writerows(rows)
    res = contactdyn.fit("b1", data, f"{MU}=0.1:1", overrides={"duration": 0.2}, stages=1, starts=3)
    assert [c.samples for c in res.channels] == [len(rows) - 1 - 10, len(rows) - 1]
    assert res.values[MU] == pytest.approx(0.3, rel=0.02)
    assert len(res.starts) == 3 and res.starts[0].start[MU] == 0.4  # the scene's value, then random ones
    assert 2 * min(s.cost for s in res.starts) == pytest.approx(res.chi2_red * res.dof)  # the best one won


# ---- a run failing inside the fit (a model whose runs fail in a region) --------------------------
class _LineModel:
    """Residuals of y = a t against data with a = 2; runs with 0.9 < a < 1.1 "fail" (the solver's first step
    from a = 0.2 lands at a = 1)."""

    def __init__(self):
        self.params = [Parameter("a", 1.0, 0.1, 10.0, True)]
        self.t = np.linspace(0, 1, 50)
        self.failures, self.runs = [], 0

    def values(self, z):
        return {"a": math.exp(float(z[0]))}

    def evaluate(self, points):
        from contactdyn.identify.model import Failure

        out = []
        for z in points:
            self.runs += 1
            a = self.values(z)["a"]
            if 0.9 < a < 1.1:
                self.failures.append(Failure({"a": a}, "SimulationError: blew up"))
                out.append(None)
            else:
                out.append((a * self.t - 2.0 * self.t) / 0.01)
        return out


def test_failed_runs_are_recorded_and_the_fit_goes_on():
    model = _LineModel()
    sol = solve(model, [np.array([math.log(0.2)])])
    assert math.exp(sol.z[0]) == pytest.approx(2.0, rel=1e-8)
    assert model.failures and all(0.9 < f.values["a"] < 1.1 for f in model.failures)
    assert "blew up" in model.failures[0].error


# ---- bad input: exit 2, the message names the column or key ------------------------------------
def _bad(capsys, tmp_path, args, *needles):
    code = main(["fit", "b1", "--set", "duration=0.1", *args])
    err = capsys.readouterr().err
    assert code == 2, err
    for needle in needles:
        assert needle in err
    assert "Traceback" not in err


def test_missing_csv(capsys, tmp_path):
    _bad(capsys, tmp_path, ["--data", str(tmp_path / "none.csv"), "--params", MU], "none.csv", "readable CSV")


def test_malformed_csv_names_the_column_and_row(capsys, tmp_path):
    path = tmp_path / "bad.csv"
    path.write_text("t,contact.tip.F_n\n0.0,100\n0.001,abc\n")
    _bad(capsys, tmp_path, ["--data", str(path), "--params", MU], "contact.tip.F_n", "'abc' in row 3")
    path.write_text("time,F\n0,1\n")
    _bad(capsys, tmp_path, ["--data", str(path), "--params", MU], "t: expected a time column")


def test_column_naming_no_channel(capsys, tmp_path, log):
    rows = list(csv.reader(log.open()))
    rows[0][1] = "contact.tip.Fn"
    path = tmp_path / "renamed.csv"
    with path.open("w", newline="") as f:
        csv.writer(f).writerows(rows)
    _bad(capsys, tmp_path, ["--data", str(path), "--params", MU], "contact.tip.Fn", "close: contact.tip.F_n")
    rows[0][1] = "tip[7]"
    with path.open("w", newline="") as f:
        csv.writer(f).writerows(rows)
    _bad(capsys, tmp_path, ["--data", str(path), "--params", MU], "tip[7]", "an index < 3")


def test_a_short_log_with_a_column_naming_no_channel_is_told_the_name_not_the_noise(capsys, tmp_path):
    """Two samples are too few to estimate a noise level, but the column's name is the first error to report."""
    path = tmp_path / "short.csv"
    path.write_text("t,contact.tip.Fn\n0.0,100\n0.001,101\n")
    _bad(capsys, tmp_path, ["--data", str(path), "--params", MU], "contact.tip.Fn", "no such channel")
    path.write_text("t,contact.tip.F_n\n0.0,100\n0.001,101\n")  # a right name: the noise is what is missing
    _bad(capsys, tmp_path, ["--data", str(path), "--params", MU], "contact.tip.F_n", "--noise COLUMN=SIGMA")


def test_key_that_is_not_a_number(capsys, tmp_path, log):
    _bad(capsys, tmp_path, ["--data", str(log), "--params", "contact.tip.normal.model"], "contact.tip.normal.model",
         "a number in the scene")
    _bad(capsys, tmp_path, ["--data", str(log), "--params", "contact.tip.normal.kk"], "contact.tip.normal.kk",
         "no such key")


def test_bounds_in_the_wrong_order(capsys, tmp_path, log):
    _bad(capsys, tmp_path, ["--data", str(log), "--params", f"{MU}=0.9:0.1"], MU, "LOW < HIGH")


def test_data_outside_the_scene_duration(capsys, tmp_path, log):
    code = main(["fit", "b1", "--set", "duration=0.05", "--data", str(log), "--params", MU])
    err = capsys.readouterr().err
    assert code == 2 and "contact.tip.F_n" in err and "duration [0, 0.05] s" in err and "t = 0.051 s" in err


def test_times_must_increase(capsys, tmp_path):
    path = tmp_path / "back.csv"
    path.write_text("t,contact.tip.F_n\n0.0,100\n0.002,101\n0.001,99\n")
    _bad(capsys, tmp_path, ["--data", str(path), "--params", MU], "t: expected strictly increasing",
         "0.001 after 0.002 in row 4")


def test_a_dead_worker_is_an_error_naming_the_runs(log):
    """A worker killed by a library crash breaks the pool: a ContactdynError with the parameter values."""
    from concurrent.futures.process import BrokenProcessPool

    from contactdyn.identify.data import measurements
    from contactdyn.identify.model import FitModel, FitSettings
    from contactdyn.identify.params import parse_params

    class DeadPool:
        def submit(self, *args):
            class Dead:
                def result(self):
                    raise BrokenProcessPool("a child process terminated abruptly")

            return Dead()

    scene = load_scene("b1", {"duration": 0.1})
    model = FitModel(scene.document, scene.file, parse_params(MU, scene.document), measurements(log, None, 0.1),
                     FitSettings(), pool=DeadPool())
    with pytest.raises(contactdyn.ContactdynError, match=r"worker process died .*'contact.tip.tangent.mu': 0.5"):
        model.evaluate([np.array([math.log(0.5)])])
