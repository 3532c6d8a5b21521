"""The compiled call's small linear algebra (contactdyn.numerics.linalg) against numpy and scipy, and the dynamic laws'
stacked pseudo-inverse (laws.controllers.dynamic.pseudo_inverse) against the per-sample one."""

import math

import numba
import numpy as np
import pytest

from contactdyn.numerics.linalg import cholesky, cross3, dot3, fma, forward_solve, lu_solve, mtv, mv, pinv, put


@numba.njit
def _put_twice(dst, src):
    put(dst, 0, src)  # (a literal at)
    put(dst, 3, src[1:])  # (a non-contiguous source: every other element)
    return dst


def test_put_stores_in_place_and_is_not_compiled_again_for_a_literal():
    """put(dst, at, src) is dst[at:at + src.size] = src; the literal 0 and a strided source use its two signatures."""
    src = np.array([1.0, 2.0, 3.0, 4.0, 5.0])
    got = _put_twice(np.zeros(6), src[::2])
    assert np.array_equal(got, [1.0, 3.0, 5.0, 3.0, 5.0, 0.0])
    assert not any(isinstance(a, numba.types.Literal) for sig in put.signatures for a in sig)


def test_mtv_is_mv_of_the_transpose_bit_for_bit():
    A, x = np.random.default_rng(5).normal(size=(4, 3)), np.random.default_rng(6).normal(size=4)
    assert np.array_equal(mtv(A, x), mv(np.ascontiguousarray(A.T), x))


@pytest.mark.parametrize("nv", [1, 2, 3, 5, 7])
def test_pinv_is_numpys_pinv_with_its_rcond(nv):
    """J⁺ of tip Jacobians (3, nv): full rank, a repeated column, a zero row, all zero; against numpy's SVD pinv."""
    rng = np.random.default_rng(nv)
    for k in range(60):
        J = rng.normal(size=(3, nv)) * 10.0 ** rng.uniform(-3, 3)
        if k % 3 == 1 and nv > 1:
            J[:, 1] = 2.0 * J[:, 0]
        if k % 4 == 2:
            J[2] = 0.0
        if k == 59:
            J[:] = 0.0
        ref = np.linalg.pinv(J, rcond=1e-10)
        assert np.allclose(pinv(J), ref, rtol=1e-12, atol=1e-12 * (1.0 + np.abs(ref).max()))


def test_pinv_near_a_singular_pose_keeps_the_small_singular_value():
    """σ₂/σ₁ = 1e-8 (above the 1e-10 cut): J⁺ has the 1e8 entries numpy's has, to 1e-7 relative."""
    u, _ = np.linalg.qr(np.random.default_rng(3).normal(size=(3, 3)))
    v, _ = np.linalg.qr(np.random.default_rng(4).normal(size=(2, 2)))
    J = u[:, :2] @ np.diag([1.0, 1e-8]) @ v.T
    ref = np.linalg.pinv(J, rcond=1e-10)
    assert np.abs(ref).max() > 1e7
    assert np.allclose(pinv(J), ref, rtol=1e-7, atol=0.0)


def test_lu_solve_is_a_solve_and_nan_when_singular():
    rng = np.random.default_rng(5)
    for n in (1, 3, 7, 12):
        A, b = rng.normal(size=(n, n)), rng.normal(size=n)
        assert np.allclose(A @ lu_solve(A, b), b, rtol=0.0, atol=1e-11 * np.abs(A).max() * (1 + np.abs(b).max()))
    assert np.all(np.isnan(lu_solve(np.array([[1.0, 2.0], [2.0, 4.0]]), np.ones(2))))


def test_cholesky_and_forward_solve():
    """L Lᵀ = A and L Y = B to round-off, nan for an indefinite A."""
    rng = np.random.default_rng(6)
    for n in (1, 4, 7):
        B = rng.normal(size=(n, n))
        A = B @ B.T + 0.1 * np.eye(n)
        L = cholesky(A)
        assert np.allclose(np.tril(L), L) and np.allclose(L @ L.T, A, rtol=0, atol=1e-13 * np.abs(A).max())
        R = rng.normal(size=(n, 3))
        assert np.allclose(L @ forward_solve(L, R), R, rtol=0, atol=1e-12 * (1 + np.abs(R).max()))
    assert np.all(np.isnan(cholesky(np.array([[1.0, 2.0], [2.0, 1.0]]))))


def test_stacked_pseudo_inverse_is_each_sample_s():
    """J⁺ over a stack equals each sample's J⁺ bitwise, and numpy's pinv (rcond 1e-10) to round-off, full rank or
    not (a zero sample: J⁺ = 0)."""
    from contactdyn.laws.controllers.dynamic import pseudo_inverse

    rng = np.random.default_rng(5)
    J = rng.normal(size=(40, 3, 5))
    for stack in (J, np.concatenate((J, np.zeros((1, 3, 5))))):
        want = np.array([pseudo_inverse(j) for j in stack])
        got = pseudo_inverse(stack)
        assert np.array_equal(got, want)
        assert np.allclose(got, np.linalg.pinv(stack, rcond=1e-10), rtol=0, atol=1e-12)


