"""A scene's first run (contactdyn.first_run): the compiled call's functions interpreted while its kind is not built,
the compiled call after;
the kind ignores values, not laws; one background build per kind; a failed build leaves no marker."""

from __future__ import annotations

import contextlib
import io
import json
import os
import re
import shutil
import subprocess
import sys
import types
from pathlib import Path

import pytest

from contactdyn import first_run
from contactdyn.cli import EXIT_OK, main
from contactdyn.errors import SceneError, SimulationError
from contactdyn.model.paths import INTERPRETED, PIPELINE
from contactdyn.scene.scene_file import load_scene

FAST = ["--set", "duration=0.05", "--set", "solver.output_rate=200"]


@pytest.fixture
def markers(tmp_path, monkeypatch):
    """The kinds' markers in a folder of this test (not the build's compile cache)."""
    monkeypatch.setattr(first_run, "_folder", lambda: tmp_path / "kinds")
    return tmp_path / "kinds"


def test_a_kind_ignores_the_values_and_sees_the_laws():
    base = load_scene("b1")
    assert first_run.kind(base) == first_run.kind(load_scene("b1", {"contact.tip.normal.k": 3.3e4, "duration": 0.7}))
    assert first_run.kind(base) == first_run.kind(load_scene("b1", {"solver.output_rate": 200}))  # an int as well
    assert first_run.kind(base) != first_run.kind(load_scene("b1", {"solver.method": "Radau"}))
    assert first_run.kind(base) != first_run.kind(load_scene("b1_force_loop"))


def test_auto_is_interpreted_until_the_kind_is_built_then_compiled(markers):
    scene = load_scene("b1")
    choice = first_run.choose(scene, "auto")
    assert (choice.path, choice.interpreted, choice.build) == ("interpreted", True, True)
    assert "background" in choice.line() and "interpreted" in choice.line()
    markers.mkdir()
    (markers / f"{first_run.kind(scene)}.built").touch()
    choice = first_run.choose(scene, "auto")
    assert (choice.compiled, choice.build, choice.line()) == (True, False, "")
    assert first_run.choose(scene, "interpreted").interpreted
    assert first_run.choose(load_scene("case1_cart"), "compiled").compiled


def test_a_path_not_among_the_paths_is_one_message_naming_the_option():
    scene = load_scene("b1")
    with pytest.raises(SceneError, match=r"--path: expected one of auto, compiled, interpreted, found 'fast'") as err:
        first_run.choose(scene, "fast")
    assert scene.file in str(err.value)


def test_a_scene_with_an_articulated_or_free_body_starts_a_build_as_any_other(markers):
    """A body with revolute joints (the lever) and a free body (drop_box, either chart) run on the compiled call,
    so their first runs start a build as any other scene's."""
    for name in ("lever", "drop_box"):
        choice = first_run.choose(load_scene(name), "auto")
        assert (choice.path, choice.build) == ("interpreted", True), name


def test_one_build_per_kind_at_a_time_and_a_dead_one_is_taken_over(markers):
    assert first_run._lock(markers, "k")
    assert not first_run._lock(markers, "k")  # a build of the kind is starting (no process written yet)
    (markers / "k.building").write_text(str(os.getpid()))
    assert not first_run._lock(markers, "k")  # its process runs
    dead = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"], capture_output=True, text=True)
    (markers / "k.building").write_text(dead.stdout.strip())
    assert first_run._lock(markers, "k")  # its process ended without removing the lock: taken over
    os.utime(markers / "k.building", (0.0, 0.0))  # written at the epoch: far more than BUILD_TIMEOUT ago
    assert first_run._lock(markers, "k")  # an old lock with no process written: taken over


