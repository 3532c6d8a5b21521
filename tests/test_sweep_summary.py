"""The sweep summary: part files per chunk, merged on resume; full rewrites that do not grow with the chunks."""

from __future__ import annotations

import json
import math
import sys
from pathlib import Path

import pandas as pd
import pytest

from contactdyn.cli import EXIT_OK, main
from contactdyn.output.result import load_result
from contactdyn.sweep import result_row
from contactdyn.sweep import summary as summary_mod
from contactdyn.sweep.summary import COST_FACTOR, PARTS, SUMMARY_FIXED, Summary

FAST = ["--set", "duration=0.03", "--set", "solver.output_rate=200"]


def _sweep(out: Path, n: int, *extra: str) -> list[str]:
    kps = ",".join(f"{500.0 + 500.0 * i}" for i in range(n))
    return ["sweep", "b1", *FAST, "--grid", f"controller.kp={kps}", "--workers", "0", "--chunk", "1", "-q",
            "--out", str(out), *extra]


def _count_rewrites(monkeypatch) -> list[int]:
    """Count the full rewrites of the table (each row count written)."""
    written: list[int] = []
    real = summary_mod.write_summary

    def counting(out, rows, *args):
        written.append(len(rows))
        return real(out, rows, *args)

    monkeypatch.setattr(summary_mod, "write_summary", counting)
    return written


@pytest.mark.parametrize("n", [2, 6])
def test_full_rewrites_do_not_grow_with_the_chunks(capsys, tmp_path, monkeypatch, n):
    written = _count_rewrites(monkeypatch)
    parts: list[str] = []
    real_add = Summary.add

    def add(self, rows):
        real_add(self, rows)
        parts.extend(p.name for p in (self.out / PARTS).glob("*.json"))

    monkeypatch.setattr(Summary, "add", add)
    assert main(_sweep(tmp_path / "s", n)) == EXIT_OK
    assert written == [0, n]  # at the start (nothing yet) and at the end, whatever the number of chunks
    assert len(set(parts)) == n  # one part file per chunk (of one run)
    assert not (tmp_path / "s" / PARTS).exists()  # merged, then removed
    assert len(pd.read_parquet(tmp_path / "s" / "summary.parquet")) == n


def test_a_killed_sweeps_parts_reach_the_summary_without_reloading(capsys, tmp_path, monkeypatch):
    """Killed after its first rewrite (as by SIGKILL: no final one), the sweep's rows are in its parts; the resume
    merges them without reloading any result, and the summary then equals the records of the runs' files."""
    out = tmp_path / "s"
    with monkeypatch.context() as m:
        written = _count_rewrites(m)
        real_rewrite = Summary.rewrite
        m.setattr(Summary, "rewrite", lambda self: real_rewrite(self) if not written else self.path)
        assert main(_sweep(out, 3)) == EXIT_OK
    assert written == [0] and len(pd.read_parquet(out / "summary.parquet")) == 0
    assert len(list((out / PARTS).glob("*.json"))) == 3
    result_mod = sys.modules["contactdyn.output.result"]
    with monkeypatch.context() as m:
        m.setattr(result_mod, "load_result", lambda *a: pytest.fail("reloaded a result"))
        assert main([*_sweep(out, 4), "--json"]) == EXIT_OK  # one more case: one run
    report = json.loads(capsys.readouterr().out)
    assert report["skipped"] == 3 and report["counts"]["ok"] == 4
    assert not (out / PARTS).exists()
    table = pd.read_parquet(out / "summary.parquet").set_index("run_id")
    assert len(table) == 4
    for rid in table.index:
        record = result_row(rid, load_result(out / "runs" / rid))
        row = table.loc[rid]
        assert set(record) <= {"run_id", *table.columns}
        for key, value in record.items():
            if key not in ("run_id", "wall_s"):
                assert row[key] == value or (math.isnan(row[key]) and math.isnan(value)), (rid, key)


def test_damaged_part_files_are_ignored(tmp_path):
    parts = tmp_path / PARTS
    parts.mkdir()
    good = {"run_id": "a", "status": "ok", "error": "", "wall_s": 0.5, "contact.tip.F_peak": float("nan")}
    (parts / "000000.json").write_text(json.dumps([good]))
    (parts / "000001.json").write_text('[{"run_id": "b", "sta')  # torn by hand: those runs are reloaded
    (parts / "000002.json").write_text(json.dumps([{"run_id": "c"}]))  # not a row
    rows = summary_mod.cached_rows(tmp_path)
    assert list(rows) == ["a"] and set(rows["a"]) == {*SUMMARY_FIXED, "contact.tip.F_peak"}