@numba.njit
def _compiled_products(a, b):
    return dot3(a, b), cross3(a, b)


@numba.njit
def _compiled_fma(a, b, c):
    """llvm.fma(a, b, c) as dot3 forms its last term: fma(a₂b₂, fma(a₁b₁, a₀b₀)) with a₀b₀ = c, a₁b₁ = 0."""
    return dot3(np.array([c, 0.0, a]), np.array([1.0, 0.0, b]))


def test_dot3_and_cross3_are_the_same_numbers_in_python_and_compiled():
    """An interpreted run's numbers are the compiled run's on every machine: dot3 forms a₀b₀ then one fused
    multiply-add per term in both (numpy's ``a @ b`` would leave it to the machine's BLAS kernel), cross3 the same
    products and differences. Random vectors and near-cancelling ones (a·b ≈ 0, where a rounding shows)."""
    rng = np.random.default_rng(3)
    for k in range(2000):
        a, b = rng.normal(size=3) * 10.0 ** rng.integers(-8, 8), rng.normal(size=3)
        if k % 2:  # b nearly orthogonal to a
            b = np.cross(a, rng.normal(size=3)) + 1e-12 * rng.normal(size=3)
        d, c = _compiled_products(a, b)
        assert dot3(a, b) == d, (a.tolist(), b.tolist())
        assert np.array_equal(cross3(a, b), c)


def test_fma_rounds_once():
    """fma(a, b, c) is a b + c rounded once: 0.1 · 10 − 1 is 2⁻⁵⁴ fused (the product's rounding error), 0 unfused;
    and it equals the compiled llvm.fma on random and cancelling triples."""
    assert fma(0.1, 10.0, -1.0) == 2.0 ** -54 and 0.1 * 10.0 - 1.0 == 0.0
    assert fma(2.0, 3.0, 1.0) == 7.0 and fma(-0.0, 1.0, -0.0) == 0.0 and math.copysign(1.0, fma(-0.0, 1.0, -0.0)) < 0
    assert math.isnan(fma(math.inf, 0.0, 1.0)) and fma(1e308, 10.0, 0.0) == math.inf
    rng = np.random.default_rng(4)
    for k in range(4000):  # (the last quarter at magnitudes where fma leaves Dekker's product for rationals)
        scale = 10.0 ** rng.integers(-150, 150, size=2) if k < 3000 else 10.0 ** rng.choice([-300, -200, 200, 300], 2)
        a, b = rng.normal(size=2) * scale
        c = rng.normal() * 10.0 ** rng.integers(-20, 20)
        if rng.random() < 0.5:  # c cancels a b to ~1e-15: the product's rounding error decides
            c = -a * b * (1.0 + 1e-15 * rng.normal())
        a, b, c = float(a), float(b), float(c)
        assert fma(a, b, c) == _compiled_fma(a, b, c), (a, b, c)


def _kkt(rng, redundant: float | None):
    """A KKT matrix [[M, −Gᵀ], [G, 0]] (M 3×3 positive definite) with two rows: the second ``redundant`` × the first
    (two holds of the same motion), or independent (None); and a consistent right-hand side."""
    Mh = rng.normal(size=(3, 3))
    g = rng.normal(size=3)
    G = np.vstack([g, redundant * g if redundant is not None else rng.normal(size=3)])
    A = np.block([[Mh @ Mh.T + 3.0 * np.eye(3), -G.T], [G, np.zeros((2, 2))]])
    return A, A @ rng.normal(size=5)


def test_a_kkt_matrix_singular_to_rounding_is_solved_by_least_squares_every_time():
    """Two holds of the same motion (rows g and c g): LU's pivot is rounding (~1e-16 of the largest entry), and its
    answer passed the residual test on 63 % of such systems with an arbitrary split of the force (λ = (9.2, −3.9)
    where the least-norm split is (−0.07, −0.18)), flipping between calls as the rounding did. Now every one is
    LEAST_SQUARES with the least-norm split λ₂/λ₁ = c, and a regular matrix keeps LU's answer bit for bit."""
    from contactdyn.model.pipeline.kkt import LEAST_SQUARES, REGULAR, solve_linear

    rng = np.random.default_rng(1)
    for _ in range(200):
        c = rng.uniform(0.3, 3.0)
        A, b = _kkt(rng, c)
        z, outcome = solve_linear(A, b)
        assert outcome == LEAST_SQUARES
        np.testing.assert_allclose(z, np.linalg.lstsq(A, b, rcond=1e-12)[0], rtol=1e-9, atol=1e-12)
        assert z[4] / z[3] == pytest.approx(c, rel=1e-9)
        A, b = _kkt(rng, None)
        z, outcome = solve_linear(A, b)
        assert outcome == REGULAR and np.array_equal(z, lu_solve(A, b))
