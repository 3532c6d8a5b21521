"""Tests marked ``slow`` run only when asked: ``pytest --slow`` (or ``-m slow``)."""

from __future__ import annotations

import os
import sys

import pytest

# `contactdyn run` in a test takes the compiled call, never starting a background build (contactdyn.first_run);
# tests/test_first_run.py tests the path ``auto`` itself
os.environ.setdefault("CONTACTDYN_PATH", "compiled")


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
def stage_law_registry():
    """``register(cls)``: a stage law registered for one test (returned), removed from the registry after it."""
    from contactdyn.laws.stage_laws import STAGE_LAWS, register_stage_law

    added: list[str] = []

    def register(cls):
        register_stage_law(cls)
        added.append(cls.name)
        return cls

    yield register
    for name in added:
        STAGE_LAWS.pop(name, None)


@pytest.fixture
def fresh_user_imports(monkeypatch):
    """A test that imports a user's law modules afresh (scene ``imports``): the import state, the four law
    registries, the key reference and those modules as they were, before and after it."""
    import contactdyn.scene.user_laws as user_laws
    from contactdyn.laws.controllers import CONTROLLERS
    from contactdyn.laws.drive_kinds import DRIVE_KINDS
    from contactdyn.laws.friction_laws import FRICTION_LAWS
    from contactdyn.laws.stage_laws import STAGE_LAWS
    from contactdyn.scene.keys import reference

    monkeypatch.setattr(user_laws, "_state", {"allowed": True, "entry_points": False})
    monkeypatch.setattr(user_laws, "IMPORTED", {})
    saved = [(registry, dict(registry)) for registry in (STAGE_LAWS, FRICTION_LAWS, DRIVE_KINDS, CONTROLLERS)]
    modules = set(sys.modules)
    reference.cache_clear()
    yield
    for registry, content in saved:
        registry.clear()
        registry.update(content)
    for name in set(user_laws.IMPORTED) - modules:  # (the test's own law modules: imported afresh by the next)
        sys.modules.pop(name, None)
    reference.cache_clear()


@pytest.fixture(scope="module")
def user_laws_after_module():
    """A module whose cases import the examples' law modules (scene ``imports``) once and keep them for its tests:
    after it, the law registries, the import record, those modules and the key reference as they were before (a
    later module sees no user law: tests/test_laws.py checks that)."""
    import contactdyn.scene.user_laws as user_laws
    from contactdyn.laws.controllers import CONTROLLERS
    from contactdyn.laws.drive_kinds import DRIVE_KINDS
    from contactdyn.laws.friction_laws import FRICTION_LAWS
    from contactdyn.laws.stage_laws import STAGE_LAWS
    from contactdyn.scene.keys import reference

    saved = [(registry, dict(registry)) for registry in (STAGE_LAWS, FRICTION_LAWS, DRIVE_KINDS, CONTROLLERS)]
    imported = dict(user_laws.IMPORTED)
    yield
    for registry, content in saved:
        registry.clear()
        registry.update(content)
    for name in set(user_laws.IMPORTED) - set(imported):  # (imported afresh by the next scene that names it)
        sys.modules.pop(name, None)
    user_laws.IMPORTED.clear()
    user_laws.IMPORTED.update(imported)
    reference.cache_clear()


@pytest.fixture
def doubled_law(stage_law_registry):
    """An affine stage law twice as stiff and twice as damped as its k and b say, registered as ``doubled`` for
    the test (F = 2k x + 2b ẋ: coefficients (2k, 2b))."""
    from contactdyn.laws.stage_laws import StageLaw

    class Doubled(StageLaw):
        name, affine = "doubled", True

        @staticmethod
        def force(k, b, p, x, xdot):
            return 2.0 * k * x + 2.0 * b * xdot

        @staticmethod
        def coefficients(k, b, p):
            return 2.0 * k, 2.0 * b

    return stage_law_registry(Doubled).name


_SCALE = {"k": 1.0}  #: a Python dict: numba cannot type it as a global


@pytest.fixture
def uncompilable_law(stage_law_registry):
    """A linear law numba cannot compile (it reads a Python dict), registered as ``uncompilable`` for the test: a
    declared Python stage, called back from the compiled call (contactdyn.laws.abi.python_stage_address)."""
    from contactdyn.laws.stage_laws import StageLaw

    class Uncompilable(StageLaw):
        name = "uncompilable"

        @staticmethod
        def force(k, b, p, x, xdot):
            return _SCALE["k"] * k * x + b * xdot

    return stage_law_registry(Uncompilable)


@pytest.fixture
def uncompilable_controller():
    """A controller numba cannot compile (τ = 0 times a Python dict's gain), registered as ``uncompilable_ctl`` for
    the test: the pipeline declines its modes (they run on the readable model, the reason named)."""
    from contactdyn.laws.controllers.base import CONTROLLERS, Controller, register
    from contactdyn.laws.params import Param

    class UncompilableController(Controller):
        name = "uncompilable_ctl"
        params = (Param("gain", "1", "a gain", 1.0),)
        reads_orientation = False

        def command(self, inp):
            return _SCALE["k"] * self.config.gain * 0.0 * inp.q, None

    register(UncompilableController)
    yield UncompilableController
    CONTROLLERS.pop(UncompilableController.name, None)
