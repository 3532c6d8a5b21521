"""Sweeps: axes, run ids, summary rows, failures recorded, resume after a kill, determinism, pool and Dask."""

from __future__ import annotations

import hashlib
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

import contactdyn
import contactdyn.scene.user_laws as user_laws
from contactdyn.cli import EXIT_FAILED, EXIT_OK, EXIT_USAGE, main
from contactdyn.errors import SceneError, SimulationError
from contactdyn.output.metrics import metrics
from contactdyn.output.result import load_result
from contactdyn.scene.scene_file import parse_scene
from contactdyn.sweep import execute as sweep_exec
from contactdyn.sweep import make_sweep, parse_grid, parse_range, run_id

# 30 ms of b1: short of the first stick (t ~ 0.047 s), where some gains end in a stick/slip event storm
FAST = ["--set", "duration=0.03", "--set", "solver.output_rate=200"]
GRID = ["--grid", "contact.tip.normal.k=1e4,1e5", "--grid", "controller.kp=1000.0,3000.0"]
ROOT = Path(contactdyn.__file__).parent.parent


def _summary(out: Path) -> pd.DataFrame:
    return pd.read_parquet(out / "summary.parquet")


def _same_outputs(a: Path, b: Path) -> None:
    """Bit-identical summaries and results, wall times aside."""
    sa, sb = _summary(a), _summary(b)
    pd.testing.assert_frame_equal(sa.drop(columns="wall_s"), sb.drop(columns="wall_s"), check_exact=True)
    names = sorted(p.name for p in (a / "runs").iterdir())
    assert names == sorted(p.name for p in (b / "runs").iterdir())
    for name in names:
        da, db = (a / "runs" / name).read_bytes(), (b / "runs" / name).read_bytes()
        if name.endswith(".npz"):
            assert da == db, name
        else:
            ja, jb = json.loads(da), json.loads(db)
            for doc in (ja, jb):
                doc.get("stats", {}).pop("wall_s", None), doc.get("stats", {}).pop("real_time_factor", None)
                doc.pop("wall_s", None)
            assert ja == jb, name


# ---- axes and ids ----------------------------------------------------------------------------------
def test_grid_values_are_toml_and_keep_lists_whole():
    assert parse_grid("contact.tip.normal.k=1e4, 2e4") == ("contact.tip.normal.k", [1e4, 2e4])
    assert parse_grid("solver.method=RK45,DOP853") == ("solver.method", ["RK45", "DOP853"])
    assert parse_grid("robot.q0=[0.1, 0.2],[0.3, 0.4]") == ("robot.q0", [[0.1, 0.2], [0.3, 0.4]])
    for bad in ("k", "k=", "=1,2", "k=1,,2"):
        with pytest.raises(SceneError, match="--grid"):
            parse_grid(bad)


def test_ranges_linear_and_log():
    assert parse_range("a=0:1:5") == ("a", [0.0, 0.25, 0.5, 0.75, 1.0])
    key, values = parse_range("b=1e2:1e4:3:log")
    assert key == "b" and values == pytest.approx([1e2, 1e3, 1e4], rel=1e-15)
    assert parse_range("c=2:3:1") == ("c", [2.0])
    for bad in ("a=0:1", "a=0:1:x", "a=0:1:0", "a=0:inf:3", "a=0:1:3:lg", "a=0:1:3:log"):
        with pytest.raises(SceneError):
            parse_range(bad)


def test_run_id_is_a_stable_hash_of_the_overrides():
    a = run_id({"duration": 0.05, "contact.tip.normal.k": 1e4})
    assert a == run_id({"contact.tip.normal.k": 1e4, "duration": 0.05})  # order does not matter
    assert a != run_id({"duration": 0.05, "contact.tip.normal.k": 2e4})
    # the recipe, fixed forever (a changed hash would orphan every saved sweep): SHA-256 of sorted compact JSON
    assert a == hashlib.sha256(b'{"contact.tip.normal.k":10000.0,"duration":0.05}').hexdigest()[:12] == "5f7ff560af64"