def test_the_build_is_started_detached_on_this_package_with_the_file_it_was_read_from(markers, monkeypatch):
    started = []

    class Popen:
        def __init__(self, argv, **options):
            started.append((argv, options))
            self.pid, self.stdin = os.getpid(), io.BytesIO()  # (a process that runs)

    monkeypatch.setattr(first_run.subprocess, "Popen", Popen)
    scene = load_scene("b1")
    assert first_run.build_in_background(scene)
    (argv, options), = started
    assert argv[1:4] == ["-P", "-m", "contactdyn.first_run"]  # -P: not a contactdyn of the working directory
    assert argv[4] == str(Path(scene.file).resolve()) and argv[5].endswith(first_run.kind(scene))
    package_root = str(Path(first_run.__file__).resolve().parents[1])
    assert options["env"]["PYTHONPATH"].split(os.pathsep)[0] == package_root
    assert (markers / f"{first_run.kind(scene)}.building").read_text() == str(os.getpid())
    assert not first_run.build_in_background(scene)  # one at a time


def test_the_command_runs_interpreted_says_so_and_asks_for_one_build(markers, monkeypatch, capsys):
    from contactdyn import cli

    asked, order = [], []
    monkeypatch.setattr(first_run, "build_in_background", lambda scene: asked.append(scene) or True)
    monkeypatch.setattr(first_run, "leaves_ahead", lambda scene: order.append(("helper", scene.name)) or True)
    run = cli._simulate_quietly
    monkeypatch.setattr(cli, "_simulate_quietly", lambda *a, **k: order.append(("run", a[1].name)) or run(*a, **k))
    code = main(["run", "b1", *FAST, "--path", "auto", "--json"])
    doc = json.loads(capsys.readouterr().out)
    assert code == EXIT_OK and len(asked) == 1 and asked[0].name == "b1"
    assert order == [("helper", "b1"), ("run", "b1")]  # the leaves' helper: started before the run
    assert {row["path"] for row in doc["stats"]["paths"].values()} == {INTERPRETED}
    main(["run", "b1", *FAST, "--path", "auto"])
    assert "built in the background" in capsys.readouterr().err
    assert main(["run", "b1", *FAST, "--path", "auto", "--set", "robot.q0=[0.1]"]) == 2  # bad input: no build
    assert len(asked) == 2 and capsys.readouterr().err.count("\n") == 1


