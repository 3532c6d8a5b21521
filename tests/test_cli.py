"""The command line: help and examples, list, run, exit codes, bad input without tracebacks, lazy dispatch."""

from __future__ import annotations

import json
import sys
import types

import numpy as np
import pytest

from contactdyn.cli import EXIT_FAILED, EXIT_OK, EXIT_USAGE, main
from contactdyn.output.result import load_result

FAST = ["--set", "duration=0.05", "--set", "solver.output_rate=200"]  # ~20 ms runs of b1


def _run(capsys, argv):
    code = main(argv)
    out, err = capsys.readouterr()
    assert "Traceback" not in out + err
    return code, out, err


@pytest.mark.parametrize("command", ["list", "run", "sweep", "view", "plot", "bench"])
def test_every_subcommand_has_help_with_an_example(capsys, command):
    code, out, _ = _run(capsys, [command, "--help"])
    assert code == EXIT_OK
    assert "example" in out and f"contactdyn {command}" in out


def test_top_level_help_documents_exit_codes(capsys):
    code, out, _ = _run(capsys, ["--help"])
    assert code == EXIT_OK
    assert "Exit codes" in out and "2 bad input" in out
    for command in ("list", "run", "sweep", "view", "plot", "bench"):
        assert command in out


def test_list_text_and_json(capsys):
    code, out, _ = _run(capsys, ["list"])
    assert code == EXIT_OK
    for word in ("scenes:", "b1", "planar2r_b1", "ur5", "chain", "friction", "task_pd", "DOP853", "Radau"):
        assert word in out
    code, out, _ = _run(capsys, ["list", "--json"])
    doc = json.loads(out)
    assert {s["name"] for s in doc["scenes"]} >= {"b1"}
    assert {"planar2r_b1", "writer2r", "panda"} <= {r["name"] for r in doc["robots"]}
    assert [m["name"] for m in doc["models"]["normal"]] == ["rigid", "a", "b", "c", "chain"]
    assert [m["name"] for m in doc["models"]["tangent"]] == ["free", "friction", "chain"]
    assert {"task_pd", "joint_pd"} <= {c["name"] for c in doc["controllers"]}
    assert {"name": "BDF", "implicit": True, "description": "implicit, for stiff scenes"} in doc["integrators"]
    code, out, _ = _run(capsys, ["list", "integrators", "--json"])
    assert list(json.loads(out)) == ["integrators"]


def test_run_text_json_quiet_and_out(capsys, tmp_path):
    code, out, _ = _run(capsys, ["run", "b1", *FAST])
    assert code == EXIT_OK and "contact tip: normal force peak" in out
    code, out, _ = _run(capsys, ["run", "b1", *FAST, "--quiet"])
    assert code == EXIT_OK and out == ""
    code, out, _ = _run(capsys, ["run", "b1", *FAST, "--json", "--out", str(tmp_path / "r")])
    doc = json.loads(out)
    assert code == EXIT_OK and doc["status"] == "ok" and doc["scene"] == "b1"
    saved = load_result(tmp_path / "r")
    F = saved["contact.tip.F_n"]
    assert doc["metrics"]["contact.tip.F_peak"] == pytest.approx(F.max(), rel=0, abs=0)
    assert doc["metrics"]["contact.tip.F_final"] == F[-1]
    assert doc["metrics"]["contact.tip.impulse_n_first"] is None  # bonded contact: no impact; NaN becomes null
    assert len(saved.t) == 11  # 0.05 s at 200 Hz, both ends


