"""Small dense solves (and the reduced SVD) without numpy's Python wrappers.

``numpy.linalg.solve``, ``det`` and ``svd`` check their arguments in Python before calling their
gufuncs; on the 2–12-row systems of a right-hand side call that check costs more than the solve
(~3 µs of ~1 µs). The gufuncs themselves are used here where numpy has them (private but stable
since numpy 1.8), the public functions otherwise. Arguments must be float arrays of matching
shapes; a singular matrix gives inf/nan, and a matrix with nan an SVD of nan (with a
RuntimeWarning), where the fallback raises LinAlgError; callers test.
"""

from __future__ import annotations

import numpy as np

__all__ = ["solve_vector", "solve_matrix", "det", "svd"]

try:
    from numpy.linalg import _umath_linalg

    solve_vector = _umath_linalg.solve1  #: A z = b for a vector b
    solve_matrix = _umath_linalg.solve  #: A Z = B for a matrix B
    det = _umath_linalg.det
    svd = _umath_linalg.svd_s  #: (u, s, vᵀ) = the reduced SVD (numpy.linalg.svd's full_matrices=False)
except (ImportError, AttributeError):  # pragma: no cover
    solve_vector = solve_matrix = np.linalg.solve
    det = np.linalg.det

    def svd(a):
        return np.linalg.svd(a, full_matrices=False)
