"""core.methods.rsl.cpca (Sloan et al. 2003, as Xu et al. 2006 §5.1 stores the VDTs):
clustered PCA is exact at full rank, meets its error budget, and the budget ignores a
constant offset.  No bpy."""

from __future__ import annotations

import numpy as np
import pytest

from prt_relight.core.methods.rsl import cpca


def test_clustered_pca_is_exact_with_full_rank_and_meets_its_budget():
    rng = np.random.default_rng(5)
    groups = [rng.normal(size=(1, 64)) + 0.1 * rng.normal(size=(40, 3)) @ rng.normal(size=(3, 64))
              for _ in range(4)]
    X = np.concatenate(groups).astype(np.float32)
    exact = cpca.clustered_pca(X, 4, 3)
    assert cpca.relative_error(X, exact) < 1e-5
    model, err, ratio = cpca.compress_by_budget(X, 0.05)
    # the reported error is relative_error's figure (the float32 model's residual is ~1e-7)
    assert err < 1e-5 and err == pytest.approx(cpca.relative_error(X, model), rel=1e-3, abs=1e-9)
    assert ratio > 1.0
    np.testing.assert_allclose(model.reconstruct(), X, atol=0.2 * np.abs(X).max())
    # by rows and in half floats: the same vectors, each row from its own cluster
    rows = model.reconstruct(37, 121, dtype=np.float16, chunk=16)
    assert rows.dtype == np.float16
    want = np.stack([model.means[c] + model.coeffs[p] @ model.bases[c]
                     for p, c in zip(range(37, 121), model.labels[37:121])])
    np.testing.assert_allclose(rows, want, atol=2e-3 * np.abs(want).max())


def test_cpca_budget_ignores_a_constant_offset():
    """The budget is relative to the spread about the mean: adding the same vector to
    every row (e.g. the constant VDT of unoccluded points) must not loosen it."""
    rng = np.random.default_rng(12)
    groups = [rng.normal(size=(1, 64)) + 0.3 * rng.normal(size=(200, 6)) @ rng.normal(size=(6, 64))
              for _ in range(8)]
    X = np.concatenate(groups)
    X = (X + 0.03 * X.std() * rng.normal(size=X.shape)).astype(np.float32)
    base, err, _ = cpca.compress_by_budget(X, 0.05)
    shifted, err_s, _ = cpca.compress_by_budget(X + 50.0, 0.05)
    assert shifted.bases.shape == base.bases.shape
    assert err_s <= 0.05 and err_s == pytest.approx(err, abs=1e-3)
    assert cpca.relative_error(X + 50.0, shifted) == pytest.approx(err_s, rel=1e-3, abs=1e-9)
