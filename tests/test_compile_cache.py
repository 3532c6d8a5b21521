"""The compiled code's cache (contactdyn.numerics.compile_cache): keyed by the compiled source, where the user says."""

from __future__ import annotations

import ast
import importlib.util
import os
import shutil
import tempfile
from pathlib import Path

import numba

import contactdyn.numerics.compile_cache as cc

COMPILED = "from .compile_cache import njit\n\n\n@njit(cache=True)\ndef f(x):\n    return x + 1\n"


def _package(tmp_path: Path) -> Path:
    pkg = tmp_path / "pkg"
    (pkg / "sub").mkdir(parents=True)
    (pkg / "kernel.py").write_text(COMPILED)
    (pkg / "sub" / "law.py").write_text(COMPILED.replace("from .", "from .."))
    (pkg / "plain.py").write_text("X = 1\n")
    return pkg


def test_the_key_changes_with_a_compiled_module_and_the_version_only(tmp_path):
    pkg = _package(tmp_path)
    assert cc.compiled_modules(pkg) == [pkg / "kernel.py", pkg / "sub" / "law.py"]
    before = cc.key(pkg)
    assert before.startswith(f"contactdyn-{cc.__version__}-") and len(before.rsplit("-", 1)[1]) == cc.HASH_CHARS
    (pkg / "plain.py").write_text("X = 2\n")
    assert cc.key(pkg) == before  # not compiled: numba never sees it
    (pkg / "sub" / "law.py").write_text(COMPILED.replace("from .", "from ..").replace("x + 1", "x + 2"))
    assert cc.key(pkg) != before
    assert cc.key(pkg, "9.9") != cc.key(pkg)


def test_the_key_changes_with_the_package_s_place_and_a_compiled_module_s_time(tmp_path):
    """numba keys its cache by a file's absolute path and time: another checkout or a reinstall has its own key."""
    pkg = _package(tmp_path)
    before = cc.key(pkg)
    os.utime(pkg / "plain.py", ns=(1, 1))
    assert cc.key(pkg) == before  # not compiled
    os.utime(pkg / "kernel.py", ns=(1, 1))
    assert cc.key(pkg) != before
    copy = tmp_path / "elsewhere" / "pkg"
    shutil.copytree(pkg, copy, copy_function=shutil.copy2)  # (the same sources and times, another place)
    assert cc.key(copy) != cc.key(pkg)


def test_a_mention_or_a_local_import_does_not_make_a_module_compiled(tmp_path):
    pkg = _package(tmp_path)
    (pkg / "notes.py").write_text('"""Compiled modules say: from .compile_cache import njit."""\n'
                                  "# from .compile_cache import njit (a comment)\n")
    (pkg / "runner.py").write_text("def folder():\n    from .compile_cache import directory\n\n"
                                   "    return directory()\n")
    assert cc.compiled_modules(pkg) == [pkg / "kernel.py", pkg / "sub" / "law.py"]
    (pkg / "runner.py").write_text("from .sub.compile_cache import directory\n")  # (top level: compiled)
    assert cc.compiled_modules(pkg) == [pkg / "kernel.py", pkg / "runner.py", pkg / "sub" / "law.py"]


def test_the_package_itself_has_its_compiled_modules_found():
    names = {p.relative_to(cc.PACKAGE).as_posix() for p in cc.compiled_modules()}
    assert {"numerics/linalg.py", "robot/rigid_body.py", "model/pipeline/pipeline.py", "hybrid/steps.py",
            "laws/controllers/computed_torque.py", "model/chain_forces.py"} <= names
    assert "first_run.py" not in names  # (it reads the directory by a local import: it compiles nothing)


def test_the_directory_is_under_numba_cache_dir_when_set(tmp_path, monkeypatch):
    pkg = _package(tmp_path)
    monkeypatch.setenv("NUMBA_CACHE_DIR", str(tmp_path / "user"))
    where = cc.cache_dir(os.environ, pkg)
    assert where == tmp_path / "user" / cc.key(pkg) and where.is_dir()


def test_the_directory_is_the_users_cache_folder_by_default(tmp_path, monkeypatch):
    pkg = _package(tmp_path)
    monkeypatch.delenv("NUMBA_CACHE_DIR", raising=False)
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "xdg"))
    assert cc.cache_dir(os.environ, pkg) == tmp_path / "xdg" / "contactdyn" / "numba" / cc.key(pkg)


def test_an_unwritable_place_falls_back_to_the_temp_folder(tmp_path, monkeypatch):
    pkg = _package(tmp_path)
    (tmp_path / "a_file").write_text("")  # no folder can be made under a file
    monkeypatch.setattr(tempfile, "tempdir", str(tmp_path / "tmp"))
    where = cc.cache_dir({"NUMBA_CACHE_DIR": str(tmp_path / "a_file")}, pkg)
    assert where.parent.parent == tmp_path / "tmp" and where.name == cc.key(pkg) and where.is_dir()


def test_no_home_falls_back_to_the_temp_folder(tmp_path, monkeypatch):
    pkg = _package(tmp_path)

    def no_home():
        raise RuntimeError("Could not determine home directory.")

    monkeypatch.setattr(Path, "home", no_home)
    monkeypatch.setattr(tempfile, "tempdir", str(tmp_path / "tmp"))
    assert cc.cache_dir({}, pkg).parent.parent == tmp_path / "tmp"