def test_cases_cross_axes_and_explicit_runs(tmp_path):
    f = tmp_path / "s.toml"
    f.write_text('scene = "b1"\n[set]\nduration = 0.05\n[grid]\n"controller.kp" = [1000.0, 2000.0]\n'
                 '[range.contact.tip.normal]\nk = { lo = 1e4, hi = 1e6, n = 3, log = true }\n'
                 '[[run]]\n"solver.method" = "RK45"\n[[run]]\n"solver.method" = "DOP853"\n')
    sw = make_sweep(None, sweep_file=f, sets=["solver.output_rate=200"], grids=["controller.kp=500.0"])
    assert sw.fixed == {"duration": 0.05, "solver.output_rate": 200}
    assert sw.axes["controller.kp"] == [500.0]  # the command line wins over the file
    assert sw.axes["contact.tip.normal.k"] == pytest.approx([1e4, 1e5, 1e6])
    cases = sw.cases()
    assert len(cases) == 2 * 3 * 1
    assert [c[0] for c in cases] == sorted(c[0] for c in cases)
    assert {c[1]["solver.method"] for c in cases} == {"RK45", "DOP853"}
    assert sw.parameter_keys() == ["controller.kp", "contact.tip.normal.k", "solver.method"]


def test_a_relative_scene_path_is_stored_resolved_for_workers_elsewhere(tmp_path, monkeypatch):
    """A worker (Dask's) runs in another working directory: the sweep keeps the scene's path resolved, so its
    ``imports`` are found beside the scene there (before: the relative path, the module looked up from the
    worker's directory and not found)."""
    (tmp_path / "proj").mkdir()
    (tmp_path / "elsewhere").mkdir()
    (tmp_path / "proj" / "beside_sweep_scene.py").write_text("LOADED = True\n")
    text = (ROOT / "sims" / "b1.toml").read_text()
    (tmp_path / "proj" / "scene.toml").write_text(f'imports = ["beside_sweep_scene"]\n{text}')
    monkeypatch.chdir(tmp_path)
    monkeypatch.setattr(sys, "path", [p for p in sys.path if p not in ("", str(tmp_path))])
    monkeypatch.setattr(user_laws, "_state", {"allowed": True, "entry_points": True})
    monkeypatch.setattr(user_laws, "IMPORTED", {})
    sweep = make_sweep("proj/scene.toml", grids=["controller.kp=1000.0,2000.0"])
    assert sweep.file == str(tmp_path / "proj" / "scene.toml")
    monkeypatch.chdir(tmp_path / "elsewhere")  # a worker's directory
    try:
        for _, _, overrides in sweep.cases():
            parse_scene(sweep.document, overrides, sweep.file)  # as run_chunk's worker does
        assert sys.modules["beside_sweep_scene"].__file__ == str(tmp_path / "proj" / "beside_sweep_scene.py")
    finally:
        sys.modules.pop("beside_sweep_scene", None)


@pytest.mark.parametrize("text, words", [
    ('scene = "b1"\n[grid]\n"controller.kp" = 3\n', ["grid.controller.kp", "non-empty list"]),
    ('scene = "b1"\n[range]\n"controller.kp" = { lo = 1, hi = 2 }\n', ["range.controller.kp.n", "missing"]),
    ('scene = "b1"\n[range]\n"controller.kp" = { lo = 1, hi = 2, n = 3, lg = 1 }\n', ["range.controller.kp.lg"]),
    ('scene = "b1"\n[grids]\n', ["grids", "did you mean 'grid'"]),
    ('scene = "b1"\n[grid\n', ["valid TOML"]),
    ('[grid]\n"controller.kp" = [1.0]\n', ["scene"]),
])
def test_bad_sweep_files_name_file_and_key(capsys, tmp_path, text, words):
    f = tmp_path / "bad.toml"
    f.write_text(text)
    code = main(["sweep", "--file", str(f), "--out", str(tmp_path / "o"), "--workers", "0", "--quiet"])
    err = capsys.readouterr().err
    assert code == EXIT_USAGE and "Traceback" not in err and str(f) in err
    for word in words:
        assert word in err


# ---- running -------------------------------------------------------------------------------------
def test_a_bad_grid_value_is_bad_input_before_any_run(capsys, tmp_path):
    out = tmp_path / "s"
    code = main(["sweep", "b1", *FAST, *GRID, "--grid", "contact.tip.normal.b=1.0,-1.0", "--out", str(out),
                 "--workers", "0", "--csv", "--quiet"])
    err = capsys.readouterr().err
    assert code == EXIT_USAGE and "Traceback" not in err
    assert "sweep value " in err and "contact.tip.normal.b = -1.0" in err
    assert "contact.tip.normal.b: expected a number >= 0" in err
    assert not out.exists()  # nothing ran, nothing written


