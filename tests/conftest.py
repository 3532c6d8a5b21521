"""Tests marked ``slow`` run only when asked: ``pytest --slow`` (or ``-m slow``)."""

from __future__ import annotations

import pytest


def pytest_addoption(parser):
    parser.addoption("--slow", action="store_true", help="also run the tests marked slow")


def pytest_collection_modifyitems(config, items):
    if config.getoption("--slow") or "slow" in (config.getoption("-m") or ""):
        return
    skip = pytest.mark.skip(reason="slow: run with --slow")
    for item in items:
        if "slow" in item.keywords:
            item.add_marker(skip)


@pytest.fixture
def doubled_law():
    """An affine stage law twice as stiff and twice as damped as its k and b say, registered as ``doubled`` for
    the test (F = 2k x + 2b ẋ: coefficients (2k, 2b))."""
    from contactdyn.laws.stage_laws import STAGE_LAWS, StageLaw, register_stage_law

    class Doubled(StageLaw):
        name, affine = "doubled", True

        @staticmethod
        def force(k, b, p, x, xdot):
            return 2.0 * k * x + 2.0 * b * xdot

        @staticmethod
        def coefficients(k, b, p):
            return 2.0 * k, 2.0 * b

    register_stage_law(Doubled)
    yield Doubled.name
    STAGE_LAWS.pop(Doubled.name, None)
