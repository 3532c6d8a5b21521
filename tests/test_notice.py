"""The first run's compilation is announced (contactdyn.numerics.notice), once per process, and only when it is slow.

No test here depends on wall time: the blocks are timed by a replaced clock, and a threshold of 0 says at once.
"""

from __future__ import annotations

import numba
import pytest

import contactdyn.numerics.compile_cache as compile_cache
import contactdyn.numerics.notice as notice

LINE = "contactdyn: compiling"


@pytest.fixture
def watch(monkeypatch):
    """A fresh process's watch, its clock at 0 s (advance it by setting ``now[0]``)."""
    now = [0.0]
    monkeypatch.setattr(notice, "_watch", notice._Watch())
    monkeypatch.setattr(notice, "clock", lambda: now[0])
    return now


def test_a_threshold_of_zero_says_once_at_the_first_block(watch, monkeypatch, capsys):
    monkeypatch.setattr(notice, "NOTICE_AFTER", 0.0)
    for _ in range(3):
        with notice.compiling("kernels"):
            pass
    err = capsys.readouterr().err
    assert err.count(LINE) == 1 and f"{LINE} kernels" in err and "cached for later runs" in err


def test_short_blocks_say_nothing_until_their_sum_passes_the_threshold(watch, monkeypatch, capsys):
    monkeypatch.setattr(notice, "NOTICE_AFTER", 100.0)  # [s] of the fake clock; a block's timer waits 40-100 s
    for start in (0.0, 60.0):
        with notice.compiling("kernels"):
            with notice.compiling("a callee"):  # nested: counted once
                watch[0] = start + 60.0
        assert capsys.readouterr().err == ""
    assert notice._watch.spent == 120.0
    with notice.compiling("the plan"):  # 120 s compiled already: said at once
        pass
    assert capsys.readouterr().err.count(f"{LINE} the plan") == 1


def test_every_numba_compile_of_the_package_is_a_block_and_others_are_not(watch, monkeypatch, capsys):
    monkeypatch.setattr(notice, "NOTICE_AFTER", 0.0)

    def add_one(x):
        return x + 1

    numba.njit(add_one)(1)  # this test module's function: not the package's
    assert capsys.readouterr().err == ""
    add_one.__module__ = "contactdyn.a_module_for_the_test"
    numba.njit(add_one)(1)  # compiled: the listener compile_cache registered says it
    assert capsys.readouterr().err.count(f"{LINE} {compile_cache.CompileNotice.WHAT}") == 1
    assert notice._watch.depth == 0


def test_an_interpreted_run_names_what_it_compiles(watch, monkeypatch, capsys):
    """Within ``about``, a compile of the package is announced as what the block says (an interpreted run compiles
    only the leaves its Python twins call), outside it as the default; ``simulate(compiled=False)`` runs in such a
    block, the compiled path outside any."""
    monkeypatch.setattr(notice, "NOTICE_AFTER", 0.0)

    def add_two(x):
        return x + 2

    add_two.__module__ = "contactdyn.a_module_for_the_test"
    with notice.about("the shared arithmetic"):
        assert notice.subject("default") == "the shared arithmetic"
        numba.njit(add_two)(1)
    assert notice.subject("default") == "default"
    assert f"{LINE} the shared arithmetic" in capsys.readouterr().err
    from contactdyn import simulate

    seen = []
    real = notice.about
    monkeypatch.setattr(notice, "about", lambda what: seen.append(what) or real(what))
    simulate("b1", {"duration": 0.01}, compiled=False)
    simulate("b1", {"duration": 0.01})
    assert len(seen) == 1 and "the interpreted call runs compiled" in seen[0]