def test_sweep_rows_metrics_sorted_by_the_swept_parameters(capsys, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    code = main(["sweep", "b1", *FAST, *GRID, "--out", "s", "--workers", "0", "--csv", "--plot",
                 "contact.tip.F_peak", "--over", "contact.tip.normal.k"])
    assert code == EXIT_OK
    out = tmp_path / "s"
    stdout = capsys.readouterr().out
    assert f"-> {out}" in stdout  # a relative --out is made absolute before it reaches any worker
    s = _summary(out)
    assert len(s) == 4 and list(s.columns[:6]) == ["run_id", "contact.tip.normal.k", "controller.kp", "status",
                                                   "error", "wall_s"]
    swept = list(zip(s["contact.tip.normal.k"], s["controller.kp"], strict=True))
    assert swept == sorted(swept)  # by the parameters in axis order, not by run id
    assert (s.error == "").all() and (s.wall_s > 0).all()
    for _, row in s.iterrows():
        result = load_result(out / "runs" / row.run_id)
        assert result.scene["controller"]["kp"] == row["controller.kp"]
        for name, value in metrics(result).items():
            assert row[name] == value or (np.isnan(row[name]) and np.isnan(value)), name
    csv = pd.read_csv(out / "summary.csv", keep_default_na=False)
    assert list(csv.run_id) == list(s.run_id)
    figure = out / "plot_contact.tip.F_peak_over_contact.tip.normal.k.png"
    assert f"plot {figure}" in stdout and figure.stat().st_size > 10_000


def test_plot_and_over_are_checked(capsys, tmp_path):
    base = ["sweep", "b1", *FAST, *GRID, "--out", str(tmp_path / "s"), "--workers", "0", "-q"]
    assert main([*base, "--plot", "contact.tip.F_peak"]) == EXIT_USAGE
    assert main([*base, "--plot", "contact.tip.F_peak", "--over", "duration"]) == EXIT_USAGE
    assert "a swept parameter (contact.tip.normal.k, controller.kp)" in capsys.readouterr().err
    assert main([*base, "--plot", "contact.tip.F_pk", "--over", "controller.kp"]) == EXIT_USAGE
    assert "did you mean 'contact.tip.F_peak'?" in capsys.readouterr().err
    assert not (tmp_path / "s").exists()  # (checked before any run: nothing was run or written)


def test_simulation_failure_and_crash_do_not_stop_the_others(capsys, tmp_path, monkeypatch):
    sim = sys.modules["contactdyn.simulate"]  # the package re-exports the function under the module's name
    real = sim.simulate
    faults = {1000.0: SimulationError("b1: event storm"), 2000.0: RuntimeError("a bug"),
              3000.0: np.linalg.LinAlgError("SVD did not converge")}

    def faulty(scene, overrides=None):
        fault = faults.get(scene.document["controller"]["kp"])
        if fault is not None:
            raise fault
        return real(scene, overrides)

    monkeypatch.setattr(sim, "simulate", faulty)
    out = tmp_path / "s"
    code = main(["sweep", "b1", *FAST, "--grid", "controller.kp=500.0,1000.0,2000.0,3000.0", "--out", str(out),
                 "--workers", "0", "--quiet"])
    assert code == EXIT_FAILED
    s = _summary(out).set_index("controller.kp")
    assert s.loc[500.0, "status"] == "ok"
    assert s.loc[1000.0, "status"] == "failed" and s.loc[1000.0, "error"] == "SimulationError: b1: event storm"
    assert s.loc[2000.0, "status"] == "crashed" and s.loc[2000.0, "error"] == "RuntimeError: a bug"
    assert s.loc[3000.0, "status"] == "failed" and "LinAlgError" in s.loc[3000.0, "error"]
    err = capsys.readouterr().err  # each failure on the console, with its error, at the end
    assert "3 of 4 runs failed:" in err and "see the status" not in err
    assert "(controller.kp = 1000):\n      SimulationError: b1: event storm" in err
    assert "crashed" in err and "RuntimeError: a bug" in err


def test_non_finite_channels_make_a_failed_row():
    result = contactdyn.simulate("b1", {"duration": 0.05, "solver.output_rate": 200})
    result.channels["q"] = result.channels["q"].copy()
    result.channels["q"][3, 0] = np.inf
    row = sweep_exec.result_row("x", result)
    assert row["status"] == "failed" and row["error"] == "non-finite values in q"


def test_whole_sweep_invalid_is_bad_input(capsys, tmp_path):
    code = main(["sweep", "b1", "--grid", "duration=-1,0", "--out", str(tmp_path / "s"), "--workers", "0"])
    err = capsys.readouterr().err
    assert code == EXIT_USAGE and "duration: expected a number > 0" in err
    assert not (tmp_path / "s").exists()  # bad input writes nothing


def test_resume_skips_finished_runs(capsys, tmp_path):
    out = tmp_path / "s"
    assert main(["sweep", "b1", *FAST, "--grid", "controller.kp=1000.0", "--out", str(out), "--workers", "0",
                 "-q"]) == EXIT_OK
    first = {p.name: p.stat().st_mtime_ns for p in (out / "runs").iterdir()}
    assert main(["sweep", "b1", *FAST, "--grid", "controller.kp=1000.0,3000.0", "--out", str(out), "--workers", "0",
                 "--json"]) == EXIT_OK
    report = json.loads(capsys.readouterr().out)
    assert report["total"] == 2 and report["skipped"] == 1 and report["counts"]["ok"] == 2
    assert all((out / "runs" / n).stat().st_mtime_ns == t for n, t in first.items())  # not rewritten
    assert len(_summary(out)) == 2


def test_resume_refuses_another_scene(capsys, tmp_path):
    out = tmp_path / "s"
    assert main(["sweep", "b1", *FAST, "--out", str(out), "--workers", "0", "-q"]) == EXIT_OK
    other = tmp_path / "b1_copy.toml"
    other.write_text((contactdyn.scene.scene_file.sims_dir() / "b1.toml").read_text().replace("mu = 0.4", "mu = 0.5"))
    assert main(["sweep", str(other), *FAST, "--out", str(out), "--workers", "0", "-q"]) == EXIT_USAGE
    assert "sweep.json" in capsys.readouterr().err


def test_killed_sweep_resumes_to_the_same_outputs(capsys, tmp_path):
    """SIGKILL mid-sweep, resume: nothing lost, nothing torn, same files as an uninterrupted sweep."""
    args = ["sweep", "b1", *FAST, "--range", "controller.kp=500:5000:24", "--workers", "0", "--quiet"]
    killed = tmp_path / "killed"
    env = {**os.environ, "PYTHONPATH": f"{ROOT}{os.pathsep}{os.environ.get('PYTHONPATH', '')}"}
    proc = subprocess.Popen([sys.executable, "-m", "contactdyn.cli", *args, "--out", str(killed)], env=env,
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    deadline = time.monotonic() + 60
    while time.monotonic() < deadline and len(list((killed / "runs").glob("*.npz"))) < 3 and proc.poll() is None:
        time.sleep(0.005)
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    done = len(list((killed / "runs").glob("*.npz")))
    assert 3 <= done < 24, "the sweep was not interrupted mid-way"
    code = main([*args, "--out", str(killed), "--json"])
    report = json.loads(capsys.readouterr().out)
    # a run killed between its .npz and its .json is not finished: it runs again
    assert done - 1 <= report["skipped"] <= done and sum(report["counts"].values()) == 24
    assert not list((killed / "runs").glob(".*.tmp"))
    fresh = tmp_path / "fresh"
    assert main([*args, "--out", str(fresh)]) == code
    _same_outputs(killed, fresh)


def test_process_pool_gives_the_same_outputs_as_one_process(capsys, tmp_path):
    args = ["sweep", "b1", *FAST, *GRID, "--quiet"]
    assert main([*args, "--out", str(tmp_path / "one"), "--workers", "0"]) == EXIT_OK
    assert main([*args, "--out", str(tmp_path / "pool"), "--workers", "2", "--chunk", "1"]) == EXIT_OK
    _same_outputs(tmp_path / "one", tmp_path / "pool")


def test_dask_local_cluster_runs_chunks(capsys, tmp_path):
    distributed = pytest.importorskip("distributed")
    args = ["sweep", "b1", *FAST, *GRID, "--grid", "contact.tip.tangent.mu=0.3,0.4", "--quiet"]
    assert main([*args, "--out", str(tmp_path / "one"), "--workers", "0"]) == EXIT_OK
    with distributed.LocalCluster(n_workers=2, processes=True, threads_per_worker=1,
                                  dashboard_address=None) as cluster:
        code = main([*args, "--out", str(tmp_path / "dask"), "--scheduler", cluster.scheduler_address,
                     "--chunk", "3"])
        tasks = dict(cluster.scheduler.task_prefixes["run_chunk"].state_counts)
    assert code == EXIT_OK
    assert tasks["memory"] == 3  # 8 runs in chunks of 3: three tasks, not eight
    _same_outputs(tmp_path / "one", tmp_path / "dask")


def test_unreachable_scheduler_is_bad_input(capsys, tmp_path, monkeypatch):
    pytest.importorskip("distributed")
    monkeypatch.setattr(sweep_exec, "SCHEDULER_TIMEOUT", 0.5)
    code = main(["sweep", "b1", *FAST, "--out", str(tmp_path / "s"), "--scheduler", "tcp://127.0.0.1:9"])
    err = capsys.readouterr().err
    assert code == EXIT_USAGE and "--scheduler" in err and "Traceback" not in err


def test_retry_failed_runs_the_failed_runs_again(capsys, tmp_path):
    out = tmp_path / "s"
    # a q0 of the wrong length validates as a scene but fails when the robot is known: a failed run
    args = ["sweep", "b1", *FAST, "--grid", "robot.q0=[0.337307481430, -1.318116071653],[0.1]", "--out", str(out),
            "--workers", "0"]
    assert main([*args, "--json"]) == EXIT_FAILED
    assert json.loads(capsys.readouterr().out)["skipped"] == 0
    assert main([*args, "--json"]) == EXIT_FAILED
    assert json.loads(capsys.readouterr().out)["skipped"] == 2  # the failure is a result too
    assert main([*args, "--json", "--retry-failed"]) == EXIT_FAILED
    report = json.loads(capsys.readouterr().out)
    assert report["skipped"] == 1 and report["counts"] == {"ok": 1, "failed": 1, "crashed": 0}


def test_resume_reads_the_summary_and_reruns_damaged_results(capsys, tmp_path, monkeypatch):
    out, fresh = tmp_path / "s", tmp_path / "fresh"
    args = ["sweep", "b1", *FAST, *GRID, "--workers", "0", "--quiet"]
    assert main([*args, "--out", str(out)]) == EXIT_OK
    assert main([*args, "--out", str(fresh)]) == EXIT_OK
    result_mod = sys.modules["contactdyn.output.result"]
    with monkeypatch.context() as m:  # finished runs listed in the summary are not reloaded
        m.setattr(result_mod, "load_result", lambda *a: pytest.fail("reloaded a result"))
        assert main([*args, "--out", str(out), "--json"]) == EXIT_OK
        assert json.loads(capsys.readouterr().out)["skipped"] == 4
    _same_outputs(out, fresh)
    (out / "summary.parquet").unlink()  # the summary lost, one result damaged by hand
    victim = sorted((out / "runs").glob("*.npz"))[0]
    victim.write_bytes(b"not a zip file")
    assert main([*args, "--out", str(out), "--json"]) == EXIT_OK
    assert json.loads(capsys.readouterr().out)["skipped"] == 3
    _same_outputs(out, fresh)


def _interrupted_sweep(args: list[str], out: Path) -> tuple[int, str]:
    """(exit code, stderr) of ``contactdyn ARGS`` sent Ctrl-C once its first run is saved."""
    env = {**os.environ, "PYTHONPATH": f"{ROOT}{os.pathsep}{os.environ.get('PYTHONPATH', '')}"}
    proc = subprocess.Popen([sys.executable, "-m", "contactdyn.cli", *args], env=env, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, start_new_session=True)
    deadline = time.monotonic() + 60
    while time.monotonic() < deadline and not any((out / "runs").glob("*.npz")) and proc.poll() is None:
        time.sleep(0.005)
    os.killpg(proc.pid, signal.SIGINT)  # as a terminal's Ctrl-C: the whole process group
    _, err = proc.communicate(timeout=60)
    return proc.returncode, err


def test_ctrl_c_stops_pool_workers_without_tracebacks_and_resumes(capsys, tmp_path):
    # 150 runs of 1 s: several seconds of work left when the first is saved, far more than can finish before the
    # signal even on a loaded machine (150 runs of FAST's 0.03 s once all did, and of 0.3 s under a load of 4 on
    # 2 cores: the sweep ended with 0, not 130). Should the signal still land after the sweep's end (the whole sweep
    # done, exit 0: nothing was interrupted, so nothing tested), it is tried again in a new folder, twice at most.
    for attempt in range(3):
        out = tmp_path / f"s{attempt}"
        args = ["sweep", "b1", "--set", "duration=1.0", "--set", "solver.output_rate=200", "--range",
                "contact.tip.normal.k=5e4:2e5:150:log", "--workers", "2", "--chunk", "5", "--quiet", "--out",
                str(out)]
        code, err = _interrupted_sweep(args, out)
        if not (code == 0 and len(list((out / "runs").glob("*.npz"))) == 150):
            break
    assert code == 130, err
    assert "Traceback" not in err and "run the same command again to resume" in err
    assert main(args) == EXIT_OK
    assert len(_summary(out)) == 150 and (_summary(out).status == "ok").all()


def test_a_failed_runs_line_names_only_the_keys_that_run_set(tmp_path):
    """A sweep of a grid and [[run]] rows: a row's keys it does not set are empty cells in the summary (NaN), not
    values of the run; the console line leaves them out."""
    from contactdyn.sweep.report import failure_lines, failures

    summary = tmp_path / "summary.parquet"
    pd.DataFrame({"run_id": ["r0", "r1"], "status": ["ok", "failed"], "error": ["", "boom"],
                  "controller.delay": [0, 2], "robot.joint.q2.damping": [float("nan"), 1e12]}).to_parquet(summary)
    rows = failures(summary, ["controller.delay", "robot.joint.q2.damping", "controller.sensor.force_noise"])
    assert [r["params"] for r in rows] == [{"controller.delay": 2, "robot.joint.q2.damping": 1e12}]
    assert failure_lines(rows)[0] == "  failed r1 (controller.delay = 2, robot.joint.q2.damping = 1e+12):"
    pd.DataFrame({"run_id": ["r2"], "status": ["failed"], "error": ["x"], "controller.delay": [1],
                  "controller.sensor.force_noise": [float("nan")]}).to_parquet(summary)
    assert failures(summary, ["controller.delay", "controller.sensor.force_noise"])[0]["params"] == \
        {"controller.delay": 1}


def test_a_runs_warnings_are_in_its_saved_result_not_lines_on_the_console(tmp_path):
    """benchmarks/stiff_force.toml aliases at its output rate (a sanity warning). Its sweep's runs keep that warning in
    their saved results; Python prints no warning line for it (before: one per run, with the worker's source line,
    even with --quiet)."""
    import warnings

    from contactdyn.output.physics_checks import PhysicsWarning
    from contactdyn.scene.sanity import SanityWarning

    out = tmp_path / "s"
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        code = main(["sweep", str(ROOT / "benchmarks" / "stiff_force.toml"), *FAST, "--grid",
                     "controller.kp=1000.0,2000.0", "--out", str(out), "--workers", "0", "--quiet"])
    assert code == EXIT_OK
    assert not [w for w in caught if issubclass(w.category, SanityWarning | PhysicsWarning)]
    summary = _summary(out)
    for rid, count in zip(summary.run_id, summary.warnings, strict=True):
        warned = load_result(out / "runs" / rid).meta["warnings"]
        assert any("aliases" in w for w in warned) and count == len(warned)


def test_a_sweep_says_at_its_end_how_many_runs_gave_warnings(tmp_path, capsys):
    """Without --quiet, one line at the end counts the runs whose results hold warnings (b1's hold none)."""
    main(["sweep", str(ROOT / "benchmarks" / "stiff_force.toml"), *FAST, "--grid", "controller.kp=1000.0,2000.0",
          "--out", str(tmp_path / "s"), "--workers", "0"])
    assert "contactdyn: warning: 2 of 2 runs gave sanity or physics-check warnings" in capsys.readouterr().err
    main(["sweep", "b1", *FAST, "--grid", "controller.kp=1000.0,2000.0", "--out", str(tmp_path / "b"),
          "--workers", "0"])
    assert "gave sanity" not in capsys.readouterr().err
