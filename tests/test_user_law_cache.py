"""A user's law as its files say now, after an edit: its compiled code is cached keyed by every one of the user's files
it depends on (contactdyn.numerics.compile_cache.sources_key), so an edit of a file the law imports a constant or a
compiled helper from compiles it again in the next process (numba alone checks the law's own file and would load the
old code); and a process that reads the scene again (a notebook, a sweep's worker) imports the edited modules again
(contactdyn.scene.user_laws)."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import types
from pathlib import Path

import numpy as np

import contactdyn.numerics.compile_cache as cc
from contactdyn import parse_scene, simulate
from contactdyn.laws.stage_laws import STAGE_LAWS
from contactdyn.scene.user_laws import import_scene_modules

ROOT = Path(__file__).resolve().parent.parent

LAW = '''
from contactdyn.laws import StageLaw
from law_constants import K3
from law_helpers import shape


class EditedLaw(StageLaw):
    name = "edited_for_cache_test"

    @staticmethod
    def force(k, b, p, x, xdot):
        return K3 * shape(x) + k * x + b * xdot
'''
HELPERS = "import numba\n\n\n@numba.njit\ndef shape(x):\n    return {shape}\n"
#: the law through its compiled C function, in a process of its own: F at x = 0.5 m, ẋ = 0 (k = 1, b = 0)
PROBE = '''
import json, sys
import numba
import numpy as np
sys.path.insert(0, sys.argv[1])
from law import EditedLaw
from contactdyn.laws import abi
address = abi.stage_address(EditedLaw)

@numba.njit
def force(address):
    return abi.call_stage(address, 1.0, 0.0, np.zeros(0), 0, 0, 0.5, 0.0)

print(json.dumps({"force": force(address), "reason": EditedLaw.compiled_reason}))
'''


def _force(folder: Path, cache: Path) -> float:
    env = {**os.environ, "NUMBA_CACHE_DIR": str(cache), "PYTHONPATH": str(ROOT)}
    done = subprocess.run([sys.executable, "-c", PROBE, str(folder)], env=env, capture_output=True, text=True,
                          timeout=300)
    assert done.returncode == 0, done.stderr[-2000:]
    got = json.loads(done.stdout.strip().splitlines()[-1])
    assert got["reason"] == ""  # compiled, not a declared Python stage
    return got["force"]


def test_an_edit_of_a_file_the_law_imports_from_compiles_it_again(tmp_path):
    folder, cache = tmp_path / "laws", tmp_path / "cache"
    folder.mkdir()
    (folder / "law.py").write_text(LAW)
    (folder / "law_constants.py").write_text("K3 = 2.0\n")
    (folder / "law_helpers.py").write_text(HELPERS.format(shape="x * x"))
    assert _force(folder, cache) == 2.0 * 0.25 + 0.5
    assert _force(folder, cache) == 2.0 * 0.25 + 0.5  # loaded from the cache
    (folder / "law_constants.py").write_text("K3 = 3.0\n")  # the same size: numba's own check could not tell
    assert _force(folder, cache) == 3.0 * 0.25 + 0.5
    (folder / "law_helpers.py").write_text(HELPERS.format(shape="x * x * x"))
    assert _force(folder, cache) == 3.0 * 0.125 + 0.5
    assert len(list(cache.rglob("user-*"))) == 3  # one directory per state of the law's sources


def _module(tmp_path: Path, name: str, source: str, package: str = "") -> types.ModuleType:
    path = tmp_path / f"{name.replace('.', '/')}.py"
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(source)
    module = types.ModuleType(name)
    module.__file__, module.__package__ = str(path), package
    return module


def test_the_sources_are_the_users_modules_imported_transitively_and_no_installed_one(tmp_path, monkeypatch):
    modules = {
        "mylaw": _module(tmp_path, "mylaw", "import numpy as np\nimport contactdyn\nfrom tools.consts import K\n"),
        "tools": _module(tmp_path, "tools/__init__", "", "tools"),
        "tools.consts": _module(tmp_path, "tools.consts", "from .deep import D\nK = D\n", "tools"),
        "tools.deep": _module(tmp_path, "tools.deep", "D = 1.0\n", "tools"),
        "unused": _module(tmp_path, "unused", "U = 2\n"),
    }
    for name, module in modules.items():
        monkeypatch.setitem(sys.modules, name, module)

    def law(x):
        return x

    law.__module__ = "mylaw"
    found = sorted(p.relative_to(tmp_path).as_posix() for p in cc.user_sources(law))
    assert found == ["mylaw.py", "tools/__init__.py", "tools/consts.py", "tools/deep.py"]
    before = cc.sources_key(law)
    (tmp_path / "tools" / "deep.py").write_text("D = 2.0\n")
    assert cc.sources_key(law) != before
    after = cc.sources_key(law)
    (tmp_path / "unused.py").write_text("U = 3\n")  # a module the law does not import
    assert cc.sources_key(law) == after


def test_a_function_of_the_package_or_an_installed_one_has_no_user_sources():
    import numpy as np

    from contactdyn.laws.stage_laws import Linear

    assert cc.user_sources(Linear.force) == {}
    assert cc.user_sources(np.linalg.norm) == {}


SCALED = '''
from contactdyn.laws import StageLaw, register_stage_law
from scaled_law_factor import S


@register_stage_law
class Scaled(StageLaw):
    name = "scaled_for_reimport_test"

    @staticmethod
    def force(k, b, p, x, xdot):
        return S * k * x + b * xdot
'''


def _press(folder: Path, law: str, k: float):
    """examples/cubic_press.toml for 0.05 s with stage law ``law`` of stiffness k [N/m]."""
    import tomllib

    doc = tomllib.loads((ROOT / "examples" / "cubic_press.toml").read_text())
    doc.update(imports=["scaled_law"], duration=0.05)
    doc["contact"]["tip"]["normal"].update(law=law, k=k)
    del doc["contact"]["tip"]["normal"]["k3"]
    return simulate(parse_scene(doc, file=str(folder / "press.toml")))


def test_a_process_that_reads_the_scene_again_runs_the_edited_law(tmp_path, fresh_user_imports):
    (tmp_path / "scaled_law.py").write_text(SCALED)
    (tmp_path / "scaled_law_factor.py").write_text("S = 1.0\n")
    import_scene_modules(["scaled_law"], str(tmp_path / "press.toml"))
    first = STAGE_LAWS["scaled_for_reimport_test"]
    import_scene_modules(["scaled_law"], str(tmp_path / "press.toml"))
    assert STAGE_LAWS["scaled_for_reimport_test"] is first  # nothing edited: not imported again
    runs = {}
    for factor in (1.0, 2.0):
        (tmp_path / "scaled_law_factor.py").write_text(f"S = {factor}\n")  # (the law's own file unchanged)
        runs[factor] = _press(tmp_path, "scaled_for_reimport_test", 1e5), _press(tmp_path, "linear", factor * 1e5)
    for mine, twin in runs.values():  # the user's law S k x + b ẋ is the linear law of stiffness S k
        F, F_twin = mine["contact.tip.F_n"], twin["contact.tip.F_n"]
        assert np.abs(F - F_twin).max() <= 1e-9 * np.abs(F_twin).max()
    assert np.abs(runs[2.0][0]["contact.tip.F_n"] - runs[1.0][0]["contact.tip.F_n"]).max() > 0.1  # [N] it moved (0.6 N)
    assert STAGE_LAWS["scaled_for_reimport_test"] is not first