def test_the_readable_path_is_gone(monkeypatch, capsys):
    """``--path readable`` (the readable model's run) no longer exists: argparse rejects it in one line naming the
    paths there are, and so does ``CONTACTDYN_PATH=readable``."""
    assert first_run.PATHS == ("auto", "compiled", "interpreted")
    assert main(["run", "b1", *FAST, "--path", "readable"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1, err
    # (argparse quotes the choices with repr in older Pythons, not in newer ones)
    assert re.search(r"argument --path: invalid choice: 'readable' \(choose from '?auto'?, '?compiled'?, "
                     r"'?interpreted'?\)", err), err
    monkeypatch.setenv("CONTACTDYN_PATH", "readable")
    assert main(["run", "b1", *FAST]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "CONTACTDYN_PATH: expected one of auto, compiled, interpreted, found 'readable'" \
        in err, err


def test_a_bad_path_in_the_environment_is_one_message(monkeypatch, capsys):
    monkeypatch.setenv("CONTACTDYN_PATH", "fast")
    assert main(["run", "b1", *FAST]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "CONTACTDYN_PATH" in err and "fast" in err


@pytest.mark.parametrize("duration, built_for", [(0.05, 0.05), (600.0, 60.0)])  # [s]: a long one for a minute
def test_the_build_runs_compiled_and_marks_the_kind(markers, monkeypatch, duration, built_for):
    scene = load_scene("b1", {"duration": duration})
    ran = []
    monkeypatch.setattr(sys.modules["contactdyn.simulate"], "simulate",
                        lambda s, overrides, compiled: ran.append((s.document, overrides, compiled)))
    markers.mkdir()
    (markers / "x.building").touch()
    monkeypatch.setattr("sys.stdin", io.StringIO(json.dumps(scene.document)))
    monkeypatch.setattr("os.nice", lambda n: 0)
    assert first_run.main([scene.file, str(markers / "x")]) == 0
    assert ran == [(scene.document, {"duration": built_for}, True)]
    assert (markers / "x.built").is_file() and not (markers / "x.building").exists()


def test_a_failed_build_is_recorded_and_said_and_not_retried(markers, monkeypatch):
    markers.mkdir()
    (markers / "y.building").touch()
    monkeypatch.setattr("sys.stdin", io.StringIO(json.dumps({"duration": "not a number"})))
    monkeypatch.setattr("os.nice", lambda n: 0)
    assert first_run.main(["nowhere.toml", str(markers / "y")]) == 1
    assert [p.name for p in markers.iterdir()] == ["y.failed"] and "duration" in (markers / "y.failed").read_text()
    scene = load_scene("b1")
    (markers / f"{first_run.kind(scene)}.failed").write_text("SceneError: ...")
    choice = first_run.choose(scene, "auto")
    assert (choice.path, choice.build) == ("interpreted", False) and "failed to build" in choice.line()
    first_run.mark_built(scene)  # (a run with --path compiled)
    assert first_run.choose(scene, "auto").compiled and not (markers / f"{first_run.kind(scene)}.failed").exists()


def test_the_interpreted_run_and_the_compiled_run_agree():
    from contactdyn import simulate

    interpreted = simulate("b1", {"duration": 0.2}, compiled=False)
    compiled = simulate("b1", {"duration": 0.2})
    assert {row["path"] for row in interpreted.stats["paths"].values()} == {INTERPRETED}
    assert {row["path"] for row in compiled.stats["paths"].values()} == {PIPELINE}
    F_i, F_c = interpreted["contact.tip.F_n"], compiled["contact.tip.F_n"]
    assert abs(F_i - F_c).max() <= 1e-6 * abs(F_c).max()


def test_a_bad_default_path_is_named():
    with pytest.raises(SceneError, match="CONTACTDYN_PATH.*auto, compiled, interpreted, found 'fast'"):
        first_run.default_path({"CONTACTDYN_PATH": "fast"})
    assert first_run.default_path({}) == "auto"


def test_a_run_on_the_compiled_call_marks_its_kind(markers, capsys):
    scene = load_scene("b1", {"duration": 0.05, "solver.output_rate": 200.0})
    assert not first_run.built(scene)
    assert main(["run", "b1", *FAST, "--path", "compiled", "--quiet"]) == EXIT_OK
    assert first_run.built(scene) and first_run.choose(scene, "auto").compiled


def test_a_failure_on_the_compiled_call_is_diagnosed_in_one_line(capsys):
    """case1_cart run for 20 s with its cart at 1 m/s (0.25 in the scene) fails at ~3.85 s (its contact turns stiff;
    at 0.25 m/s at ~12.3 s); on the compiled call, as on the same call interpreted, the command prints one line with
    the cause (the diagnosis evaluates the failure's state: a strided column of the solution once reached the
    compiled call as a new array layout and failed to compile)."""
    faster = ["--set", "body.cart.velocity0=1.0", "--set", "body.cart.servo={velocity=1.0, gain=5e4}"]
    for path in ("compiled", "interpreted"):
        code = main(["run", "case1_cart", "--set", "duration=20", *faster, "--path", path, "--quiet"])
        err = capsys.readouterr().err
        assert code == 1 and err.count("\n") == 1 and "integration failed at t = 3.846" in err, (path, err[-300:])
        assert "Traceback" not in err and "fastest mode" in err


def test_the_recorded_leaves_are_the_ones_the_interpreted_run_compiles_and_none_is_compiled_to_record_them(
        monkeypatch):
    """The leaves' helper's record (RecordingTwins): each leaf the scene reaches, once per argument types, as numba
    types them where the interpreted run calls it compiled: the very signatures that run compiles (or loads). Each
    leaf is replaced by a fresh dispatcher of its function (numba's cache shared with it): recording gives none a
    signature; the interpreted run after it gives each exactly the recorded ones."""
    import importlib

    from contactdyn.hybrid.loop import HybridRun
    from contactdyn.model.system import System
    from contactdyn.numerics.compile_cache import njit
    from contactdyn.numerics.twins import LATE_LEAVES, LEAVES, RecordingTwins

    fresh = {}
    for name in LEAVES:
        module, _, function = name.rpartition(".")
        leaf = getattr(importlib.import_module(module), function)
        if not leaf._can_compile:  # (fixed signatures: compiled at import)
            continue
        fresh[name] = njit(leaf.py_func, cache=True)
        for held in [m for n, m in sys.modules.items() if n.startswith("contactdyn.")]:  # (every module's name of it)
            for attribute, value in list(vars(held).items()):
                if value is leaf:
                    monkeypatch.setattr(held, attribute, fresh[name])
    scene = load_scene("case1_cart", {"duration": first_run.RECORD_DURATION})
    recorder = RecordingTwins()
    HybridRun(System(scene), interpreted=True, twins=recorder).run(0.0)
    assert {name: leaf.signatures for name, leaf in fresh.items() if leaf.signatures} == {}  # none compiled
    names = [f"{leaf.py_func.__module__}.{leaf.py_func.__qualname__}" for leaf, _ in recorder.calls]
    assert {"contactdyn.robot.rigid_body._kinematics", "contactdyn.robot.rigid_body._jacobians",
            "contactdyn.robot.rigid_body._inertia"} <= set(names) <= LEAVES | set(LATE_LEAVES)
    assert len(set(map(repr, recorder.calls))) == len(recorder.calls)  # once per leaf and types
    from contactdyn import simulate

    simulate(scene, interpreted=True)
    recorded = {(name, types_) for name, (_, types_) in zip(names, recorder.calls, strict=True) if name in fresh}
    compiled = {(name, tuple(types_)) for name, leaf in fresh.items() for types_ in leaf.signatures}
    assert recorded == compiled


class _Leaf:
    """A leaf as compile_claimed sees it: ``compile(types)`` appends to ``done``; ``fails``: as numba says it of a leaf
    of fixed signatures; ``then``: called after it compiles."""

    def __init__(self, name, done, fails=False, then=None):
        self.name, self.done, self.fails, self.then = name, done, fails, then
        self.py_func = types.SimpleNamespace(__module__="tests.leaves", __qualname__=name)

    def compile(self, types_):
        if self.fails:
            raise RuntimeError("compilation disabled")
        self.done.append((self.name, types_))
        if self.then is not None:
            self.then()


def _hold(leaf, types_):
    """The claim of (leaf, types) held as another process would hold it (flock: one per open file)."""
    claim = first_run._claim(leaf, types_)
    assert claim is not None and not isinstance(claim, contextlib.nullcontext)
    return claim


def test_the_helper_compiles_the_last_reached_leaf_first_skips_one_claimed_and_leaves_what_fails(markers):
    done = []
    a, b, c, d = (_Leaf(n, done, fails=n == "b") for n in "abcd")
    with _hold(d, (4,)):  # (the run compiles d)
        first_run.compile_claimed([(a, (1,)), (b, (2,)), (c, (3,)), (d, (4,))], backwards=True)
    assert done == [("c", (3,)), ("a", (1,))]


def test_the_run_compiles_its_leaves_first_reached_first_and_waits_for_one_the_helper_holds(markers):
    """The helper holds b's claim until the run has compiled c: the run goes on to c, then waits for b and takes it
    (numba loads it from the cache then). Its claims are released: the helper can take each after it."""
    done = []
    held = {}
    a, c = _Leaf("a", done), _Leaf("c", done, then=lambda: held.pop("b").close())
    b = _Leaf("b", done)
    held["b"] = _hold(b, (2,))
    first_run.compile_claimed([(a, (1,)), (b, (2,)), (c, (3,))])
    assert done == [("a", (1,)), ("c", (3,)), ("b", (2,))] and held == {}
    for leaf, types_ in ((a, (1,)), (b, (2,)), (c, (3,))):
        with _hold(leaf, types_):
            pass
    assert len(list((markers / first_run.CLAIMS).iterdir())) == 3  # one claim per leaf and types


def test_a_run_that_waited_too_long_for_a_claim_compiles_the_leaf_itself(markers, monkeypatch):
    monkeypatch.setattr(first_run, "CLAIM_WAIT", 0.0)
    done = []
    b = _Leaf("b", done)
    with _hold(b, (2,)):
        first_run.compile_claimed([(b, (2,))])
    assert done == [("b", (2,))]


def test_the_command_compiles_the_runs_leaves_before_it_runs_only_beside_a_helper(markers, monkeypatch):
    from contactdyn import cli

    order = []
    monkeypatch.setattr(first_run, "build_in_background", lambda scene: True)
    monkeypatch.setattr(first_run, "leaves_first", lambda scene: order.append(("leaves", scene.name)))
    run = cli._simulate_quietly
    monkeypatch.setattr(cli, "_simulate_quietly", lambda *a, **k: order.append(("run", a[1].name)) or run(*a, **k))
    for started in (True, False):
        monkeypatch.setattr(first_run, "leaves_ahead", lambda scene, started=started: started)
        assert main(["run", "b1", *FAST, "--path", "auto", "--quiet"]) == EXIT_OK
    assert order == [("leaves", "b1"), ("run", "b1"), ("run", "b1")]


def test_a_first_runs_own_record_is_the_helpers_and_it_hands_it_to_compile_claimed_forwards(monkeypatch):
    got = []
    monkeypatch.setattr(first_run, "compile_claimed", lambda calls, backwards=False: got.append((calls, backwards)))
    monkeypatch.setattr(first_run, "RUN_RECORD_LIMIT", 60.0)  # (the whole record, also on a slow machine)
    scene = load_scene("case1_cart")
    first_run.leaves_first(scene)
    names = [leaf.py_func.__qualname__ for leaf, _ in got[0][0]]
    assert len(got) == 1 and got[0][1] is False and {"_kinematics", "_inertia", "lu_solve"} <= set(names)
    assert names[-3:] == ["horner_rows", "horner_at", "pinv"]  # the output's and an event's interpolant, the push's
    record = first_run.record_leaves(scene.file, scene.document, 60.0)
    assert got[0][0] == [call for call in record if call[0].py_func.__qualname__ not in ("robot_terms", "frame_terms")]
    assert len(record) == len(got[0][0]) + 2  # (the late leaves, the helper's after: the robot's and frames' terms)
    monkeypatch.setattr(first_run, "record_leaves", lambda *a: 1 / 0)
    first_run.leaves_first(scene)  # (a failure is left to the run)
    assert len(got) == 1


def test_the_record_reaches_the_leaves_of_a_later_phase_started_at_the_scenes_start(monkeypatch):
    """case1_cart's push (its second phase) runs the dynamic position law, whose J⁺ (``pinv``) the approach never
    calls: the record holds it, after the first phase's leaves; a phase that cannot start adds nothing."""
    scene = load_scene("case1_cart")
    starts = first_run._phase_starts(scene.document)
    assert [[p["name"] for p in d["phase"]] for d in starts] == [["approach", "push"], ["push"]]
    assert first_run._phase_starts(load_scene("b1").document) == [load_scene("b1").document]
    names = [leaf.py_func.__qualname__ for leaf, _ in first_run.record_leaves(scene.file, scene.document, 60.0)]
    approach = {**scene.document, "phase": scene.document["phase"][:1]}
    first = [leaf.py_func.__qualname__ for leaf, _ in first_run.record_leaves(scene.file, approach, 60.0)]
    assert "pinv" in names and "pinv" not in first and names[:len(first)] == first
    record = first_run._record

    def push_fails(file, document, recorder):
        if document["phase"][0]["name"] == "push":
            raise SimulationError("cannot start there")
        record(file, document, recorder)

    monkeypatch.setattr(first_run, "_record", push_fails)
    assert [leaf.py_func.__qualname__ for leaf, _ in first_run.record_leaves(scene.file, scene.document, 60.0)] == first
    started = []
    monkeypatch.setattr(first_run, "_record", lambda file, document, recorder: started.append(document["phase"][0]))
    first_run.record_leaves(scene.file, scene.document, -1.0)  # past its deadline: no later phase is started
    assert [p["name"] for p in started] == ["approach"]


def test_the_leaves_helper_needs_a_second_core_and_runs_one_at_a_time(markers, monkeypatch):
    started = []
    monkeypatch.setattr(first_run, "_start", lambda scene, marker, *options: started.append(options) or True)
    scene = load_scene("b1")
    monkeypatch.setattr(first_run, "_cores", lambda: 1)
    assert not first_run.leaves_ahead(scene) and started == []
    monkeypatch.setattr(first_run, "_cores", lambda: 2)
    assert first_run.leaves_ahead(scene) and started == [("--leaves",)]
    assert not first_run.leaves_ahead(scene) and len(started) == 1  # its lock is held
    (markers / f"{first_run.LEAVES_LOCK}.building").unlink()
    monkeypatch.setenv(first_run.HELPER_ENV, "0")
    assert not first_run.leaves_ahead(scene) and len(started) == 1  # turned off
    monkeypatch.setenv(first_run.HELPER_ENV, "1")
    assert first_run.leaves_ahead(scene) and len(started) == 2


def test_the_helper_hands_its_record_to_compile_claimed_marks_the_kind_and_records_no_failure(markers, monkeypatch):
    from contactdyn.numerics.twins import LATE_LEAVES, name_of

    compiled, late = [], []
    monkeypatch.setattr(first_run, "compile_claimed", lambda calls, backwards: compiled.append((calls, backwards)))
    monkeypatch.setattr(first_run, "_compile", lambda leaf, types_: late.append(name_of(leaf)) or True)
    monkeypatch.setattr("os.nice", lambda n: 0)
    scene = load_scene("b1")
    markers.mkdir()
    lock = markers / f"{first_run.LEAVES_LOCK}.building"
    lock.touch()
    monkeypatch.setattr("sys.stdin", io.StringIO(json.dumps(scene.document)))
    assert first_run.main(["--leaves", scene.file, str(markers / first_run.LEAVES_LOCK)]) == 0
    assert len(compiled) == 1 and compiled[0][0] and compiled[0][1] is True and not lock.exists()
    done = markers / f"{first_run.kind(scene)}.leaves"
    assert sorted(p.name for p in markers.iterdir()) == sorted([done.name, first_run.CLAIMS])
    assert late == list(LATE_LEAVES[1:])  # b1's: all but the operational law's, in their order
    assert len(list((markers / first_run.CLAIMS).glob("*.arrived"))) == len(late)
    monkeypatch.setattr(first_run, "_cores", lambda: 2)
    assert not first_run.leaves_ahead(scene)  # (a helper did this kind)
    done.unlink()
    shutil.rmtree(markers / first_run.CLAIMS)
    lock.touch()
    monkeypatch.setattr("sys.stdin", io.StringIO(json.dumps({})))  # (no scene: the helper fails)
    assert first_run.main(["--leaves", scene.file, str(markers / first_run.LEAVES_LOCK)]) == 1
    assert list(markers.iterdir()) == []  # no marker of a failure: the run reports its own


def test_the_helper_is_started_detached_with_its_option_and_not_beside_the_kinds_build(markers, monkeypatch):
    started = []

    class Popen:
        def __init__(self, argv, **options):
            started.append(argv)
            self.pid, self.stdin = os.getpid(), io.BytesIO()

    monkeypatch.setattr(first_run.subprocess, "Popen", Popen)
    monkeypatch.setattr(first_run, "_cores", lambda: 2)
    scene = load_scene("b1")
    assert first_run.build_in_background(scene) and not first_run.leaves_ahead(scene)  # (its build runs)
    (markers / f"{first_run.kind(scene)}.building").unlink()
    assert first_run.leaves_ahead(scene)
    assert started[-1][1:] == ["-P", "-m", "contactdyn.first_run", "--leaves", str(Path(scene.file).resolve()),
                               str(markers / first_run.LEAVES_LOCK)]
    assert (markers / f"{first_run.LEAVES_LOCK}.building").read_text() == str(os.getpid())


def test_the_recording_stops_at_its_deadline_keeping_what_it_has():
    from contactdyn.hybrid.loop import HybridRun
    from contactdyn.model.system import System
    from contactdyn.numerics.twins import RecordingTwins

    recorder = RecordingTwins(deadline=0.0)  # (already past)
    with pytest.raises(RecordingTwins.Enough):
        HybridRun(System(load_scene("b1", {"duration": 1e-3})), interpreted=True, twins=recorder).run(0.0)
    assert recorder.calls == []


@pytest.mark.parametrize("quota, cores", [("100000 100000\n", 1), ("150000 100000\n", 1), ("200000 100000\n", 2),
                                          ("max 100000\n", 2), ("nonsense\n", 2)])
def test_a_containers_cpu_quota_counts_as_cores(tmp_path, monkeypatch, quota, cores):
    """A container limited to one CPU's time (cgroup v2's cpu.max) gets no helper beside its run, whatever its
    affinity shows."""
    monkeypatch.setattr(first_run.os, "sched_getaffinity", lambda pid: {0, 1}, raising=False)
    monkeypatch.setattr(first_run, "CPU_QUOTA", tmp_path / "cpu.max")
    (tmp_path / "cpu.max").write_text(quota)
    assert first_run._cores() == cores
    (tmp_path / "cpu.max").unlink()
    assert first_run._cores() == 2


def test_a_file_system_that_does_not_lock_gives_claims_that_hold_nothing(markers, monkeypatch):
    """flock failing otherwise than "held" (ENOLCK on some network file systems): no claims, each process compiles
    what it reaches, nobody waits."""
    import fcntl

    def no_locks(handle, operation):
        raise OSError(37, "No locks available")

    monkeypatch.setattr(fcntl, "flock", no_locks)
    done = []
    claim = first_run._claim(_Leaf("a", done), (1,), wait=60.0)
    assert isinstance(claim, contextlib.nullcontext)
    first_run.compile_claimed([(_Leaf("a", done), (1,))])
    assert done == [("a", (1,))]


def test_the_helper_compiles_the_late_leaves_after_the_others_in_their_order_and_marks_each_arrived(markers,
                                                                                                    monkeypatch):
    """A record holding late leaves: the helper's claimed compile gets the others (backwards), the kind is marked,
    then the late leaves compile in LATE_LEAVES' order (not the order reached) and arrive (one that fails does not);
    the run's own record leaves them out."""
    from contactdyn.numerics import twins

    done = []
    a, b = _Leaf("a", done), _Leaf("b", done)
    first, second, broken = _Leaf("first", done), _Leaf("second", done), _Leaf("broken", done, fails=True)
    monkeypatch.setattr(twins, "LATE_LEAVES", (*twins.LATE_LEAVES, *(f"tests.leaves.{n}" for n in
                                                                     ("first", "broken", "second"))))
    record = [(a, (1,)), (second, (2,)), (broken, (3,)), (b, (4,)), (first, (5,))]
    monkeypatch.setattr(first_run, "record_leaves", lambda *args: list(record))
    scene = load_scene("b1")
    kind_done = markers / f"{first_run.kind(scene)}.leaves"
    real = first_run.compile_claimed

    def claimed(calls, backwards=False):
        assert not kind_done.exists() and not first_run.arrived(first, (5,))  # (before the late ones)
        real(calls, backwards)

    monkeypatch.setattr(first_run, "compile_claimed", claimed)
    first_run.compile_leaves(scene.file, scene.document, str(markers / first_run.LEAVES_LOCK))
    assert done == [("b", (4,)), ("a", (1,)), ("first", (5,)), ("second", (2,))] and kind_done.is_file()
    assert first_run.arrived(first, (5,)) and first_run.arrived(second, (2,)) and not first_run.arrived(first, (2,))
    assert not first_run.arrived(broken, (3,))
    got = []
    monkeypatch.setattr(first_run, "compile_claimed", lambda calls, backwards=False: got.append(calls))
    first_run.leaves_first(scene)
    assert got == [[(a, (1,)), (b, (4,))]]


def test_only_an_interpreted_run_of_the_path_auto_takes_late_leaves(markers):
    from contactdyn.numerics import twins

    scene = load_scene("b1")
    taken = []
    for path in ("auto", "interpreted", "compiled"):
        choice = first_run.choose(scene, path)
        with first_run.arrivals(choice):
            taken.append(twins.Twins().arrived)
    assert taken == [first_run.arrived, None, None] and twins.Twins().arrived is None
    first_run.mark_built(scene)
    with first_run.arrivals(first_run.choose(scene, "auto")):  # (built: compiled)
        assert twins.Twins().arrived is None
