"""A sweep's processes: a run that kills its worker is recorded; no process outlives a killed sweep."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pandas as pd
import pytest

import contactdyn
from contactdyn.cli import EXIT_USAGE, main
from contactdyn.sweep.store import lock_out

ROOT = Path(contactdyn.__file__).parent.parent
FAST = ["--set", "duration=0.03", "--set", "solver.output_rate=200"]


def _env(extra: Path | None = None) -> dict[str, str]:
    paths = [str(p) for p in (extra, ROOT) if p is not None]
    return {**os.environ, "PYTHONPATH": os.pathsep.join([*paths, os.environ.get("PYTHONPATH", "")])}


def _crash_hook(tmp_path: Path) -> Path:
    """A folder whose sitecustomize every process of the sweep imports at start-up (parent, fork server,
    workers): the run with kp = 2000 ends its process with SIGSEGV, as a crash in a C library would."""
    hook = tmp_path / "hook"
    hook.mkdir()
    (hook / "sitecustomize.py").write_text(textwrap.dedent("""
        import os, signal, sys
        import contactdyn.simulate
        sim = sys.modules["contactdyn.simulate"]
        real = sim.simulate
        def crashing(scene, overrides=None):
            if scene.document["controller"]["kp"] == 2000.0:
                os.kill(os.getpid(), signal.SIGSEGV)
            return real(scene, overrides)
        sim.simulate = crashing
    """))
    return hook


def test_a_run_that_kills_its_worker_is_recorded_with_the_signal(tmp_path):
    hook = _crash_hook(tmp_path)
    out = tmp_path / "s"
    cmd = [sys.executable, "-m", "contactdyn.cli", "sweep", "b1", *FAST, "--grid",
           "controller.kp=500.0,1000.0,2000.0,3000.0,4000.0", "--workers", "2", "--chunk", "2", "--quiet",
           "--out", str(out)]
    proc = subprocess.run(cmd, env=_env(hook), capture_output=True, text=True, timeout=300)
    assert proc.returncode == 1, proc.stderr
    assert "Traceback" not in proc.stderr
    s = pd.read_parquet(out / "summary.parquet").set_index("controller.kp")
    assert len(s) == 5
    assert s.loc[2000.0, "status"] == "failed"
    assert s.loc[2000.0, "error"] == "the run's process killed by SIGSEGV (11)"
    assert (s.drop(index=2000.0).status == "ok").all()


@pytest.mark.slow
def test_a_run_that_kills_its_dask_worker_is_recorded(tmp_path):
    pytest.importorskip("distributed")
    hook = _crash_hook(tmp_path)
    out = tmp_path / "s"
    script = textwrap.dedent(f"""
        import sys, distributed
        from contactdyn.cli import main
        with distributed.LocalCluster(n_workers=2, processes=True, threads_per_worker=1,
                                      dashboard_address=None) as cluster:
            sys.exit(main(["sweep", "b1", *{FAST!r}, "--grid", "controller.kp=500.0,1000.0,2000.0,3000.0",
                           "--scheduler", cluster.scheduler_address, "--chunk", "2", "--quiet",
                           "--out", {str(out)!r}]))
    """)
    env = {**_env(hook), "DASK_DISTRIBUTED__SCHEDULER__ALLOWED_FAILURES": "0"}
    proc = subprocess.run([sys.executable, "-c", script], env=env, capture_output=True, text=True, timeout=300)
    assert proc.returncode == 1, proc.stderr[-3000:]
    s = pd.read_parquet(out / "summary.parquet").set_index("controller.kp")
    # the runs of a chunk whose Dask worker died run again here, each in its own process
    assert s.loc[2000.0, "status"] == "failed" and s.loc[2000.0, "error"] == "the run's process killed by SIGSEGV (11)"
    assert (s.drop(index=2000.0).status == "ok").all() and len(s) == 4


def _session(sid: int) -> list[int]:
    """Live processes of a session (zombies excluded)."""
    pids = []
    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit():
            continue
        try:
            stat = (entry / "stat").read_text()
        except OSError:
            continue
        fields = stat[stat.rindex(")") + 2:].split()  # state, ppid, pgrp, session, ...
        if int(fields[3]) == sid and fields[0] != "Z":
            pids.append(int(entry.name))
    return pids


@pytest.mark.parametrize("sig", [signal.SIGKILL, signal.SIGTERM])
def test_killing_the_sweep_leaves_no_process_and_no_write(tmp_path, sig):
    out = tmp_path / "s"
    cmd = [sys.executable, "-m", "contactdyn.cli", "sweep", "b1", *FAST, "--range",
           "contact.tip.normal.k=5e4:2e5:200:log", "--workers", "2", "--chunk", "4", "--quiet", "--out", str(out)]
    proc = subprocess.Popen(cmd, env=_env(), stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                            start_new_session=True)
    runs = out / "runs"
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline and len(list(runs.glob("*.npz"))) < 3 and proc.poll() is None:
        time.sleep(0.01)
    assert proc.poll() is None, "the sweep ended before it could be killed"
    assert len(_session(proc.pid)) >= 3  # parent, forkserver, workers (and the resource tracker)
    os.kill(proc.pid, sig)
    proc.wait(timeout=30)
    deadline = time.monotonic() + 10
    while _session(proc.pid) and time.monotonic() < deadline:
        time.sleep(0.05)
    assert _session(proc.pid) == [], "processes outlived the sweep"
    files = {p.name: p.stat().st_mtime_ns for p in runs.iterdir()}
    time.sleep(1.0)
    assert {p.name: p.stat().st_mtime_ns for p in runs.iterdir()} == files, "a file was written after the kill"
    assert len([n for n in files if n.endswith(".npz")]) < 200


def test_a_second_sweep_into_the_same_folder_is_refused(capsys, tmp_path):
    out = tmp_path / "s"
    (out / "runs").mkdir(parents=True)
    tmp = out / "runs" / ".abc.npz.x.tmp"  # the first sweep's file in flight
    tmp.write_bytes(b"partial")
    held = lock_out(out)
    try:
        code = main(["sweep", "b1", *FAST, "--out", str(out), "--workers", "0", "-q"])
    finally:
        held.close()
    err = capsys.readouterr().err
    assert code == EXIT_USAGE
    assert "--out: expected a folder no other sweep is writing to" in err and f"process {os.getpid()}" in err
    assert tmp.read_bytes() == b"partial"  # not deleted


def test_a_pool_broken_while_its_chunks_go_in_runs_the_rest_each_in_its_own_process(monkeypatch):
    """A worker can die before the last chunk is submitted (a loaded machine: the pool's manager sees it first):
    ``submit`` then raises BrokenProcessPool. The chunks it refused go to the isolated runs with the others whose
    worker died; nothing is lost and nothing raises."""
    from concurrent.futures import Future
    from concurrent.futures.process import BrokenProcessPool

    from contactdyn.sweep import execute

    class Pool:  # the first chunk runs; the pool breaks before the second goes in
        submitted = 0

        def submit(self, fn, *args):
            Pool.submitted += 1
            if Pool.submitted > 1:
                raise BrokenProcessPool("A child process terminated abruptly, the process pool is not usable anymore")
            done = Future()
            done.set_result(("pool", args[-1]))
            return done

        def shutdown(self, wait=True, cancel_futures=False):
            pass

    monkeypatch.setattr(execute, "process_pool", lambda n: Pool())
    monkeypatch.setattr(execute, "run_isolated", lambda ctx, fn, args, runs, n: iter([("isolated", runs)]))
    out = list(execute._execute_pool(("doc", "file", "dir"), [[1, 2], [3, 4], [5]], 2))
    assert out == [("pool", [1, 2]), ("isolated", [3, 4, 5])]
