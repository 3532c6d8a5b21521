"""The compiled Horner loops of DOP853's dense output (contactdyn.numerics.dense_output) and its batched interpolants:
NumPy's numbers bit for bit."""

import numpy as np
from scipy.integrate._ivp import dop853_coefficients as coef

from contactdyn.numerics.dense_output import coefficients, horner_at, horner_rows, stage_states
from contactdyn.numerics.dop853 import dense_states, solve


def numpy_horner(F, s):
    """y − y_old of interpolants F (..., rows, n) at step fractions s: the NumPy arithmetic the kernels replace."""
    y = np.zeros(F.shape[:-2] + F.shape[-1:])
    for k, row in enumerate(range(F.shape[-2] - 1, -1, -1)):
        y += F[..., row, :]
        y *= s if k % 2 == 0 else 1.0 - s
    return y


def same_bits(a, b):
    return a.shape == b.shape and np.array_equal(a.view(np.int64), b.view(np.int64))


def test_horner_kernels_are_numpys_bit_for_bit():
    rng = np.random.default_rng(3)
    for _ in range(500):
        n, m = int(rng.integers(1, 30)), int(rng.integers(1, 6))
        C = rng.standard_normal((m, 7, n)) * 10.0 ** rng.integers(-12, 6, size=(m, 7, n))
        Y0 = rng.standard_normal((m, n)) * 10.0 ** rng.integers(-5, 3)
        s = rng.random(9)
        which = rng.integers(0, m, size=9)
        assert same_bits(horner_at(C[0], float(s[0]), Y0[0]), numpy_horner(C[0], float(s[0])) + Y0[0])
        want = numpy_horner(C[which], s[:, None]) + Y0[which]
        assert same_bits(horner_rows(C, which, s, Y0), want)


def test_interpolant_arithmetic_is_numpys_bit_for_bit():
    """The compiled stage states and coefficients are the NumPy forms they replace (einsum over the stages, then
    scipy's Dop853DenseOutput rows), bit for bit, on stages of mixed magnitudes. (From n = 2 states, as every run has:
    for one state einsum sums its contiguous axis in another order.)"""
    rng = np.random.default_rng(7)
    A, D = coef.A, np.ascontiguousarray(coef.D)
    for _ in range(400):
        m, n = int(rng.integers(1, 6)), int(rng.integers(2, 40))
        K = rng.standard_normal((m, 16, n)) * 10.0 ** rng.integers(-8, 8, size=(m, 16, 1))
        Y0, y_new = rng.standard_normal((m, n)), rng.standard_normal((m, n))
        h = rng.random(m) * 10.0 ** rng.integers(-6, 0)
        for s in (13, 14, 15):
            want = Y0 + h[:, None] * np.einsum("msn,s->mn", K[:, :s], A[s, :s])
            assert same_bits(stage_states(K, s, A, Y0, h), want)
        dy = y_new - Y0
        want = np.concatenate([dy[:, None], (h[:, None] * K[:, 0] - dy)[:, None],
                               (2.0 * dy - h[:, None] * (K[:, 12] + K[:, 0]))[:, None],
                               h[:, None, None] * np.einsum("ds,msn->mdn", D, K)], axis=1)
        assert same_bits(coefficients(K, Y0, y_new, h, D, 12), want)


def oscillator(t, y):
    return np.array([y[1], -y[0] - 0.1 * y[1]])


def test_one_batch_for_several_runs_gives_each_runs_own_states():
    """The interpolants of two runs built in one batch: the states each run's dense output gives alone."""
    runs = [solve(oscillator, (0.0, 5.0), y0, rtol=1e-8, atol=1e-10) for y0 in ([1.0, 0.0], [0.3, -2.0])]
    alone = [solve(oscillator, (0.0, 5.0), y0, rtol=1e-8, atol=1e-10) for y0 in ([1.0, 0.0], [0.3, -2.0])]
    tt = np.linspace(0.0, 5.0, 37)
    together = dense_states([(run.sol, tt) for run in runs])
    for got, run in zip(together, alone, strict=True):
        assert same_bits(got, np.ascontiguousarray(run.sol(tt).T))
        assert same_bits(got[5], run.sol(float(tt[5])))
    assert [run.sol.late_calls for run in runs] == [run.sol.late_calls for run in alone]


def test_one_time_gives_the_array_calls_numbers():
    """DenseSolution.state (one time, no arrays) and the array call: the same step, the same bits, at step ends too."""
    run = solve(oscillator, (0.0, 5.0), [1.0, 0.0], rtol=1e-8, atol=1e-10)
    alone = solve(oscillator, (0.0, 5.0), [1.0, 0.0], rtol=1e-8, atol=1e-10)
    tt = np.concatenate([run.t, np.linspace(0.0, 5.0, 23)])
    for t in tt:
        assert same_bits(run.sol(float(t)), np.ascontiguousarray(alone.sol(np.array([t]))[:, 0]))