@pytest.mark.parametrize("argv, words", [
    (["run", "b1", "--set", "contact.tip.normal.kk=1e4"], ["contact.tip.normal.kk", "did you mean 'k'"]),
    (["run", "b1", "--set", "duration=abc"], ["duration", "expected a number", "'abc'"]),
    (["run", "b1", "--set", "duration=nan"], ["duration", "finite"]),
    (["run", "b1", "--set", "duration=-inf"], ["duration", "finite"]),
    (["run", "b1", "--set", "contact.tip.tangent.mu=-0.1"], ["contact.tip.tangent.mu", ">= 0"]),
    (["run", "b1", "--set", "solver.method=DOP85"], ["solver.method", "did you mean 'DOP853'"]),
    (["run", "b1", "--set", "robot.q0=[1.0]"], ["robot.q0", "2 joint values"]),
    (["run", "b1", "--set", "robot.urdf=ur55"], ["robot", "did you mean ur5"]),
    (["run", "b1", "--set", "duration"], ["--set", "key.path=value"]),
    (["run", "b1x"], ["scene", "did you mean b1"]),
    (["sweep", "b1", "--grid", "controller.kpp=1,2", "--workers", "0"], ["controller.kpp", "did you mean 'kp'"]),
    (["sweep", "b1", "--range", "controller.kp=1:2"], ["--range", "lo:hi:n"]),
    (["sweep", "b1", "--range", "controller.kp=-1:2:3:log"], ["lo > 0"]),
    (["sweep", "b1", "--workers", "x"], ["--workers", "invalid int"]),
    (["bench", "b1", "--rtols", "1e-4,abc"], ["--rtols", "comma-separated numbers"]),
    (["nosuchcommand"], ["invalid choice"]),
    (["run"], ["required", "scene"]),
])
def test_bad_input_is_one_message_and_exit_2(capsys, argv, words):
    code, out, err = _run(capsys, argv)
    assert code == EXIT_USAGE, err
    assert len(err.strip().splitlines()) <= 2, err  # one message (+ a pointer to --help for misuse)
    for word in words:
        assert word in err


def test_bad_files_name_the_file(capsys, tmp_path):
    bad_toml = tmp_path / "broken.toml"
    bad_toml.write_text("name = 'x'\nduration = = 1\n")
    not_utf8 = tmp_path / "binary.toml"
    not_utf8.write_bytes(b"name = '\xff\xfe'\n")
    for path, word in ((bad_toml, "valid TOML"), (not_utf8, "UTF-8")):
        code, _, err = _run(capsys, ["run", str(path)])
        assert code == EXIT_USAGE and str(path) in err and word in err


def test_unwritable_output_is_bad_input(capsys, tmp_path):
    blocker = tmp_path / "a_file"
    blocker.write_text("")
    for argv in (["run", "b1", *FAST, "--out", str(blocker / "run")],
                 ["sweep", "b1", *FAST, "--workers", "0", "--out", str(blocker)]):
        code, _, err = _run(capsys, argv)
        assert code == EXIT_USAGE and str(blocker) in err


def test_json_mode_reports_errors_on_stdout_too(capsys):
    code, out, err = _run(capsys, ["run", "b1", "--json", "--set", "duration=0"])
    assert code == EXIT_USAGE
    assert json.loads(out) == {"status": "bad input", "error": err.split("error: ", 1)[1].strip(), "exit_code": 2}


def test_failed_run_exits_1(capsys):
    # b1 with these gains slips and sticks within 0.05 s: more than one event stops the run
    code, _, err = _run(capsys, ["run", "b1", *FAST, "--set", "controller.kp=1581.0", "--set", "solver.max_events=1"])
    assert code == EXIT_FAILED and "more than 1 events" in err


def test_absurd_magnitudes_are_bad_input_naming_the_key(capsys):
    # 1e308 rad/s once ended in "SVD did not converge" (exit 1); it is a typo, refused before the run
    code, _, err = _run(capsys, ["run", "b1", *FAST, "--set", "robot.v0=[1e308, 1e308]"])
    assert code == EXIT_USAGE and "robot.v0: expected numbers of magnitude <= 1e+12" in err


# ---- view, plot, bench: dispatched lazily to other modules ---------------------------------------
def _fake_module(monkeypatch, name, **functions):
    calls = []
    module = types.ModuleType(f"contactdyn.{name}")
    for fname in functions:
        setattr(module, fname, lambda *a, _f=fname: calls.append((_f, a)) or functions[_f])
    monkeypatch.setitem(sys.modules, f"contactdyn.{name}", module)
    return calls


