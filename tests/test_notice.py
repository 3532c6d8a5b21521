"""The first run's compilation is announced (contactdyn.hybrid.notice), once, and only when it is slow."""

from __future__ import annotations

import time

import contactdyn.hybrid.notice as notice


def test_a_slow_build_is_announced_once_and_a_fast_one_not(monkeypatch, capsys):
    monkeypatch.setattr(notice, "NOTICE_AFTER", 0.05)
    monkeypatch.setattr(notice, "_said", type(notice._said)())
    with notice.compiling("kernels"):
        pass
    time.sleep(0.1)
    assert capsys.readouterr().err == ""
    for _ in range(2):
        with notice.compiling("kernels"):
            time.sleep(0.2)
    err = capsys.readouterr().err
    assert err.count("contactdyn: compiling kernels") == 1 and "cached for later runs" in err