class _Clock:
    """A fake monotonic clock [s]; a rewrite costs ``per_row`` seconds per row of the table."""

    def __init__(self, per_row: float) -> None:
        self.now, self.per_row, self.in_rewrites = 0.0, per_row, 0.0

    def __call__(self) -> float:
        return self.now

    def write(self, out, rows, *args) -> Path:
        cost = self.per_row * len(rows)
        self.now += cost
        self.in_rewrites += cost
        return out / "summary.parquet"


def _simulated_sweep(tmp_path: Path, monkeypatch, runs: int, chunk: int, run_s: float, per_row: float) -> tuple:
    """Chunks of ``chunk`` runs finishing every ``chunk * run_s`` seconds; (rewrites, time in rewrites / total)."""
    tmp_path.mkdir()
    clock = _Clock(per_row)
    monkeypatch.setattr(summary_mod, "write_summary", clock.write)
    summary = Summary(tmp_path, {}, {}, [], False, clock=clock)
    summary.rewrite()
    for start in range(0, runs, chunk):
        clock.now += chunk * run_s
        summary.add([{"run_id": f"{i:06d}", "status": "ok", "error": "", "wall_s": run_s}
                     for i in range(start, min(runs, start + chunk))])
    if summary.pending:
        summary.rewrite()
    return summary.rewrites, clock.in_rewrites / clock.now


def test_rewrites_follow_the_time_not_the_chunks(tmp_path, monkeypatch):
    # the same 70 s of runs in 28 chunks or in 280: the same rewrites (start, at 30 s and 60 s, end)
    coarse = _simulated_sweep(tmp_path / "a", monkeypatch, runs=280, chunk=10, run_s=0.25, per_row=0.0)
    fine = _simulated_sweep(tmp_path / "b", monkeypatch, runs=280, chunk=1, run_s=0.25, per_row=0.0)
    assert coarse[0] == fine[0] == 4


def test_time_in_rewrites_stays_a_bounded_fraction(tmp_path, monkeypatch):
    # rewrites priced at 1 ms per row (80x the measured cost), runs at 11 ms (2 workers): rewriting after every
    # chunk of 32 would spend 96 % of a 20 000-run sweep rewriting. Here: at most 1 / (1 + COST_FACTOR) between
    # the start and the end, plus the final rewrite (per_row / run_s of the runs' time), at any size
    per_row, run_s = 1e-3, 0.011
    for runs in (2_000, 20_000):
        rewrites, fraction = _simulated_sweep(tmp_path / str(runs), monkeypatch, runs=runs, chunk=32, run_s=run_s,
                                              per_row=per_row)
        assert fraction <= 1.0 / (1.0 + COST_FACTOR) + per_row / run_s, runs
        assert rewrites < runs / 32 / 10, runs


def test_a_parameter_column_keeps_its_type_integers_as_integers(tmp_path):
    """A delay of 2 samples is 2 in the summary, not 2.0; a column of ints and floats is floats."""
    params = {"r0": {"controller.delay": 2, "controller.kp": 1, "name": "a"},
              "r1": {"controller.delay": 0, "controller.kp": 2.5, "name": "b"},
              "r2": {"controller.delay": 1, "controller.kp": 3, "name": "c"},
              "r3": {"controller.kp": 4, "name": "d"}}  # (no delay set: missing)
    rows = {i: {"run_id": i, "status": "ok", "error": "", "wall_s": 1.0} for i in params}
    path = summary_mod.write_summary(tmp_path, rows, params, ["controller.delay", "controller.kp", "name"], True)
    frame = pd.read_parquet(path)
    assert str(frame["controller.delay"].dtype) == "Int64" and str(frame["controller.kp"].dtype) == "float64"
    assert frame["controller.delay"].tolist()[:3] == [0, 1, 2] and frame["controller.delay"].isna().tolist()[3]
    assert all(type(v) is int for v in frame["controller.delay"].dropna().tolist())
    assert pd.read_csv(tmp_path / "summary.csv")["controller.delay"].tolist()[:3] == [0, 1, 2]
