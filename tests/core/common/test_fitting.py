"""core.common.fitting: the non-negative least-squares solver against brute force."""

import itertools

import numpy as np
import pytest

from prt_relight.core.common.fitting import nonnegative_least_squares


def _brute_force_nnls(A, b):
    """Best feasible unconstrained solution over every subset of columns (the NNLS
    optimum is the unconstrained optimum on its support)."""
    n = A.shape[1]
    best, best_x = np.inf, np.zeros(n)
    for k in range(n + 1):
        for cols in itertools.combinations(range(n), k):
            x = np.zeros(n)
            if cols:
                x[list(cols)] = np.linalg.lstsq(A[:, cols], b, rcond=None)[0]
            if np.any(x < 0):
                continue
            r = float(np.sum((A @ x - b) ** 2))
            if r < best - 1e-12:
                best, best_x = r, x
    return best_x, best


@pytest.mark.parametrize("seed", range(12))
def test_nnls_equals_brute_force(seed):
    rng = np.random.default_rng(seed)
    m, n = int(rng.integers(4, 40)), int(rng.integers(1, 8))
    A = rng.normal(size=(m, n))
    if seed % 3 == 0:                      # correlated columns, like overlapping SG lobes
        A = np.abs(A) + 2.0
    b = rng.normal(size=m) * 3.0
    x = nonnegative_least_squares(A, b)
    xb, rb = _brute_force_nnls(A, b)
    assert np.all(x >= 0)
    assert float(np.sum((A @ x - b) ** 2)) == pytest.approx(rb, rel=1e-9, abs=1e-12)
    # KKT: gradient zero on the support, pointing inward off it
    g = A.T @ (b - A @ x)
    assert np.all(np.abs(g[x > 0]) <= 1e-8 * max(1.0, np.abs(A.T @ b).max()))
    assert np.all(g[x == 0] <= 1e-8 * max(1.0, np.abs(A.T @ b).max()))


def test_nnls_degenerate_inputs():
    assert nonnegative_least_squares(np.zeros((5, 0)), np.ones(5)).shape == (0,)
    assert np.all(nonnegative_least_squares(np.ones((5, 3)), np.zeros(5)) == 0)
    assert np.all(nonnegative_least_squares(np.ones((5, 3)), -np.ones(5)) == 0)
    # duplicate columns: a solution with the right fit, finite and non-negative
    A = np.ones((6, 2))
    x = nonnegative_least_squares(A, np.full(6, 2.0))
    assert np.all(np.isfinite(x)) and np.all(x >= 0) and x.sum() == pytest.approx(2.0)
