"""A compiled function called by its address (numerics.native_call): the same result and errors as a direct call."""

import numba
import numpy as np
import pytest
from numba import types

from contactdyn.numerics.native_call import address, call_at, declare


@numba.njit
def _scaled(a, k):
    """(k a, Σ a) [-]; a ValueError for k < 0 (an exception must cross the address call)."""
    if k < 0:
        raise ValueError("k must be >= 0")
    return a * k, a.sum()


declare("test.scaled", _scaled, types.Tuple((types.float64[::1], types.float64))(types.float64[::1], types.int64))


@numba.njit
def _by_address(at, a, k):
    return call_at(at, "test.scaled", (a, k))


@numba.njit
def _wrong_types(at, a):
    return call_at(at, "test.scaled", (a, 1.5))


def test_a_call_by_address_returns_what_the_direct_call_returns():
    a = np.array([1.0, 2.0, 4.0])
    got, total = _by_address(address("test.scaled"), a, 3)
    want, want_total = _scaled(a, 3)
    assert np.array_equal(got, want) and total == want_total == 7.0


def test_an_exception_crosses_the_address_call():
    with pytest.raises(ValueError, match="k must be >= 0"):
        _by_address(address("test.scaled"), np.ones(2), -1)


def test_arguments_other_than_the_declared_signature_are_a_typing_error_naming_both():
    with pytest.raises(numba.core.errors.TypingError, match=r"call_at 'test.scaled'.*float64.*int64"):
        _wrong_types(address("test.scaled"), np.ones(2))
