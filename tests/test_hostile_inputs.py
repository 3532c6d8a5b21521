"""Hostile inputs: bad scenes, URDFs, overrides and run files end in one clear line, never a crash.

Each case is a ``contactdyn`` command line with the exit code and a piece of the message it
must give. The cases run in batches, each batch in one subprocess (the interpreter's start
dominates a case) under a memory cap (RLIMIT_AS) and a timeout, so a case that crashes,
hangs or grows without bound fails the test instead of taking the test run down. Large
inputs (a 17 MB scene, a 1000-link URDF, a 16 GiB channel header) are generated here.
"""

from __future__ import annotations

import json
import math
import os
import resource
import subprocess
import sys
import zipfile
from pathlib import Path

import numpy as np
import pytest

import contactdyn
from contactdyn.scene.scene_file import sims_dir

ROOT = Path(contactdyn.__file__).parent.parent
RUNNER = Path(__file__).parent / "hostile_runner.py"
MEMORY_CAP = 2 * 2**30  #: [B] address space of a batch
BATCH_TIMEOUT = 240.0  #: [s] for one batch of cases
FAST = ["--set", "duration=0.01", "--set", "solver.output_rate=200"]
B1 = (sims_dir() / "b1.toml").read_text()
MOVE = '{ kind = "constant_velocity", delta = [-0.6, 0.0, 0.0], duration = 4.0 }'
LIMIT = '<limit lower="-6.283185307180" upper="6.283185307180" effort="500.0" velocity="20.0"/>'
INERTIAL = '<inertial><mass value="1"/><inertia ixx="1" iyy="1" izz="1" ixy="0" ixz="0" iyz="0"/></inertial>'

Case = tuple[str, list[str], int, str]  # id, argv, exit code, a piece of stderr ("" for none)


def _cap() -> None:
    resource.setrlimit(resource.RLIMIT_AS, (MEMORY_CAP, MEMORY_CAP))


