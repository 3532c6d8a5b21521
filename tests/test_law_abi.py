"""Laws called by address (contactdyn.laws.abi): each law through its compiled C function equals its Python
function; a law numba cannot compile is declared."""

from __future__ import annotations

import sys
from pathlib import Path

import numba
import numpy as np
import pytest

from contactdyn.laws import abi
from contactdyn.laws.friction_laws import FRICTION_LAWS, Coulomb, FrictionLaw, FrictionSpec, Stribeck
from contactdyn.laws.stage_laws import STAGE_LAWS, HuntCrossley, Linear, StageLaw, register_stage_law

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT / "examples"))
from cubic_stage import Cubic  # noqa: E402

K, B = 1e5, 300.0  #: [N/m], [N·s/m]
XS = np.concatenate([-np.logspace(-6, -2, 7), [0.0], np.logspace(-7, -2, 11)])  #: compressions [m]
XDS = np.array([-1.0, -0.1, -1e-3, 0.0, 1e-3, 0.1, 1.0])  #: rates [m/s]
SPEEDS = np.concatenate([[0.0], np.logspace(-6, 1, 29)])  #: slip speeds [m/s]


@numba.njit(cache=True)
def _stage_grid(address, k, b, p, xs, xds, out):
    for i in range(xs.size):
        for j in range(xds.size):
            out[i, j] = abi.call_stage(address, k, b, p, 0, p.size, xs[i], xds[j])


@numba.njit(cache=True)
def _friction_grid(address, mu_s, mu_k, p, speeds, out):
    for i in range(speeds.size):
        out[i] = abi.call_friction(address, mu_s, mu_k, p, 0, p.size, speeds[i])


def _close(got: np.ndarray, want: np.ndarray, scale: np.ndarray | None = None) -> None:
    """|got − want| ≤ 1e-15 · scale (default |want|). A stage force's scale is the size of its terms,
    k|x| + b|ẋ| + |F|: numba forms x**3 as x·x·x where Python calls pow(), an ulp apart, which a sum of
    cancelling terms shows as more than 1e-15 of F."""
    scale = np.abs(want) if scale is None else scale
    assert np.all(np.abs(got - want) <= 1e-15 * scale), np.max(np.abs(got - want) / scale)


@pytest.mark.parametrize("law, p", [(Linear, ()), (HuntCrossley, (1.5,)), (HuntCrossley, (2.3,)), (Cubic, (1e9,))])
def test_a_stage_law_through_its_address_equals_its_python_function(law, p):
    address = abi.stage_address(law)
    assert address != 0 and law.compiled_reason == ""
    params = np.array(p, dtype=float)
    got = np.empty((XS.size, XDS.size))
    _stage_grid(address, K, B, params, XS, XDS, got)
    want = np.array([[law.force(K, B, p, x, xd) for xd in XDS] for x in XS])
    scale = K * np.abs(XS)[:, None] + B * np.abs(XDS)[None, :] + np.abs(want)
    _close(got, want, scale)
    if law is not Cubic:  # no integer power: the same operations, bit for bit
        np.testing.assert_array_equal(got, want)
    twin = np.array([[abi.call_stage(address, K, B, params, 0, len(p), x, xd) for xd in XDS] for x in XS])
    np.testing.assert_array_equal(twin, want)  # the plain-Python twin calls the law's own function


@pytest.mark.parametrize("law, p", [(Coulomb, ()), (Stribeck, (0.01,)), (Stribeck, (1e-9,))])
def test_a_friction_law_through_its_address_equals_its_kinetic_coefficient(law, p):
    address = abi.friction_address(law)
    assert address != 0 and law.compiled_reason == ""
    spec = FrictionSpec(0.6, 0.4, 0.0, law.name, p)
    got = np.empty(SPEEDS.size)
    _friction_grid(address, spec.mu_s, spec.mu_k, np.array(p, dtype=float), SPEEDS, got)
    _close(got, np.array([float(spec.mu(v)) for v in SPEEDS]))
    _close(got, spec.mu(SPEEDS))  # the law's Python function on an array of speeds, as the samples call it


def test_a_friction_law_given_by_kinetic_only_is_declared_python():
    class Old(FrictionLaw):
        name = "old_style"

        @staticmethod
        def kinetic(spec, speed):
            return spec.mu_k + 0.0 * speed

    assert abi.friction_address(Old) == 0
    assert "kinetic(spec, speed) only" in Old.compiled_reason


_SCALE = {"k": 1.0}  #: a Python dict: numba cannot type it as a global


@pytest.fixture
def uncompilable_law():
    """A linear law numba cannot compile (it reads a Python dict), registered as ``uncompilable``."""

    class Uncompilable(StageLaw):
        name = "uncompilable"

        @staticmethod
        def force(k, b, p, x, xdot):
            return _SCALE["k"] * k * x + b * xdot

    register_stage_law(Uncompilable)
    yield Uncompilable
    STAGE_LAWS.pop(Uncompilable.name, None)


def test_a_law_numba_cannot_compile_is_declared(uncompilable_law):
    assert abi.stage_address(uncompilable_law) == 0
    assert uncompilable_law.compiled_reason.startswith("numba cannot compile")
    assert "_SCALE" in uncompilable_law.compiled_reason


def test_registered_laws_compile():
    for law in STAGE_LAWS.values():
        assert abi.stage_address(law) != 0, law.compiled_reason
    for law in FRICTION_LAWS.values():
        assert abi.friction_address(law) != 0, law.compiled_reason