@pytest.fixture(scope="module")
def saved_run(tmp_path_factory) -> str:
    path = tmp_path_factory.mktemp("runs") / "b1"
    assert main(["run", "b1", *FAST, "--quiet", "--out", str(path)]) == EXIT_OK
    return str(path)


def test_plot_view_bench_dispatch_with_their_arguments(capsys, monkeypatch, saved_run):
    calls = _fake_module(monkeypatch, "output.plots", plot_command=0)
    assert main(["plot", saved_run, "--out", "figs", "--format", "png,svg"]) == EXIT_OK
    (_, (args,)), = calls
    assert (args.run, args.out, args.format) == (saved_run, "figs", ["png", "svg"])

    calls = _fake_module(monkeypatch, "viewer", view_command=0)
    assert main(["view", saved_run, "--html", "b1.html", "--port", "7001", "--speed", "0.5"]) == EXIT_OK
    (_, (args,)), = calls
    assert (args.run, args.html, args.port, args.speed) == (saved_run, "b1.html", 7001, 0.5)

    calls = _fake_module(monkeypatch, "analysis.workprecision", bench_command=3)
    assert main(["bench", "b1", "--methods", "DOP853,RK45", "--rtols", "1e-4,1e-6", "--repeats", "2",
                 "--out", "wp", "--set", "duration=0.1"]) == 3
    (_, (args,)), = calls
    assert (args.scene, args.methods, args.rtols, args.repeats, args.out, args.set) == \
        ("b1", "DOP853,RK45", "1e-4,1e-6", 2, "wp", ["duration=0.1"])


def test_run_view_hands_the_result_to_the_viewer(capsys, monkeypatch):
    calls = _fake_module(monkeypatch, "viewer", view_result=0)
    assert main(["run", "b1", *FAST, "--view", "--quiet"]) == EXIT_OK
    (_, (result, args)), = calls
    assert np.all(np.isfinite(result["contact.tip.F_n"])) and args.view


@pytest.mark.parametrize("command", ["plot", "view"])
def test_plot_and_view_of_a_missing_run_is_bad_input(capsys, tmp_path, command):
    code, _, err = _run(capsys, [command, str(tmp_path / "nothing")])
    assert code == EXIT_USAGE and "not a saved run (need nothing.npz and nothing.json" in err


@pytest.mark.parametrize("argv", [["plot", "SAVED"], ["view", "SAVED"], ["bench", "b1"],
                                  ["run", "b1", *FAST, "--view", "--quiet"]])
def test_missing_module_is_one_line_and_exit_1(capsys, monkeypatch, saved_run, argv):
    argv = [saved_run if a == "SAVED" else a for a in argv]
    for name in ("output.plots", "viewer", "analysis.workprecision"):
        monkeypatch.setitem(sys.modules, f"contactdyn.{name}", None)  # import raises ImportError
    code, _, err = _run(capsys, argv)
    assert code == EXIT_FAILED and "not available yet" in err and len(err.strip().splitlines()) == 1


def test_a_reader_that_leaves_early_is_not_an_error():
    import subprocess

    # `contactdyn list robots | head -0`: the pipe is closed before the listing is written
    proc = subprocess.Popen([sys.executable, "-m", "contactdyn.cli", "list", "robots"], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)
    proc.stdout.close()
    err = proc.stderr.read()
    assert proc.wait(timeout=120) == 0 and "error" not in err, err


def test_help_imports_no_simulator():
    """``contactdyn --help`` stays light (≤ 1 s on a loaded machine): numba, numpy and Pinocchio are not imported."""
    import subprocess

    code = ("import sys; from contactdyn.cli import main\ntry:\n    main(['--help'])\nexcept SystemExit:\n    pass\n"
            "print(sorted(m for m in ('numba', 'numpy', 'pinocchio') if m in sys.modules))")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert done.stdout.strip().splitlines()[-1] == "[]", done.stderr


def test_python_dash_m_contactdyn_is_the_command():
    import subprocess

    from contactdyn import __version__

    done = subprocess.run([sys.executable, "-m", "contactdyn", "--version"], capture_output=True, text=True,
                          timeout=60)
    assert done.returncode == EXIT_OK and __version__ in done.stdout + done.stderr