def run_batch(cases: list[Case], cwd: Path) -> dict[str, dict]:
    payload = json.dumps([{"id": c[0], "argv": c[1]} for c in cases])
    env = {"PYTHONPATH": str(ROOT), "PATH": "/usr/bin:/bin", "HOME": str(cwd), "MPLBACKEND": "Agg",
           "OPENBLAS_NUM_THREADS": "1", "CONTACTDYN_PATH": "compiled",  # no background build (first_run)
           # the compiled code's cache: the user's, not the temporary HOME's (cold)
           "XDG_CACHE_HOME": os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")}
    if os.environ.get("NUMBA_CACHE_DIR"):
        env["NUMBA_CACHE_DIR"] = os.environ["NUMBA_CACHE_DIR"]
    proc = subprocess.run([sys.executable, str(RUNNER)], input=payload, capture_output=True, text=True, cwd=cwd,
                          env=env, timeout=BATCH_TIMEOUT, preexec_fn=_cap)
    results = {r["id"]: r for r in map(json.loads, proc.stdout.splitlines())}
    missing = [c[0] for c in cases if c[0] not in results]
    assert not missing, f"the batch died (exit {proc.returncode}) at case {missing[0]}: {proc.stderr[-2000:]}"
    return results


def check(cases: list[Case], cwd: Path) -> None:
    assert len({c[0] for c in cases}) == len(cases), "duplicate case ids"
    results = run_batch(cases, cwd)
    wrong = []
    for cid, _, code, piece in cases:
        r = results[cid]
        err = r["err"]
        ok = r["code"] == code and piece in err and "Traceback" not in err and "\x1b" not in err + r["out"]
        if code == 2:  # bad input: exactly one line, short, no NumPy or Pinocchio text
            ok = ok and err.count("\n") == 1 and err.startswith("contactdyn") and r["err_chars"] < 1000
        if not ok:
            wrong.append(f"{cid}: exit {r['code']} (expected {code}, {piece!r}): {err[:600]!r}")
    assert not wrong, "\n".join(wrong)


# ---- scenes ------------------------------------------------------------------------------------
def scene_cases(tmp: Path) -> list[Case]:
    def write(name: str, text: str | bytes) -> str:
        path = tmp / f"{name}.toml"
        path.write_bytes(text if isinstance(text, bytes) else text.encode())
        return str(path)

    moves = lambda n: B1.replace(f"moves = [{MOVE}]", "moves = [" + ", ".join([MOVE] * n) + "]")  # noqa: E731
    big_q0 = "[" + ", ".join(["0.1"] * 10**5) + "]"  # tomllib reads ~10^5 numbers per second
    (tmp / "adir.toml").mkdir()
    files = {
        "empty": ("", 2, "expected a value (required key is missing)"),
        "binary": (bytes(range(256)) * 4, 2, "<file>: expected"),
        "bad_toml": ("duration = = 1", 2, "expected valid TOML"),
        "latin1": ("name = 'caf\xe9'".encode("latin-1"), 2, "expected UTF-8 text"),
        "deep_arrays": (B1 + "\nx = " + "[" * 5000 + "]" * 5000 + "\n", 2, "nested at most 32 deep"),
        "deep_tables": (B1 + "\n[" + ".".join(f"t{i}" for i in range(40)) + "]\n", 2, "nested at most 32 deep"),
        "deep_inline": (B1 + "\nx = " + "{a = " * 40 + "1" + "}" * 40 + "\n", 2, "nested at most 32 deep"),
        "huge": (B1 + "\n#" + "x" * (17 * 2**20) + "\n", 2, "at most 16 MB"),
        "moves_2000": (moves(2000), 2, "phase[0].reference.moves: expected at most 64 moves, found '2000 moves'"),
        "moves_65": (moves(65), 2, "at most 64 moves"),
        "typo_key": (B1.replace("duration = 2.0", "durration = 2.0"), 2, "did you mean 'duration'"),
        "duration_text": (B1.replace("duration = 2.0", 'duration = "2 s"'), 2, "duration: expected a number [s]"),
        "duration_bool": (B1.replace("duration = 2.0", "duration = true"), 2, "duration: expected a number"),
        "duration_inf": (B1.replace("duration = 2.0", "duration = inf"), 2, "duration: expected a finite number"),
        "duration_nan": (B1.replace("duration = 2.0", "duration = nan"), 2, "duration: expected a finite number"),
        "q0_100000": (B1.replace("q0 = [0.337307481430, -1.318116071653]", f"q0 = {big_q0}"), 2, "robot.q0"),
        "name_number": (B1.replace('name = "b1"', "name = 5"), 2, "name: expected a string"),
        "urdf_number": (B1.replace('urdf = "planar2r_b1"', "urdf = 5"), 2, "robot"),
        "normal_model": (B1.replace('normal.model = "b"', 'normal.model = "zzz"'), 2, "normal.model: expected one of"),
        "zero_normal": (B1.replace("normal.direction = [0.0, 1.0, 0.0]", "normal.direction = [0.0, 0.0, 0.0]"), 2,
                        "non-zero direction"),
        "phase_number": (B1.replace("[[phase]]", "phase = 5\n[[xphase]]"), 2, "phase"),
        "solver_number": (B1.replace("[solver]", "solver = 5\n[xsolver]"), 2, "solver"),
        "method": (B1.replace('method = "DOP853C"', 'method = "Euler"'), 2, "solver.method: expected one of"),
        "controller_kind": (B1.replace('kind = "task_pd"', 'kind = "nope"'), 2, "controller"),
        "gravity_2": (B1.replace("gravity = [0.0, 0.0, 0.0]", "gravity = [0.0, 0.0]"), 2, "robot.gravity"),
        "k_inf": (B1.replace("normal.k = 1e5", "normal.k = inf"), 2, "contact.tip.normal.k: expected a finite"),
        "k_absurd": (B1.replace("normal.k = 1e5", "normal.k = 1e300"), 2, "magnitude <= 1e+12"),
        "mu_negative": (B1.replace("tangent.mu = 0.4", "tangent.mu = -0.4"), 2, "contact.tip.tangent.mu"),
    }
    keep_duration = ["--set", "solver.output_rate=200"]  # FAST would override the file's duration
    cases = [(f"scene/{name}", ["run", write(name, text), *(keep_duration if "duration" in name else FAST)], code,
              piece) for name, (text, code, piece) in files.items()]
    escaped = write("escape", B1.replace('name = "b1"', 'name = "b1\\u001b[31mRED\\u001b]0;title\\u0007"'))
    cases += [
        ("scene/escape_codes_printed_escaped", ["run", escaped, *FAST], 0, ""),
        ("scene/directory", ["run", str(tmp / "adir.toml"), *FAST], 2, "scene: expected a scene file"),
        ("scene/missing", ["run", str(tmp / "nothing.toml"), *FAST], 2, "scene: expected a scene file"),
        ("scene/sweep_deep_file", ["sweep", "--file", write("sweep_deep", "x = " + "[" * 3000 + "]" * 3000),
                                   "--workers", "0"], 2, "nested at most 32 deep"),
        ("scene/sweep_too_many_runs", ["sweep", "b1", "--range", "controller.kp=1:2:1000", "--range",
                                       "contact.tip.normal.k=1:2:1000", "--out", str(tmp / "sw")], 2,
         "at most 100000 runs"),
        ("scene/sweep_range_n", ["sweep", "b1", "--range", "controller.kp=1:2:1000000000", "--out", str(tmp / "sw")],
         2, "1 <= n <= 100000"),
    ]
    return cases


# ---- overrides ---------------------------------------------------------------------------------
OVERRIDES: list[tuple[str | list[str], int, str]] = [  # --set value(s), exit code, message piece
    *[(f"{key}={value}", 2, f"{key}: expected a finite number")
      for key in ("contact.tip.normal.k", "contact.tip.normal.m", "contact.tip.normal.b", "contact.tip.tangent.mu",
                  "contact.tip.tangent.viscous", "solver.stabilization", "duration", "solver.rtol")
      for value in ("inf", "nan", "-inf")],
    ("controller.kp=inf", 2, "controller.kp: expected a finite number"),
    ("controller.kd=nan", 2, "controller.kd: expected a finite number"),
    ("duration=-1", 2, "duration: expected a number > 0"),
    ("duration=0", 2, "duration: expected a number > 0"),
    ("duration=1e308", 2, "duration: expected a number of magnitude <= 1e+12"),
    ("duration=1e5", 2, "duration: expected a number <= 10000 [s]"),
    ("solver.max_step=1e-300", 2, "solver.max_step: expected at most 1e+07 steps"),
    ("solver.max_step=0", 2, "solver.max_step: expected a number > 0"),
    ("solver.max_step=nan", 2, "solver.max_step: expected a finite number"),
    ("solver.output_rate=1e7", 0, ""),  # 0.01 s: 1e5 samples, fine
    (["duration=2.0", "solver.output_rate=1e7"], 2,
     "solver.output_rate: expected at most 1e+07 samples over the run (duration"),
    (["duration=1000.0", "solver.output_rate=5e3"], 2, "fits in memory: 5e+06 samples would need about 7.2 GiB"),
    ("solver.output_rate=1e12", 2, "solver.output_rate"),
    ("solver.output_rate=0", 2, "solver.output_rate: expected a number > 0"),
    ("solver.output_rate=inf", 2, "solver.output_rate: expected a finite number"),
    ("solver.rtol=0", 2, "solver.rtol: expected a number >= 1e-14"),
    ("solver.max_events=0", 2, "solver.max_events: expected an integer >= 1"),
    ("solver.max_events=1.5", 2, "solver.max_events: expected an integer"),
    ("robot.q0=[nan, 1.0]", 2, "robot.q0: expected finite numbers"),
    ("robot.q0=[1e300, 0.0]", 2, "robot.q0: expected numbers of magnitude <= 1e+12"),
    ("robot.q0=[1.0]", 2, "robot.q0"),
    ("robot.v0=[inf, 0.0]", 2, "robot.v0: expected finite numbers"),
    ("robot.v0=[1e308, 1e308]", 2, "robot.v0: expected numbers of magnitude"),
    ("contact.tip.normal.k=1e300", 2, "contact.tip.normal.k: expected a number of magnitude <= 1e+12"),
    ("controller.kp=1e13", 2, "controller.kp: expected a number of magnitude <= 1e+12"),
    ("contact.tip.point=[nan, 0.0, 0.0]", 2, "contact.tip.point: expected finite numbers"),
    ("contact.tip.normal.kk=1.0", 2, "did you mean 'k'"),
    ("phase.5.name=x", 2, "phase.5: expected an index < 1"),
    ("duration.x=1", 2, "duration.x: expected a table to set a key in, found 0.01"),
    ("duration", 2, "--set: expected key.path=value"),
    ("robot.gravity_compensation=2.0", 2, "robot.gravity_compensation: expected a number <= 1"),
    ("phase.0.until=-1.0", 2, "phase[0].until"),
    ("solver.method=\"RK4\"", 2, "solver.max_step"),
    ("robot.q0=" + "[" * 200 + "]" * 200, 2, "nested at most 32 deep"),
    ("robot.q0=[" + ", ".join(["0.5"] * 100000) + "]", 2, "characters)"),  # the value abbreviated
    ("name=\"\\u001b[2J\"", 0, ""),
]


def override_cases() -> list[Case]:
    cases = []
    for i, (sets, code, piece) in enumerate(OVERRIDES):
        sets = [sets] if isinstance(sets, str) else sets
        argv = ["run", "b1", *FAST, *[a for text in sets for a in ("--set", text)]]
        cases.append((f"set/{i:02d} {' '.join(sets)[:60]}", argv, code, piece))
    cases.append(("set/rk4_step_too_large", ["run", "b1", "--set", "duration=0.5", "--set", "solver.method=\"RK4\"",
                                             "--set", "solver.max_step=0.5"], 1,
                  "too large for the stiffest mode (|λ| = 91.6 1/s, period 0.0686 s)"))
    return cases


# ---- URDFs -------------------------------------------------------------------------------------
def _urdf(joints: list[tuple[str, str, str]], links: list[str], extra: str = "") -> str:
    body = "".join(f'<link name="{n}">{INERTIAL}</link>' for n in links)
    body += "".join(f'<joint name="{n}" type="revolute"><parent link="{p}"/><child link="{c}"/><axis xyz="0 0 1"/>'
                    '<limit lower="-1" upper="1" effort="1" velocity="1"/></joint>' for n, p, c in joints)
    return f'<robot name="r">{body}{extra}</robot>'


def urdf_cases(tmp: Path) -> list[Case]:
    good = (ROOT / "urdf" / "planar2r_b1.urdf").read_text()
    chain = [(f"j{i}", f"l{i}", f"l{i + 1}") for i in range(999)]
    laughs = ('<?xml version="1.0"?><!DOCTYPE lolz [<!ENTITY lol "lol">' +
              "".join(f'<!ENTITY lol{i} "{("&lol" + str(i - 1) + ";") * 10 if i else "&lol;" * 10}">'
                      for i in range(9)) + ']><robot name="r"><link name="&lol8;"/></robot>')
    files: dict[str, tuple[str | bytes, str]] = {
        "cycle_second_parent": (_urdf([("j1", "base", "a"), ("j2", "a", "b"), ("j3", "b", "a")], ["base", "a", "b"]),
                                "link 'a' is the child of two joints"),
        "own_parent": (_urdf([("j1", "base", "a"), ("j2", "a", "a")], ["base", "a"]), "'a' is its own parent"),
        "root_own_parent": (_urdf([("j1", "base", "base")], ["base"]), "'base' is its own parent"),
        "detached_cycle": (_urdf([("j1", "base", "a"), ("j2", "b", "c"), ("j3", "c", "b")], ["base", "a", "b", "c"]),
                           "cycle through links b -> c -> b"),
        "long_cycle": (_urdf([("j1", "base", "a"), ("j2", "x", "y"), ("j3", "y", "z"), ("j4", "z", "x")],
                             ["base", "a", "x", "y", "z"]), "the joints form a cycle"),
        "long_names": (_urdf([("j" * 10**5, "base", "a" * 10**5), ("j2", "a" * 10**5, "a" * 10**5)],
                             ["base", "a" * 10**5]), "(100002 characters) is its own parent"),
        "no_root": (_urdf([("j1", "a", "b"), ("j2", "b", "a")], ["a", "b"]), "found none"),
        "two_roots": (_urdf([("j1", "base", "a")], ["base", "a", "b"]), "expected one root link"),
        "undefined_parent": (_urdf([("j1", "nowhere", "a")], ["a"]), "parent link 'nowhere' is not defined"),
        "undefined_child": (_urdf([("j1", "base", "nowhere")], ["base"]), "child link 'nowhere' is not defined"),
        "duplicate_link": (_urdf([("j1", "base", "a")], ["base", "a", "a"]), "two links named 'a'"),
        "duplicate_joint": (_urdf([("j1", "base", "a"), ("j1", "a", "b")], ["base", "a", "b"]),
                            "two joints named 'j1'"),
        "joint_without_parent": ('<robot name="r"><link name="a"/><joint name="j" type="fixed"><child link="a"/>'
                                 "</joint></robot>", "missing <parent"),
        "thousand_links": (_urdf(chain, [f"l{i}" for i in range(1000)]), "1000 links; at most 400"),
        "129_moving_joints": (_urdf(chain[:129], [f"l{i}" for i in range(130)]), "129 moving joints; at most 128"),
        "huge": (good.replace("<robot", "<!--" + "x" * (17 * 2**20) + "--><robot", 1), "at most 16 MB is read"),
        "malformed": (good[: len(good) // 2], "malformed XML"),
        "empty": ("", "malformed XML"),
        "binary": (bytes(range(256)) * 8, "malformed XML"),
        "not_a_robot": ("<html><body/></html>", "expected a <robot> element"),
        "xxe": ('<?xml version="1.0"?><!DOCTYPE r [<!ENTITY x SYSTEM "file:///etc/passwd">]>'
                '<robot name="r"><link name="&x;"/></robot>', "reference to external entity"),
        "xxe_content": ('<?xml version="1.0"?><!DOCTYPE r [<!ENTITY x SYSTEM "file:///etc/passwd">]>'
                        '<robot name="r"><link name="a">&x;</link></robot>', "undefined entity"),
        "billion_laughs": (laughs, "amplification"),
        "long_link_negative_mass": (good.replace('"link1"', '"' + "L" * 10**5 + '"').replace(
            '<mass value="3.0"/>', '<mass value="-3.0"/>', 1), "characters)"),
        "negative_mass": (good.replace('<mass value="3.0"/>', '<mass value="-3.0"/>', 1), "mass must be >= 0"),
        "nan_mass": (good.replace('<mass value="3.0"/>', '<mass value="nan"/>', 1),
                     "link 'link1' <inertial> <mass>: value='nan': expected finite numbers"),
        "text_mass": (good.replace('<mass value="3.0"/>', '<mass value="heavy"/>', 1),
                      "<mass>: value='heavy': expected finite numbers"),
        "nan_inertial_origin": (good.replace("<inertial>", '<inertial><origin xyz="nan 0 0"/>', 1),
                                "<inertial> <origin>: xyz='nan 0 0': expected finite numbers"),
        "huge_visual_origin": (good.replace("<link name=\"link1\">",
                                            '<link name="link1"><visual><origin xyz="1e400 0 0"/>'
                                            '<geometry><sphere radius="0.1"/></geometry></visual>', 1),
                               "<visual> <origin>: xyz='1e400 0 0': expected finite numbers"),
        "limits_reversed": (good.replace('lower="-6.283185307180" upper="6.283185307180"', 'lower="1" upper="-1"', 1),
                            "lower limit [1.0] > upper limit [-1.0]"),
        "no_limits": (good.replace(LIMIT, "", 1), "does not specify limits"),
        "no_tip_link": (good.replace('"tip"', '"tip2"'), "tip"),
    }
    (tmp / "adir.urdf").mkdir()
    cases = []
    for name, (text, piece) in files.items():
        path = tmp / f"{name}.urdf"
        path.write_bytes(text if isinstance(text, bytes) else text.encode())
        cases.append((f"urdf/{name}", ["run", "b1", *FAST, "--set", f'robot.urdf="{path}"'], 2, piece))
    # a visual mesh nowhere to be found is left out of the drawing, as ROS tools do: a warning, the run goes on
    missing_mesh = tmp / "missing_mesh.urdf"
    missing_mesh.write_text(good.replace("<geometry>", '<geometry><mesh filename="nope.stl"/>', 1))
    cases.append(("urdf/missing_mesh", ["run", "b1", *FAST, "--set", f'robot.urdf="{missing_mesh}"'], 0,
                  "warning: visual: missing_mesh.urdf: 1 visual mesh(es) not found"))
    passwd_mesh = tmp / "passwd_mesh.urdf"
    passwd_mesh.write_text(good.replace("<geometry>", '<geometry><mesh filename="/etc/passwd"/>', 1))
    cases.append(("urdf/mesh_is_etc_passwd", ["run", "b1", *FAST, "--set", f'robot.urdf="{passwd_mesh}"'], 0,
                  "1 visual mesh(es) not found or unusable"))
    cases += [("urdf/missing", ["run", "b1", *FAST, "--set", f'robot.urdf="{tmp / "nope.urdf"}"'], 2,
               "no such URDF file"),
              ("urdf/directory", ["run", "b1", *FAST, "--set", f'robot.urdf="{tmp / "adir.urdf"}"'], 2, "robot")]
    return cases


# ---- saved runs --------------------------------------------------------------------------------
def _npy_header(shape: tuple[int, ...], descr: str = "<f8") -> bytes:
    text = f"{{'descr': '{descr}', 'fortran_order': False, 'shape': {shape}, }}".ljust(117) + "\n"
    return b"\x93NUMPY\x01\x00" + len(text).to_bytes(2, "little") + text.encode()


def run_file_cases(tmp: Path) -> list[Case]:
    good = tmp / "good"
    contactdyn.simulate("b1", {"duration": 0.01, "solver.output_rate": 200}).save(good)
    npz, sidecar = good.with_name("good.npz").read_bytes(), good.with_name("good.json").read_text()
    doc = json.loads(sidecar)
    t = np.linspace(0.0, 0.01, 3)

    def channels_npz(path: Path, **arrays) -> None:
        with open(path, "wb") as f:
            np.savez(f, **arrays)

    def cycle_scene() -> str:
        (tmp / "cycle.urdf").write_text(_urdf([("j1", "base", "a"), ("j2", "a", "a")], ["base", "a"]))
        robot = {**doc["scene"]["robot"], "urdf": str(tmp / "cycle.urdf")}
        return json.dumps({**doc, "scene": {**doc["scene"], "robot": robot},
                           "meta": {**doc["meta"], "robot": str(tmp / "cycle.urdf")}})

    runs: dict[str, tuple[object, object, str]] = {  # name: (npz bytes or writer, json text, message piece)
        "garbage_npz": (b"not a zip file at all", sidecar, "not a readable run archive (BadZipFile"),
        "truncated_npz": (npz[: len(npz) // 2], sidecar, "not a readable run archive"),
        "empty_npz": (b"", sidecar, "not a readable run archive"),
        "empty_zip": (lambda p: zipfile.ZipFile(p, "w").close(), sidecar, "no time channel t"),
        "foreign_npz": (lambda p: channels_npz(p, a=np.ones(3), b=np.zeros(2)), sidecar, "no time channel t"),
        "t_2d": (lambda p: channels_npz(p, t=np.ones((3, 2))), sidecar, "no time channel t"),
        "t_empty": (lambda p: channels_npz(p, t=np.zeros(0)), sidecar, "no time channel t"),
        "length_mismatch": (lambda p: channels_npz(p, t=t, q=np.ones((5, 2))), sidecar, "channel 'q' has shape (5, 2)"),
        "channel_3d": (lambda p: channels_npz(p, t=t, q=np.ones((3, 2, 2))), sidecar, "has shape (3, 2, 2)"),
        "object_dtype": (lambda p: channels_npz(p, t=t, q=np.array([None, 1, "x"], dtype=object)), sidecar,
                         "holds object, expected numbers"),
        "string_dtype": (lambda p: channels_npz(p, t=t, q=np.array(["a", "b", "c"])), sidecar, "expected numbers"),
        "complex_dtype": (lambda p: channels_npz(p, t=t, q=t * 1j), sidecar, "expected numbers"),
        "header_16gib": (lambda p: zipfile.ZipFile(p, "w").writestr("t.npy", _npy_header((2**31,))), sidecar,
                         "declares 2147483648 values in a 128-byte member"),
        "bad_npy_magic": (lambda p: zipfile.ZipFile(p, "w").writestr("t.npy", b"\x93NUMPY\x09\x00zz"), sidecar,
                          "channel 't' is in an unknown .npy format version"),
        "bad_npy_header": (lambda p: zipfile.ZipFile(p, "w").writestr("t.npy", _npy_header((3,))[:20]), sidecar,
                           "not a readable run archive"),
        "t_nan": (lambda p: channels_npz(p, t=t * np.nan), sidecar, "t is not finite and non-decreasing"),
        "t_decreasing": (lambda p: channels_npz(p, t=t[::-1].copy()), sidecar, "not finite and non-decreasing"),
        "force_2d": (lambda p: channels_npz(p, t=t, **{"contact.tip.F_n": np.ones((3, 4))}), sidecar,
                     "channel 'contact.tip.F_n' has shape (3, 4), expected (3,)"),
        "tip_2_columns": (lambda p: channels_npz(p, t=t, tip=np.ones((3, 2))), sidecar, "expected (3, 3)"),
        "q_v_disagree": (lambda p: channels_npz(p, t=t, q=np.ones((3, 5)), v=np.ones((3, 2))), sidecar,
                         "channels q and v have different numbers of joints"),
        "json_garbage": (npz, "{not json", "not a run's JSON sidecar (JSONDecodeError"),
        "json_list": (npz, "[1, 2, 3]", "expected a JSON object, found list"),
        "json_no_events": (npz, json.dumps({k: v for k, v in doc.items() if k != "events"}),
                           "'events' must be a JSON array, found 'nothing'"),
        "json_events_dict": (npz, json.dumps({**doc, "events": {"a": 1}}), "'events' must be a JSON array"),
        "json_event_without_t": (npz, json.dumps({**doc, "events": [{"kind": "touch"}]}),
                                 "events[0] must be an object with a time t"),
        "json_impact_text_t": (npz, json.dumps({**doc, "impacts": [{"t": "soon"}]}), "impacts[0] must be an object"),
        "json_meta_list": (npz, json.dumps({**doc, "meta": [1]}), "'meta' must be a JSON object"),
        "json_meta_joints_number": (npz, json.dumps({**doc, "meta": {**doc["meta"], "joints": 5}}),
                                    "meta.joints has the wrong type: 5"),
        "json_event_kind_list": (npz, json.dumps({**doc, "events": [{"t": 0.0, "kind": ["x"]}]}),
                                 "events[0].kind has the wrong type"),
        "json_impact_contact_list": (npz, json.dumps({**doc, "impacts": [{"t": 0.0, "contact": ["x"]}]}),
                                     "impacts[0].contact has the wrong type"),
        "json_scene_contact_number": (npz, json.dumps({**doc, "scene": {**doc["scene"], "contact": 5}}),
                                      "scene.contact must be a table of tables, found 5"),
        "json_deep": (npz, "[" * 100000 + "]" * 100000, "not a run's JSON sidecar (RecursionError"),
        "json_binary": (npz, "\udcff\udcfe".encode("utf-8", "surrogateescape").decode("latin-1"),
                        "not a run's JSON sidecar"),
    }
    cases = []
    for name, (channels, text, piece) in runs.items():
        base = tmp / name
        npz_path, json_path = base.with_name(f"{name}.npz"), base.with_name(f"{name}.json")
        if callable(channels):
            channels(npz_path)
        else:
            npz_path.write_bytes(channels)
        json_path.write_text(text, encoding="latin-1")
        cases.append((f"run/plot/{name}", ["plot", str(base), "--out", str(tmp / "figs")], 2, piece))
        cases.append((f"run/view/{name}", ["view", str(base), "--html", str(tmp / "v.html")], 2, piece))
    (tmp / "foreign_scene.npz").write_bytes(npz)
    (tmp / "foreign_scene.json").write_text(json.dumps({**doc, "scene": {"foo": 1}}))
    (tmp / "sparse.npz").write_bytes(npz)
    with open(tmp / "sparse.json", "wb") as f:
        f.truncate(2**29)  # 512 MB of zeros, sparse on disk
    (tmp / "dir.npz").mkdir()
    (tmp / "dir.json").write_text(sidecar)
    (tmp / "cyc.npz").write_bytes(npz)
    (tmp / "cyc.json").write_text(cycle_scene())
    channels_npz(tmp / "no_q.npz", t=t)
    (tmp / "no_q.json").write_text(sidecar)
    channels_npz(tmp / "q_5.npz", t=t, q=np.ones((3, 5)))
    (tmp / "q_5.json").write_text(sidecar)
    bad = dict(np.load(good.with_name("good.npz")))
    channels_npz(tmp / "q_nan.npz", **{**bad, "q": np.full_like(bad["q"], np.nan)})
    (tmp / "q_nan.json").write_text(sidecar)
    channels_npz(tmp / "ff_5.npz", **{**bad, "contact.tip.F_f": np.ones((len(bad["t"]), 5))})
    (tmp / "ff_5.json").write_text(sidecar)
    cases += [
        ("run/view/q_nan", ["view", str(tmp / "q_nan"), "--html", str(tmp / "v.html")], 2,
         "channel q holds non-finite values"),
        ("run/view/friction_columns", ["view", str(tmp / "ff_5"), "--html", str(tmp / "v.html")], 2,
         "channel contact.tip.F_f has 5 columns but the scene gives contact 'tip' 1 tangents"),
        ("run/view/no_q", ["view", str(tmp / "no_q"), "--html", str(tmp / "v.html")], 2, "no joint channel q"),
        ("run/view/q_for_another_robot", ["view", str(tmp / "q_5"), "--html", str(tmp / "v.html")], 2,
         "channel q has 5 columns but robot"),
        ("run/plot/missing", ["plot", str(tmp / "nothing")], 2, "not a saved run (need nothing.npz and nothing.json"),
        ("run/view/missing", ["view", str(tmp / "nothing.npz")], 2, "not a saved run"),
        ("run/plot/huge_sidecar", ["plot", str(tmp / "sparse")], 2, "more than a run's sidecar"),
        ("run/view/npz_is_a_directory", ["view", str(tmp / "dir"), "--html", str(tmp / "v.html")], 2,
         "not a saved run"),
        ("run/view/foreign_scene", ["view", str(tmp / "foreign_scene"), "--html", str(tmp / "v.html")], 2,
         "its scene document no longer validates"),
        ("run/view/scene_names_a_cyclic_urdf", ["view", str(tmp / "cyc"), "--html", str(tmp / "v.html")], 2,
         "'a' is its own parent"),
    ]
    return cases


# ---- round 2 (issue 33): where files go, silently dropped input, blocking files and ports, one validation ----
def round2_cases(tmp: Path) -> list[Case]:
    import os

    def write(name: str, text: str) -> str:
        path = tmp / name
        path.write_text(text)
        return str(path)

    escaped = write("escaped.toml", B1.replace('name = "b1"', 'name = "../../../escaped"'))
    decreasing = write("decreasing.toml", B1.replace('name = "slide"', 'name = "slide"\nuntil = 1.0', 1)
                       + '\n[[phase]]\nname = "back"\nuntil = 0.5\n[[phase]]\nname = "last"\n')
    fifo = tmp / "fifo.csv"
    os.mkfifo(fifo)
    good = tmp / "good"
    contactdyn.simulate("b1", {"duration": 0.01, "solver.output_rate": 200}).save(good)
    doc = json.loads(good.with_name("good.json").read_text())
    (tmp / "nan_duration.npz").write_bytes(good.with_name("good.npz").read_bytes())
    (tmp / "nan_duration.json").write_text(json.dumps({**doc, "meta": {**doc["meta"], "duration": math.nan}}))
    with open(tmp / "no_q.npz", "wb") as f:
        np.savez(f, t=np.linspace(0.0, 0.01, 3), tip=np.zeros((3, 3)))
    (tmp / "no_q.json").write_text(json.dumps(doc))
    more_toml = 'duration=0.2\n[solver]\nmethod="RK4"'
    return [
        ("r2/sweep_name_escapes", ["sweep", escaped, "--grid", "controller.kp=1,2", "--workers", "0", *FAST], 2,
         "cannot name one"),
        ("r2/new_name_escapes", ["new", "../../x"], 2, "NAME: expected a plain name"),
        ("r2/grid_key_twice", ["sweep", "b1", "--grid", "controller.kp=1,2", "--grid", "controller.kp=3",
                               "--workers", "0", "--out", str(tmp / "sw")], 2, "controller.kp is given twice"),
        ("r2/set_carries_more_toml", ["run", "b1", "--set", more_toml], 2, "one value on one line"),
        ("r2/until_decreases", ["run", decreasing, *FAST], 2, "phase ends do not decrease"),
        ("r2/max_events_unbounded", ["run", "b1", "--set", "solver.max_events=100000000", *FAST], 2,
         "solver.max_events: expected an integer <= 1000000"),
        ("r2/fit_data_fifo", ["fit", "b1", "--data", str(fifo), "--params", "contact.tip.tangent.mu"], 2,
         "expected a regular CSV file"),
        ("r2/view_port_too_big", ["view", str(good), "--port", "99999"], 2, "invalid port"),
        ("r2/view_port_negative", ["view", str(good), "--port", "-5"], 2, "invalid port"),
        ("r2/view_host_unresolvable", ["view", str(good), "--host", "no-such-host.invalid"], 2, "invalid host"),
        ("r2/plot_format_exe", ["plot", str(good), "--format", "exe", "--out", str(tmp / "f")], 2,
         "--format: expected a comma-separated list of png, svg"),
        ("r2/bench_rtols_nan", ["bench", "b1", "--rtols", "nan", "--out", str(tmp / "b")], 2,
         "--rtols: expected comma-separated finite numbers > 0"),
        ("r2/bench_repeats_0", ["bench", "b1", "--repeats", "0", "--out", str(tmp / "b")], 2, "--repeats"),
        ("r2/plot_nan_duration", ["plot", str(tmp / "nan_duration"), "--out", str(tmp / "f2")], 2,
         "is not a finite number"),
        ("r2/plot_no_q", ["plot", str(tmp / "no_q"), "--out", str(tmp / "f3")], 2, "no joint channel q"),
        ("r2/memory_bound", ["run", "b1", "--set", "duration=0.2", "--set", "solver.output_rate=1e7"], 2,
         "would need about 2.9 GiB"),
        ("r2/new_name_with_slash", ["new", "a/b"], 2, "NAME: expected a plain name"),
        ("r2/new_name_hidden", ["new", ".hidden"], 2, "NAME: expected a plain name"),
        ("r2/set_carriage_return", ["run", "b1", "--set", "duration=0.2\r[solver]"], 2, "one value on one line"),
        ("r2/view_port_zero", ["view", str(good), "--port", "0"], 2, "invalid port"),
        ("r2/bench_rtols_negative", ["bench", "b1", "--rtols=-1e-4", "--out", str(tmp / "b")], 2,
         "finite numbers > 0"),
        ("r2/grid_and_range_same_key", ["sweep", "b1", "--grid", "controller.kp=1,2", "--range",
                                        "controller.kp=1:2:3", "--workers", "0", "--out", str(tmp / "sw2")], 2,
         "given twice"),
    ]


# ---- round 3: sampled control, joint damping and friction, drives, users' laws ----------------------
ELASTIC = 'robot.drive={kind="elastic", c=1e4, R=10.24, C_M=0.16, J=2e-5, N=100.0}'
ROUND3_SETS: list[tuple[str | list[str], int, str]] = [  # on b1: (--set values, exit code, a piece of stderr)
    ("controller.sample_rate=-1", 2, "controller.sample_rate: expected a number >= 0 [Hz], found -1.0"),
    ("controller.sample_rate=nan", 2, "controller.sample_rate: expected a finite number [Hz]"),
    ("controller.sample_rate=1e308", 2, "controller.sample_rate: expected a number <= 1e+06 [Hz]"),
    ("controller.sample_rate=1e-7", 2, "expected 0 (continuous) or a rate >= 1e-06 Hz"),
    ("controller.delay=-1", 2, "controller.delay: expected an integer >= 0 [samples], found -1"),
    ("controller.delay=1.5", 2, "controller.delay: expected an integer, found 1.5"),
    ("controller.delay=3", 2, "controller.delay: expected no delay for a continuous controller"),
    (["controller.sample_rate=500", "controller.delay=100000"], 2, "controller.delay: expected an integer <= 10000"),
    (["controller.sample_rate=500", "controller.delay=1e308"], 2,
     "controller.delay: expected an integer <= 10000 [samples], found 1e+308\n"),
    (["controller.sample_rate=500", 'controller.hold="volts"'], 2, "controller.hold: expected one of"),
    (["controller.sample_rate=500", 'controller.hold="voltage"'], 2,
     "controller.hold: expected hold = \"voltage\" only with a motor on every joint"),
    (["controller.sample_rate=500", "controller.sensor.seed=-1"], 2, "sensor.seed: expected an integer >= 0"),
    (["controller.sample_rate=500", "controller.sensor.seed=1.5"], 2, "controller.sensor.seed: expected an integer"),
    (["controller.sample_rate=500", "controller.sensor.force_cutoff=0"], 2, "force_cutoff: expected a number > 0"),
    (["controller.sample_rate=500", "controller.sensor.encoder_resolution=1e-13"], 2, "a resolution >= 1e-12"),
    (["controller.sample_rate=500", "controller.sensor.force_cutoff=5e-324"], 2,
     "controller.sensor.force_cutoff: expected a cut-off >= 1e-06 Hz (or none: no filter), found 5e-324"),
    (["controller.sample_rate=500", "controller.sensor.force_cutoff=1e-310"], 2, "a cut-off >= 1e-06 Hz"),
    (["controller.sample_rate=500", "controller.sensor.noise=1"], 2, "did you mean 'force_noise'"),
    ("robot.joint.q1.friction=-1", 2, "robot.joint.q1.friction: expected a number >= 0 [N·m or N], found -1.0"),
    ("robot.joint.q1.damping=nan", 2, "robot.joint.q1.damping: expected a finite number"),
    ("robot.joint.q3.friction=1", 2, "robot.joint.q3: expected a table named after an active joint of the robot"),
    ("robot.joint.q1={friction_static=1, friction_kinetic=2}", 2, "expected a kinetic friction <= friction_static"),
    ("robot.joint.q1={friction_kinetic=1}", 2, "robot.joint.q1.friction_static: expected a static limit"),
    ('robot.active_joints=["q9"]', 2, "robot.active_joints: expected joints of the robot (each active or locked, not "
     "both), found "),
    ("robot.locked={q9=0.0}", 2, "robot.locked.q9: expected joints of the robot"),
    (['robot.active_joints=["q1"]', "robot.locked={q1=0.0}"], 2, "robot.active_joints: expected joints of the robot "
     "(each active or locked, not both), found"),
    ("robot.active_joints=[]", 2, "robot.active_joints: expected a list of joint names (at least one"),
    ('robot.drive={kind="dc_motor", R=0.0, C_M=0.16}', 2, "robot.drive.R: expected a number > 0 [Ω], found 0.0"),
    ('robot.drive={kind="dc_motor", R=1.0, C_M=0.16, J=0.0, u_max=[1.0, 2.0, 3.0]}', 2,
     "robot.drive.u_max: expected one value or 2 (one per joint ['q1', 'q2'])"),
    (ELASTIC.replace("J=2e-5", "J=0.0"), 2, "robot.drive: expected parameters that give the drive of joint 'q1' "
     "(kind 'elastic') a finite torsional frequency (its motor coordinate needs a motor inertia > 0), found "
     "'natural_frequency = x / 0 at R = 10.24"),
    (ELASTIC.replace("J=2e-5", "J=[2e-5, 0.0]"), 2, "the drive of joint 'q2' (kind 'elastic') a finite torsional"),
    (ELASTIC.replace("N=100.0", "N=1e-300"), 2,
     "a finite inertia >= 0 on the motor shaft, found 'motor_inertia = x / 0"),
    ('robot.drive={kind="dc_motor", R=10.24, C_M=0.16, J=2e-5, N=100.0, wheel_radius=1e-300}', 2,
     "a finite reflected rotor inertia >= 0, found 'reflected_inertia = inf at R = 10.24"),
]


#: a user's controller module: (the class's lines, the scene's controller kind, exit code, a piece of stderr); each
#: module is imported once in the batch's process, under a name of its own
LAW = ("from contactdyn.laws import Controller, Param, register\nimport numpy as np\n\n\n"
       "@register\nclass C(Controller):\n")
COMMAND = "    def command(self, inp):\n        return np.zeros(2), None\n"
ROUND3_LAWS: dict[str, tuple[str, str, int, str]] = {
    "param_named_delay": ('    name = "with_delay"\n    params = (Param("delay", "s", "my delay", 0.5),)\n' + COMMAND,
                          "with_delay", 2, "ValueError: controller 'with_delay': parameter 'delay' is named like a key "
                          "of the table it is read from (the table would give one value to both)"),
    "param_twice": ('    name = "twice"\n    params = (Param("a", "-", "a", 1.0), Param("a", "-", "b", 2.0))\n'
                    + COMMAND, "twice", 2, "controller 'twice': parameter names must be unique"),
    "params_not_a_tuple": ('    name = "params_text"\n    params = "gain"\n' + COMMAND, "params_text", 2,
                           "controller 'params_text': params must be a tuple of Param, got 'gain'"),
    "outputs_typo": ('    name = "volts"\n    outputs = "voltages"\n' + COMMAND, "volts", 2,
                     "controller 'volts': outputs must be one of ('torque', 'voltage'), got 'voltages'"),
    "n_states_negative": ('    name = "negative_states"\n    n_states = -1\n' + COMMAND, "negative_states", 2,
                          "controller 'negative_states': n_states must be an integer in [0, 10000], got -1"),
    "n_states_text": ('    name = "text_states"\n    n_states = "1"\n' + COMMAND, "text_states", 2,
                      "n_states must be an integer in [0, 10000], got '1'"),
    "n_states_huge": ('    name = "huge_states"\n    n_states = 10**9\n' + COMMAND, "huge_states", 2,
                      "n_states must be an integer in [0, 10000], got 1000000000"),
    "gives_voltages": ('    name = "my_volts"\n    outputs = "voltage"\n' + COMMAND, "my_volts", 2, "controller.kind: "
                       "expected a controller that gives voltages ('my_volts') only with a motor on every joint"),
    "bind_sets_n_states": ('    name = "bound_states"\n    def bind(self, context):\n        self.n_states = 1.5\n'
                           + COMMAND, "bound_states", 1, "controller 'bound_states' (law_bind_sets_n_states.py) set "
                           "n_states = 1.5: expected an integer in [0, 10000]"),
    "bind_raises": ('    name = "bind_raises"\n    def bind(self, context):\n        raise ValueError("no bind")\n'
                    + COMMAND, "bind_raises", 1, "controller 'bind_raises' (law_bind_raises.py, line 9) raised "
                    "ValueError: no bind"),
    "init_raises": ('    name = "init_raises"\n    def __init__(self, config, nv):\n        raise RuntimeError("no")\n'
                    + COMMAND, "init_raises", 1, "controller 'init_raises' (law_init_raises.py, line 9) raised "
                    "RuntimeError: no"),
    "read_raises": ('    name = "read_raises"\n    @classmethod\n    def read(cls, r):\n        raise KeyError("x")\n'
                    + COMMAND, "read_raises", 1, "controller 'read_raises' (law_read_raises.py, line 10) raised "
                    "KeyError: 'x'"),
    "read_returns_none": ('    name = "read_none"\n    @classmethod\n    def read(cls, r):\n        return None\n'
                          + COMMAND, "read_none", 1, "controller 'read_none' (law_read_returns_none.py) read returned "
                          "NoneType: expected a config with the kind of its controller"),
    "exits": ("    name = 'exits'\n" + COMMAND + "\n\nimport sys\nsys.exit(3)\n", "exits", 2,
              "found law_exits: SystemExit: 3 (law_exits.py, line 13)\n"),
}

#: a user's stage or friction law module that its register refuses at import: (its source, a piece of stderr)
STAGE = "from contactdyn.laws import Param, StageLaw, register_stage_law\n\n\n@register_stage_law\nclass L(StageLaw):\n"
FRICTION = "from contactdyn.laws import FrictionLaw, Param, register_friction_law\n\n\n@register_friction_law\nclass F"
ROUND3_IMPORTS: dict[str, tuple[str, str]] = {
    "stage_param_m": (STAGE + '    name = "with_m"\n    params = (Param("m", "kg", "a mass", 1.0),)\n',
                      "stage law 'with_m': parameter 'm' is named like a key of the table it is read from"),
    "stage_param_model": (STAGE + '    name = "with_model"\n    params = (Param("model", "-", "x", 1.0),)\n',
                          "stage law 'with_model': parameter 'model' is named like a key"),
    "stage_params_text": (STAGE + '    name = "params_text"\n    params = "k3"\n',
                          "stage law 'params_text': params must be a tuple of Param, got 'k3'"),
    "stage_no_stage_law": (STAGE.replace("(StageLaw)", "") + '    name = "plain"\n',
                           "a stage law must subclass contactdyn.laws.StageLaw"),
    "friction_param_mu_k": (FRICTION + '(FrictionLaw):\n    name = "with_mu_k"\n'
                            '    params = (Param("mu_k", "-", "x", 0.3),)\n',
                            "friction law 'with_mu_k': parameter 'mu_k' is named like a key"),
    "friction_params_twice": (FRICTION + '(FrictionLaw):\n    name = "twice_f"\n'
                              '    params = (Param("a", "-", "a", 1.0), Param("a", "-", "b", 1.0))\n',
                              "friction law 'twice_f': parameter names must be unique"),
    "stage_bounds_crossed": (STAGE + '    name = "crossed"\n    params = (Param("q", "-", "x", lo=5.0, hi=2.0),)\n',
                             "stage law 'crossed': parameter 'q' has lo = 5 > hi = 2: no value is in its bounds"),
    "stage_default_nan": (STAGE + '    name = "nan_default"\n    params = (Param("q", "-", "x", float("nan")),)\n',
                          "stage law 'nan_default': parameter 'q' has default nan outside its bounds [0, inf)"),
    "controller_default_below_lo": (LAW + '    name = "negative_gain"\n    params = (Param("gain", "-", "g", -1.0),)\n'
                                    + COMMAND, "controller 'negative_gain': parameter 'gain' has default -1 outside "
                                    "its bounds [0, inf) (lo = 0 unless declared)"),
    "friction_no_friction_law": (FRICTION + ':\n    name = "plain_f"\n',
                                 "a friction law must subclass contactdyn.laws.FrictionLaw"),
}

#: a user's drive kind whose transmission figures are no numbers: (its class's lines, exit code, a piece of stderr)
KIND = ("from contactdyn.laws import DriveKind, Param, register_drive_kind\n\n\n@register_drive_kind\n"
        "class K(DriveKind):\n    motorized = True\n    params = (Param('g', '-', 'gain', 1.0),)\n")
ROUND3_KINDS: dict[str, tuple[str, int, str]] = {
    "speed_raises": ("    @staticmethod\n    def n_speed(spec):\n        raise ValueError('no speed')\n", 1,
                     "drive kind 'speed_raises' (kind_speed_raises.py, line 11) raised ValueError: no speed; in its "
                     "n_speed"),
    "speed_text": ("    @staticmethod\n    def n_speed(spec):\n        return 'x'\n", 1,
                   "drive kind 'speed_text' (kind_speed_text.py) returned 'x' as its n_speed: expected a number"),
    "negative_inertia": ("    @staticmethod\n    def motor_inertia(spec):\n        return -1.0\n", 2,
                         "robot.drive: expected parameters that give the drive of joint 'q1' (kind 'negative_inertia') "
                         "a finite inertia >= 0 on the motor shaft, found 'motor_inertia = -1 at g = 1'"),
    "negative_limit": ("    has_voltage = True\n    @staticmethod\n    def voltage_limit(spec):\n"
                       "        return -5.0\n", 2,
                       "(kind 'negative_limit') a voltage limit > 0 (inf: none), found 'voltage_limit = -5 at g = 1'"),
}


def round3_cases(tmp: Path) -> list[Case]:
    cases = []
    for i, (sets, code, piece) in enumerate(ROUND3_SETS):
        sets = [sets] if isinstance(sets, str) else sets
        argv = ["run", "b1", *FAST, *[a for text in sets for a in ("--set", text)]]
        cases.append((f"r3/{i:02d} {' '.join(sets)[:60]}", argv, code, piece))
    controller = B1[B1.index("[controller]"):B1.index("[[phase]]")]
    for name, (body, kind, code, piece) in ROUND3_LAWS.items():
        scene = _law_scene(tmp, f"law_{name}", LAW + body, B1.replace(controller, f'[controller]\nkind = "{kind}"\n\n'))
        cases.append((f"r3/law/{name}", ["run", str(scene), *FAST], code, piece))
    for name, (body, code, piece) in ROUND3_KINDS.items():
        scene = _law_scene(tmp, f"kind_{name}", KIND + f"    name = {name!r}\n" + body,
                           B1.replace("[robot]", f'[robot]\ndrive.kind = "{name}"'))
        cases.append((f"r3/kind/{name}", ["run", str(scene), *FAST], code, piece))
    (tmp / "law_reads_some.py").write_text(LAW + '    name = "reads_some"\n'
                                           '    params = (Param("gain", "-", "g", 0.5),)\n'
                                           "    @classmethod\n    def read(cls, r):\n"
                                           "        if r.float('gain', 0.5) > 1.0:\n"
                                           "            raise ValueError('gain too large')\n"
                                           "        return super().read(r)\n" + COMMAND)
    (tmp / "law_reads_some.toml").write_text('imports = ["law_reads_some"]\n' + B1.replace(
        controller, '[controller]\nkind = "reads_some"\n\n'))
    cases.append(("r3/sweep/a_law_reading_one_value_fails_that_run", [
        "sweep", str(tmp / "law_reads_some.toml"), *FAST, "--grid", "controller.gain=0.5,2.0", "--workers", "0",
        "--out", str(tmp / "sweep_reads_some")], 1, "LawError: controller 'reads_some' (law_reads_some.py, line 12) "
        "raised ValueError: gain too large"))
    for key in ("controller.delay", "controller.sensor.seed"):  # a count to fit: every run but the start failed
        argv = ["fit", "force_loop_real_cell", "--data", str(tmp / "log.csv"), "--params", key, "--set",
                "controller.sensor.seed=3", "--workers", "0"]
        cases.append((f"r3/fit/{key}", argv, 2, f"{key}: expected a key the scene reads as a real number (the fit "
                      "moves it continuously; this one is a count: run a sweep over its values instead), found "))
    good = (ROOT / "urdf" / "planar2r_b1.urdf").read_text()
    urdfs = {  # a joint's friction given twice, or as two numbers: the parsers kept the first, or said it in jargon
        "two_dynamics": (good.replace(LIMIT, LIMIT + '<dynamics friction="0.5"/><dynamics friction="5"/>', 1),
                         "joint 'q1': <dynamics> 2 times: expected it once (the URDF's parsers read the first"),
        "two_masses": (good.replace('<mass value="3.0"/>', '<mass value="3.0"/><mass value="30.0"/>', 1),
                       "link 'link1' <inertial>: <mass> 2 times: expected it once"),
        "damping_two_numbers": (good.replace(LIMIT, LIMIT + '<dynamics damping="1 2"/>', 1),
                                "joint 'q1' <dynamics>: damping='1 2': expected one number"),
    }
    for name, (text, piece) in urdfs.items():
        (tmp / f"{name}.urdf").write_text(text)
        cases.append((f"r3/urdf/{name}", ["run", "b1", *FAST, "--set", f'robot.urdf="{tmp / name}.urdf"'], 2, piece))
    for name, (source, piece) in ROUND3_IMPORTS.items():
        cases.append((f"r3/import/{name}", ["run", str(_law_scene(tmp, f"law_{name}", source, B1)), *FAST], 2, piece))
    return cases


def _law_scene(tmp: Path, stem: str, source: str, scene: str) -> Path:
    """The scene file ``stem``.toml (``scene``'s text) importing the law module ``stem``.py (``source``), both
    written in ``tmp``."""
    (tmp / f"{stem}.py").write_text(source)
    path = tmp / f"{stem}.toml"
    path.write_text(f'imports = ["{stem}"]\n' + scene)
    return path


def _friction_cases(tmp: Path, tag: str, laws: dict, header: str = "") -> list[Case]:
    """Round ``tag``'s friction laws (name -> (its coefficient's body, what its error says)) on b1's tip, each run
    compiled and interpreted: each must stop at once naming the law and the contact."""
    tip = 'tangent.law = "{name}"\ntangent.mu_s = 0.6\ntangent.mu_k = 0.4'
    cases = []
    for name, (body, piece) in laws.items():
        stem = f"mu{tag}_{name}"
        scene = _law_scene(tmp, stem, header + NEGATIVE.format(name=stem) + body,
                           B1.replace("tangent.mu = 0.4", tip.format(name=stem)))
        for path in ("compiled", "interpreted"):
            said = (f"contactdyn: error: t = 0 s: friction law '{stem}' ({stem}.py) {piece} at slip speed 0.15 "
                    f"m/s (mu_s = 0.6, mu_k = 0.4) on contact 'tip': {FRICTION_EXPECTED}\n")
            cases.append((f"r{tag}/friction/{name}/{path}", ["run", str(scene), *FAST, "--path", path], 1, said))
    return cases


# ---- round 4: laws' flags, a friction law's negative coefficient, a phase that changes its controller's kind ----
#: a user's law module whose flag its register refuses at import: (its source, a piece of stderr)
ROUND4_FLAGS: dict[str, tuple[str, str]] = {
    "stage_affine_text": (STAGE + '    name = "affine_text"\n    affine = "yes"\n',
                          "stage law 'affine_text': affine must be True or False, got 'yes'"),
    "stage_affine_not": (STAGE + '    name = "affine_not"\n    affine = True\n    @staticmethod\n'
                         '    def force(k, b, p, x, xdot):\n        return max(k * x + b * xdot, 0.0)\n',
                         "stage law 'affine_not': affine = True, but its force at x = -0.01 m, ẋ = 0 m/s is 0 N, "
                         "not K x + B ẋ = -10 N (k = 1000, b = 10): declare affine = False"),
    "scaled": (
        STAGE + '    name = "affine_double"\n    affine = True\n    params = (Param("g", "-", "gain", 2.0),)\n'
        '    @staticmethod\n    def force(k, b, p, x, xdot):\n        return p[0] * k * x + b * xdot\n',
        "stage law 'affine_double': affine = True, but its force at x = -0.01 m, ẋ = 0 m/s is -20 N, not K x + B ẋ "
        "= -10 N (k = 1000, b = 10, g = 2): declare affine = False"),
    "friction_constant_number": (FRICTION + '(FrictionLaw):\n    name = "constant_one"\n    constant = 1\n',
                                 "friction law 'constant_one': constant must be True or False, got 1"),
    "friction_constant_not": (FRICTION + '(FrictionLaw):\n    name = "constant_not"\n    constant = True\n'
                              '    params = (Param("w", "s/m", "fall", 1.0),)\n    @staticmethod\n'
                              '    def coefficient(mu_s, mu_k, p, speed):\n'
                              '        return mu_k + (mu_s - mu_k) / (1.0 + p[0] * speed)\n',
                              "friction law 'constant_not': constant = True, but its mu at slip speed 0 m/s is 0.8, "
                              "not mu_k = 0.5 (mu_s = 0.8, w = 1): declare constant = False"),
    "controller_uses_forces_text": (LAW + '    name = "forces_text"\n    uses_forces = "False"\n' + COMMAND,
                                    "controller 'forces_text': uses_forces must be True or False, got 'False'"),
    "controller_needs_gravity_none": (LAW + '    name = "gravity_none"\n    needs_gravity = None\n' + COMMAND,
                                      "controller 'gravity_none': needs_gravity must be True or False, got None"),
    "controller_reads_orientation_int": (LAW + '    name = "orientation_int"\n    reads_orientation = 0\n' + COMMAND,
                                         "controller 'orientation_int': reads_orientation must be True or False"),
    "kind_motorized_text": (KIND.replace("motorized = True", 'motorized = "True"') + "    name = 'motorized_text'\n",
                            "drive kind 'motorized_text': motorized must be True or False, got 'True'"),
    "kind_has_voltage_int": (KIND + "    name = 'voltage_int'\n    has_voltage = 1\n",
                             "drive kind 'voltage_int': has_voltage must be True or False, got 1"),
}

FRICTION_EXPECTED = "expected a finite coefficient >= 0 (friction opposes the slip)"
#: a user's friction law on B1's sliding tip: (its class's body, how it gives μ, a piece of stderr)
NEGATIVE = ("from contactdyn.laws import FrictionLaw, register_friction_law\n\n\n@register_friction_law\n"
            "class Negative(FrictionLaw):\n    name = {name!r}\n\n")
ROUND4_FRICTION: dict[str, tuple[str, str]] = {
    "coefficient_negative": ("    @staticmethod\n    def coefficient(mu_s, mu_k, p, speed):\n"
                             "        return mu_k - 10.0 + 0.0 * speed\n", "returned μ = -9.6"),
    "kinetic_negative": ("    @classmethod\n    def kinetic(cls, spec, speed):\n"
                         "        return spec.mu_k - 10.0 + 0.0 * speed\n", "returned μ = -9.6"),
    "coefficient_minus_inf": ("    @staticmethod\n    def coefficient(mu_s, mu_k, p, speed):\n"
                              "        return mu_k - 1e308 * 10.0 if speed > 0.0 else mu_k\n", "returned μ = -inf"),
}


def round4_cases(tmp: Path) -> list[Case]:
    cases = []
    for name, (source, piece) in ROUND4_FLAGS.items():
        cases.append((f"r4/flag/{name}", ["run", str(_law_scene(tmp, f"law4_{name}", source, B1)), *FAST], 2, piece))
    (tmp / "law4_bind_flag.py").write_text(LAW + '    name = "bind_flag"\n    def bind(self, context):\n'
                                           '        self.uses_forces = "yes"\n' + COMMAND)
    controller = B1[B1.index("[controller]"):B1.index("[[phase]]")]
    (tmp / "law4_bind_flag.toml").write_text('imports = ["law4_bind_flag"]\n' + B1.replace(
        controller, '[controller]\nkind = "bind_flag"\n\n'))
    cases.append(("r4/flag/bind_sets_uses_forces", ["run", str(tmp / "law4_bind_flag.toml"), *FAST], 1,
                  "controller 'bind_flag' (law4_bind_flag.py) set uses_forces = 'yes': expected True or False"))
    cases += _friction_cases(tmp, "4", ROUND4_FRICTION)
    joint = ('[phase.controller]\nkind = "joint_pd"\nkp = {kp}\nkd = 10.0\n[phase.reference]\nspace = "joint"\n'
             'start = [0.3, -1.3]\n')
    phase = B1[B1.index("[[phase]]"):]
    for name, text, code, piece in [  # B1's [controller] is a task PD with kp [N/m], kd and axes
        ("joint_pd_phase_runs", joint.format(kp=100.0), 0, ""),
        ("joint_pd_phase_own_key", joint.format(kp=-1.0), 2,
         "phase[0].controller.kp: expected a number >= 0 [N·m/rad], found -1.0\n"),
    ]:
        (tmp / f"phase4_{name}.toml").write_text(B1.replace(phase, '[[phase]]\nname = "joint"\n' + text))
        cases.append((f"r4/phase/{name}", ["run", str(tmp / f"phase4_{name}.toml"), *FAST, "--out",
                                           str(tmp / name)], code, piece))
    same = B1.replace("kp = 2000.0", "kp = -2000.0").replace('[[phase]]\nname = "slide"',
                                                             '[[phase]]\nname = "slide"\ncontroller.kd = 50.0')
    (tmp / "phase4_inherited_key.toml").write_text(same)
    cases.append(("r4/phase/inherited_key_named_where_written", ["run", str(tmp / "phase4_inherited_key.toml"),
                                                                 *FAST], 2,
                  "controller.kp (inherited by phase[0].controller): expected a number >= 0 [N/m], found -2000.0\n"))
    return cases


# ---- round 5: a law module's whole error at import, a friction law's non-finite μ, declared affinities --------
LONG = ("the table of gains must have as many rows as the robot has joints; got 3 rows for 2 joints (rows: kp = "
        "[100.0, 200.0, 300.0], kd = [1.0, 2.0, 3.0]); check the file gains.csv next to this scene, whose header "
        "says 'kp,kd' and whose last line ends the table")
#: a user's law module that fails at import: (its source, a piece of stderr: the exception's whole first line and
#: where the user's code raised it)
ROUND5_IMPORTS: dict[str, tuple[str, str]] = {
    "long_message": (f"def helper():\n    raise ValueError({LONG!r})\n\n\nhelper()\n",
                     f"found law5_long_message: ValueError: {LONG} (law5_long_message.py, line 2)\n"),
    "first_line_only": ("raise RuntimeError('the first line says it all\\nand the second is left out')\n",
                        "found law5_first_line_only: RuntimeError: the first line says it all (law5_first_line_only.py"
                        ", line 1)\n"),
    "syntax": ("x = 1\ndef broken(:\n", "found law5_syntax: SyntaxError: invalid syntax (law5_syntax.py, line 2)\n"),
    "exits": ("import sys\n\nsys.exit(3)\n", "found law5_exits: SystemExit: 3 (law5_exits.py, line 3)\n"),
    "refused_at_register": (
        STAGE + '    name = "affine_many"\n    affine = True\n    params = (' + ", ".join(
            f'Param("gain_{i}", "-", "a gain", 1.5)' for i in range(8)) + ',)\n    @staticmethod\n'
        '    def force(k, b, p, x, xdot):\n        return 2.0 * k * x + b * xdot\n',
        "stage law 'affine_many': affine = True, but its force at x = -0.01 m, ẋ = 0 m/s is -20 N, not K x + B ẋ = "
        "-10 N (k = 1000, b = 10, " + ", ".join(f"gain_{i} = 1.5" for i in range(8)) + "): declare affine = False "
        "(law5_refused_at_register.py, line 4)\n"),
}


#: a user's friction law on B1's sliding tip whose μ is not finite: (its class's body, how it gives μ); it stops the
#: run where a negative μ does, named with the contact (round 4's cases)
ROUND5_FRICTION: dict[str, tuple[str, str]] = {
    "coefficient_nan": ("    @staticmethod\n    def coefficient(mu_s, mu_k, p, speed):\n"
                        "        return mu_k + np.nan * speed\n", "returned μ = nan"),
    "coefficient_plus_inf": ("    @staticmethod\n    def coefficient(mu_s, mu_k, p, speed):\n"
                             "        return mu_k + np.inf if speed > 0.0 else mu_k\n", "returned μ = inf"),
    "kinetic_nan": ("    @classmethod\n    def kinetic(cls, spec, speed):\n        return spec.mu_k + np.nan * speed\n",
                    "returned μ = nan"),
    "kinetic_plus_inf": ("    @classmethod\n    def kinetic(cls, spec, speed):\n"
                         "        return spec.mu_k + np.inf * speed\n", "returned μ = inf"),
}

#: a user's drive kind with a voltage (B1's joints): (its voltage's body, exit code, a piece of stderr); its force takes
#: the voltage as it is
VOLTS = ("    has_voltage = True\n    @staticmethod\n    def force(spec, command, q, qd, theta, omega):\n"
         "        return command, 0.0, command * qd, 0.0\n    @staticmethod\n    def voltage(spec, tau, qd, omega):\n")
ROUND5_KINDS: dict[str, tuple[str, int, str]] = {
    "voltage_squared": ("        return spec.g * tau * abs(tau) + qd\n", 1,
                        "contactdyn: error: drive kind 'voltage_squared' (kind5_voltage_squared.py) gives u = -6.25 V "
                        "at τ = -2.5 N·m or N, q̇ = 0 (g = 1), not u(0) + τ (u(1) − u(0)) = -2.5 V: expected a voltage "
                        "affine in τ (has_voltage: the solve folds a force-reading controller's command through it)\n"),
    "voltage_clipped": ("        return max(min(spec.g * tau, 20.0), -20.0) + 0.1 * qd\n", 1,
                        "gives u = 20 V at τ = 40 N·m or N, q̇ = 0 (g = 1), not u(0) + τ (u(1) − u(0)) = 40 V"),
    "voltage_affine_runs": ("        return spec.g * tau - 0.5 * qd\n", 0, ""),
    "voltage_slope_undeclared": (
        "        return 2.0 * spec.g * tau - 0.5 * qd\n", 1,
        "contactdyn: error: drive kind 'voltage_slope_undeclared' (kind5_voltage_slope_undeclared.py) gives 2 of force "
        "on its coordinate per unit force command (at rest, τ = ±0.001 N·m or N through its voltage), not its "
        "command_gain 1: declare command_gain as its law's slope (the solve folds a force-reading controller's command "
        "by it)\n"),
    "voltage_raising_past_a_limit_runs": ("        if abs(tau) > 1e6:\n            raise ValueError('too much')\n"
                                          "        return spec.g * tau\n", 0, ""),
}

#: a user's controller on B1 that declares uses_forces (its contact 'tip', 2 joints): (its command's body, exit code, a
#: piece of stderr); F is the measured force on 'tip' [N], tc the generalized contact force [N·m]
ROUND5_FORCES: dict[str, tuple[str, int, str]] = {
    "forces_clipped": ("        return np.full(2, max(F, 0.0)), None\n", 1,
                       "contactdyn: error: controller 'forces_clipped' (ctl5_forces_clipped.py) declares uses_forces = "
                       "True, but its command at forces['tip'] = -2.5 N gives τ = [0, 0], not τ₀ + B F = [-2.5, -2.5] "
                       "(τ₀, B: its command at forces 0 and its differences at 1): expected a command affine in the "
                       "forces it reads (the solve folds them in)\n"),
    "forces_squared": ("        return np.array([F * F, 0.0]), None\n", 1,
                       "its command at forces['tip'] = -2.5 N gives τ = [6.25, 0], not τ₀ + B F = [-2.5, 0]"),
    "tau_contact_clipped": ("        return np.clip(tc, -1.0, 1.0), None\n", 1,
                            "its command at tau_contact[0] = -2.5 N·m or N gives τ = [-1, 0], not τ₀ + B F = "
                            "[-2.5, 0]"),
    "forces_times_tau_contact": ("        return np.array([F * tc[1], 0.0]), None\n", 1,
                                 "its command at forces['tip'] = -2.5 N, tau_contact = [40, -2.5] N·m or N (all at "
                                 "once) gives τ = [6.25, 0], not τ₀ + B F = [0, 0]"),
    "state_rate_squared": ("        return np.zeros(2), np.array([F * F])\n", 1,
                           "its command at forces['tip'] = -2.5 N gives ż = [6.25], not ż₀ + D F = [-2.5]"),
    "affine_runs": ("        return 0.01 * tc + np.full(2, 0.001 * F - 0.5), None\n", 0, ""),
    "clipped_in_motion": ("        return np.clip(np.full(2, F) + 100.0 * inp.v, -50.0, 50.0), None\n", 1,
                          "its command at forces['tip'] = -2.5 N gives τ = [47.5, 47.5], not τ₀ + B F = [50, 50]"),
}


def round5_cases(tmp: Path) -> list[Case]:
    cases = []
    for name, (source, piece) in ROUND5_IMPORTS.items():
        cases.append((f"r5/import/{name}", ["run", str(_law_scene(tmp, f"law5_{name}", source, B1)), *FAST], 2, piece))
    cases += _friction_cases(tmp, "5", ROUND5_FRICTION, header="import numpy as np\n")
    for name, (body, code, piece) in ROUND5_KINDS.items():
        scene = _law_scene(tmp, f"kind5_{name}", KIND + f"    name = {name!r}\n" + VOLTS + body,
                           B1.replace("[robot]", f'[robot]\ndrive.kind = "{name}"'))
        cases.append((f"r5/kind/{name}", ["run", str(scene), *FAST, "--out", str(tmp / name)], code, piece))
    controller = B1[B1.index("[controller]"):B1.index("[[phase]]")]
    for name, (body, code, piece) in ROUND5_FORCES.items():
        states = "    n_states = 1\n" if name.startswith("state") else ""
        source = (LAW + f"    name = {name!r}\n    uses_forces = True\n{states}    def command(self, inp):\n"
                  "        F, tc = inp.forces['tip'], inp.tau_contact\n" + body)
        scene = _law_scene(tmp, f"ctl5_{name}", source,
                           B1.replace(controller, f'[controller]\nkind = "{name}"\n\n'))
        cases.append((f"r5/uses_forces/{name}", ["run", str(scene), *FAST, "--out", str(tmp / name)], code, piece))
    return cases


BUILDERS = {"scenes": scene_cases, "overrides": lambda _: override_cases(), "urdfs": urdf_cases,
            "run_files": run_file_cases, "round2": round2_cases,
            "round3": round3_cases, "round4": round4_cases, "round5": round5_cases}


def test_corpus_has_at_least_100_cases(tmp_path):
    counts = {}
    for kind, build in BUILDERS.items():
        (tmp_path / kind).mkdir()
        counts[kind] = len(build(tmp_path / kind))
    assert sum(counts.values()) >= 100 and min(counts.values()) >= 20, counts


@pytest.mark.timeout(600)
@pytest.mark.parametrize("kind", ["scenes", "overrides", "urdfs", "run_files", "round2", "round3", "round4", "round5"])
def test_hostile_inputs(tmp_path, kind):
    check(BUILDERS[kind](tmp_path), tmp_path)


# ---- a fuzz of scene files through the command line (fixed seed) ---------------------------------
def fuzz_cases(tmp: Path, n: int = 36, seed: int = 20261129) -> list[tuple[str, list[str]]]:
    """``n`` mutants of sims/b1.toml, each a line changed: a value replaced by a hostile one, a line dropped or
    duplicated, a key renamed, bytes flipped."""
    rng = np.random.default_rng(seed)
    lines = B1.splitlines()
    values = ["nan", "inf", "-inf", "-1", "0", "1e300", "-1e-300", '"x"', "[]", "{}", "true", "[1e9, 1e9, 1e9]",
              '"../../x"', "1e-30"]
    cases = []
    for i in range(n):
        mutant = list(lines)
        k = int(rng.integers(len(mutant)))
        how = int(rng.integers(5))
        if how == 0 and "=" in mutant[k]:
            mutant[k] = mutant[k].split("=", 1)[0] + "= " + values[int(rng.integers(len(values)))]
        elif how == 1:
            del mutant[k]
        elif how == 2:
            mutant.insert(k, mutant[k])
        elif how == 3 and "=" in mutant[k]:
            mutant[k] = "z" + mutant[k].lstrip()
        else:
            raw = bytearray("\n".join(mutant).encode())
            for j in rng.integers(len(raw), size=3):
                raw[j] = int(rng.integers(32, 127))
            mutant = raw.decode(errors="replace").splitlines()
        path = tmp / f"mutant{i}.toml"
        path.write_text("\n".join(mutant) + "\n")
        cases.append((f"fuzz/{i}", ["run", str(path), "--set", "duration=0.02", "--set", "solver.output_rate=200"]))
    return cases


@pytest.mark.timeout(300)
def test_a_fuzz_of_scene_files_ends_in_a_result_or_one_line(tmp_path):
    """Every mutant runs (exit 0), fails with a reason (exit 1) or is bad input (exit 2, one line): no traceback."""
    cases = fuzz_cases(tmp_path)
    results = run_batch([(cid, argv, 0, "") for cid, argv in cases], tmp_path)
    wrong = []
    for cid, _ in cases:
        r = results[cid]
        one_line = r["code"] != 2 or (r["err"].count("\n") == 1 and r["err"].startswith("contactdyn"))
        if r["code"] not in (0, 1, 2) or "Traceback" in r["err"] or not one_line:
            wrong.append(f"{cid}: exit {r['code']}: {r['err'][:400]!r}")
    assert not wrong, "\n".join(wrong)
    assert {results[cid]["code"] for cid, _ in cases} >= {0, 2}  # the fuzz reaches both kinds of ending