def test_keys_unused_for_long_are_removed_and_others_kept(tmp_path, monkeypatch):
    pkg = _package(tmp_path)
    root = tmp_path / "user"
    now = 4.0e9  # [s] since the epoch: the clock the keys' ages are measured against (not the machine's)
    monkeypatch.setattr(cc, "clock", lambda: now)
    old, recent = now - (cc.STALE_AFTER + 1) * 86400.0, now - 86400.0  # [s]
    for name, used in (("contactdyn-0.0.1-aaaaaaaaaaaa", old), ("contactdyn-0.0.2-bbbbbbbbbbbb", recent),
                       ("someone_else", old)):
        (root / name).mkdir(parents=True)
        os.utime(root / name, (used, used))
    cc.cache_dir({"NUMBA_CACHE_DIR": str(root)}, pkg)
    assert sorted(p.name for p in root.iterdir()) == sorted(["contactdyn-0.0.2-bbbbbbbbbbbb", "someone_else",
                                                             cc.key(pkg)])


def test_a_cached_function_lands_in_the_directory_and_numba_keeps_the_users_setting(tmp_path, monkeypatch):
    monkeypatch.setattr(cc, "directory", lambda: tmp_path / "cache")
    saved = numba.config.CACHE_DIR
    source = tmp_path / "compiled_module_for_test.py"
    source.write_text(COMPILED.replace("from .compile_cache", "from contactdyn.numerics.compile_cache"))
    spec = importlib.util.spec_from_file_location("compiled_module_for_test", source)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    assert numba.config.CACHE_DIR == saved
    assert module.f(1) == 2
    assert list((tmp_path / "cache").rglob("*.nbi")) and list((tmp_path / "cache").rglob("*.nbc"))


def _imported_from_plain_modules(path: Path, compiled: set[Path]) -> dict[str, Path]:
    """Names a module imports (``from .x import name``) from the package's modules that are not compiled."""
    found = {}
    for node in ast.parse(path.read_text()).body:
        if not (isinstance(node, ast.ImportFrom) and node.level):
            continue
        base = path.parent
        for _ in range(node.level - 1):
            base = base.parent
        target = base.joinpath(*(node.module or "").split("."))
        for alias in node.names:
            module = next((q for q in (target / f"{alias.name}.py", target.with_suffix(".py"),
                                       target / "__init__.py") if q.is_file()), None)
            if module is not None and module.name != "compile_cache.py" and module not in compiled:
                found[alias.asname or alias.name] = module
    return found


def test_no_compiled_function_reads_a_name_from_a_module_the_key_does_not_hash():
    """numba freezes a compiled function's globals: a constant imported from an unhashed module would go stale."""
    compiled = set(cc.compiled_modules())
    stale = []
    for path in sorted(compiled):
        outside = _imported_from_plain_modules(path, compiled)
        for fn in ast.walk(ast.parse(path.read_text())):
            if isinstance(fn, ast.FunctionDef) and any("njit" in ast.unparse(d) for d in fn.decorator_list):
                names = {n.id for n in ast.walk(fn) if isinstance(n, ast.Name)} & set(outside)
                stale += [f"{path.name}: {fn.name} reads {n} of {outside[n].name}" for n in sorted(names)]
    assert stale == []


def _twice(x):
    return 2 * x


def test_njit_called_on_a_function_with_options_gives_the_compiled_function():
    """``njit(f, cache=False)`` as numba's: the dispatcher, not a decorator waiting for a function."""
    compiled = cc.njit(_twice, cache=False)
    assert isinstance(compiled, numba.core.registry.CPUDispatcher) and compiled(21) == 42
    assert cc.njit(cache=False)(_twice)(4) == 8  # the decorator form as before


def _saves(folder: str, tag: str, n: int) -> None:
    """(In a forked child) n cache entries of ``tag`` saved into one index, as numba saves a compiled function."""
    from numba.core import caching

    index = caching.IndexDataCacheFile(folder, "f", ("stamp", 1))
    for i in range(n):
        index.save((tag, i), (tag, i))
    os._exit(0)


def test_two_processes_saving_into_one_index_lose_and_mix_up_nothing(tmp_path, monkeypatch):
    """numba's save reads the index, adds the entry and writes it back: two processes at once (a first run and its
    leaves' helper) lost or swapped about a third of 300 entries without the lock; with it (compile_cache.locked_save)
    every entry loads its own data."""
    import multiprocessing

    from numba.core import caching

    monkeypatch.setattr(cc, "directory", lambda: tmp_path)
    assert getattr(caching.IndexDataCacheFile.save, "holds_lock", False)
    context = multiprocessing.get_context("fork")
    writers = [context.Process(target=_saves, args=(str(tmp_path), tag, 150)) for tag in "ab"]
    for w in writers:
        w.start()
    for w in writers:
        w.join(60)
    assert [w.exitcode for w in writers] == [0, 0]
    index = caching.IndexDataCacheFile(str(tmp_path), "f", ("stamp", 1))
    assert [(tag, i) for tag in "ab" for i in range(150) if index.load((tag, i)) != (tag, i)] == []
