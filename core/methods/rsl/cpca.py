# SPDX-License-Identifier: GPL-3.0-or-later
"""Clustered PCA (Sloan et al. 2003) of per-point vectors within an error budget: how RSL
stores its visibility distance tables (Xu et al. 2006, §5.1)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass
class ClusteredPCA:
    """``x_p ~= means[labels[p]] + coeffs[p] @ bases[labels[p]]`` (CPCA, Sloan 2003)."""

    labels: np.ndarray        # (P,) int
    means: np.ndarray         # (C, D) float32
    bases: np.ndarray         # (C, E, D) float32, orthonormal rows
    coeffs: np.ndarray        # (P, E) float32

    def reconstruct(self, start: int = 0, stop: int | None = None, dtype=np.float64,
                    chunk: int = 8192) -> np.ndarray:
        """Vectors ``start:stop`` as ``dtype``: per cluster, the mean plus one matrix
        product of the coefficients with the cluster's bases (no per-point copy of them)."""
        lab = self.labels[start:stop]
        coeffs = self.coeffs[start:stop]
        out = np.empty((len(lab), self.means.shape[1]), dtype)
        order = np.argsort(lab, kind="stable")
        clusters, first = np.unique(lab[order], return_index=True)
        ends = np.append(first[1:], len(lab))
        for c, a, e in zip(clusters, first, ends):
            for b in range(a, e, chunk):
                rows = order[b:min(e, b + chunk)]
                out[rows] = self.means[c] + coeffs[rows] @ self.bases[c]
        return out

    @property
    def stored_floats(self) -> int:
        C, E, D = self.bases.shape
        return C * (E + 1) * D + len(self.labels) * (E + 1)


def _top_components(X: np.ndarray, count: int, rng) -> np.ndarray:
    """(count, D) leading right singular vectors of X (randomized range finder, 2 power
    iterations; exact when count >= rank)."""
    n, d = X.shape
    k = min(count, n, d)
    if k == 0:
        return np.zeros((0, d), np.float32)
    if min(n, d) <= count + 8:
        _, _, vt = np.linalg.svd(X, full_matrices=False)
        return vt[:k]
    omega = rng.standard_normal((d, k + 8)).astype(X.dtype)
    Y = X @ omega
    for _ in range(2):
        Y, _ = np.linalg.qr(Y)
        Y = X @ (X.T @ Y)
    Q, _ = np.linalg.qr(Y)
    _, _, vt = np.linalg.svd(Q.T @ X, full_matrices=False)
    return vt[:k]


def clustered_pca(vectors: np.ndarray, clusters: int, eigen: int, iterations: int = 8,
                  seed: int = 0) -> ClusteredPCA:
    """Cluster with k-means (in a global 32-D PCA space), then a PCA basis of ``eigen``
    vectors per cluster (rows sorted by decreasing variance, so the first ``e`` rows
    are the best ``e``-vector basis)."""
    X = np.asarray(vectors, dtype=np.float32)
    P, D = X.shape
    C = max(1, min(int(clusters), P))
    E = max(0, min(int(eigen), D))
    rng = np.random.default_rng(seed)
    labels = np.zeros(P, np.int64)
    if C > 1:
        mu = X.mean(0)
        sample = X[rng.choice(P, min(P, 4096), replace=False)] - mu
        red_basis = _top_components(sample, 32, rng)
        Z = (X - mu) @ red_basis.T
        centres = Z[rng.choice(P, C, replace=False)]
        for _ in range(iterations):
            d2 = (Z * Z).sum(1)[:, None] - 2 * Z @ centres.T + (centres * centres).sum(1)[None]
            labels = np.argmin(d2, axis=1)
            for c in range(C):
                m = labels == c
                centres[c] = Z[m].mean(0) if m.any() else Z[rng.integers(P)]
    means = np.zeros((C, D), np.float32)
    bases = np.zeros((C, E, D), np.float32)
    coeffs = np.zeros((P, E), np.float32)
    order = np.argsort(labels, kind="stable")
    bounds = np.searchsorted(labels[order], np.arange(C + 1))
    for c in range(C):
        idx = order[bounds[c]:bounds[c + 1]]
        if len(idx) == 0:
            continue
        Xc = X[idx]
        means[c] = Xc.mean(0)
        Xc -= means[c]
        B = _top_components(Xc, E, rng)
        bases[c, :len(B)] = B
        coeffs[idx] = Xc @ bases[c].T
    return ClusteredPCA(labels, means, bases, coeffs)


def truncated(model: ClusteredPCA, eigen: int) -> ClusteredPCA:
    """The same clusters with only the first ``eigen`` basis vectors."""
    return ClusteredPCA(model.labels, model.means, model.bases[:, :eigen].copy(),
                        model.coeffs[:, :eigen].copy())


def _spread(X: np.ndarray, chunk: int = 4096) -> float:
    """``sum |x - mean|²`` over the rows (float64), or ``sum |x|²`` when the rows are
    all equal: the scale of :func:`relative_error` and :func:`compress_by_budget`.

    Measured about the mean, a constant part of the vectors does not loosen the
    budget: the VDT of an unoccluded point is the constant "no boundary" value, and
    against the plain norm those would let the budget spend its whole error on the
    points with shadow boundaries."""
    mu = sum(np.asarray(X[a:a + chunk], np.float64).sum(0)
             for a in range(0, len(X), chunk)) / max(len(X), 1)
    spread = total = 0.0
    for a in range(0, len(X), chunk):
        x = np.asarray(X[a:a + chunk], np.float64)
        spread += float(((x - mu) ** 2).sum())
        total += float((x * x).sum())
    return spread if spread > 1e-12 * total else total


def _residual_energy(X: np.ndarray, model: ClusteredPCA, chunk: int = 4096) -> float:
    """``sum |x - reconstruction|²`` over the rows, in float64 from the model's float32
    parameters, cluster by cluster: the residual itself, never a difference of two
    large energies (that cancels to rounding noise when the residual is small)."""
    order = np.argsort(model.labels, kind="stable")
    bounds = np.searchsorted(model.labels[order], np.arange(len(model.means) + 1))
    energy = 0.0
    for c in range(len(model.means)):
        mean = model.means[c].astype(np.float64)
        basis = model.bases[c].astype(np.float64)
        for a in range(bounds[c], bounds[c + 1], chunk):
            idx = order[a:min(a + chunk, bounds[c + 1])]
            r = np.asarray(X[idx], np.float64) - mean
            r -= model.coeffs[idx].astype(np.float64) @ basis
            energy += float(np.einsum("pd,pd->", r, r))
    return energy


def _relative_error(X: np.ndarray, model: ClusteredPCA, spread: float, chunk: int = 4096) -> float:
    """:func:`relative_error` with the spread (:func:`_spread`) given."""
    return float(np.sqrt(_residual_energy(X, model, chunk) / max(spread, 1e-300)))


def relative_error(vectors: np.ndarray, model: ClusteredPCA, chunk: int = 4096) -> float:
    """RMS reconstruction error relative to the vectors' RMS spread about their mean."""
    return _relative_error(vectors, model, _spread(vectors, chunk), chunk)


#: cluster counts and eigenvector counts tried by :func:`compress_by_budget`
CPCA_CLUSTERS = (1, 4, 16, 64, 256)
CPCA_EIGEN = (4, 8, 16, 32)


def compress_by_budget(vectors: np.ndarray, budget: float, seed: int = 0):
    """The cheapest (clusters, eigenvectors) pair -- fewest stored floats -- whose
    relative RMS error (:func:`relative_error`: against the spread about the mean
    vector) is within ``budget``; pairs that would not compress at least
    2:1 or leave fewer than 16 vectors per cluster are skipped, and when none meets
    the budget the most accurate one tried is kept.  One clustering per cluster
    count, truncated for smaller eigenvector counts.  Returns ``(model, error,
    compression ratio)``; the ratio counts stored floats (§5.1)."""
    X = np.asarray(vectors, np.float32)
    P, D = X.shape
    pairs = sorted(((C * (E + 1) * D + P * (E + 1), C, E) for C in CPCA_CLUSTERS
                    for E in CPCA_EIGEN if C * 16 <= max(P, 16) and E < D),
                   key=lambda t: t[0])
    pairs = [p for p in pairs if 2 * p[0] <= X.size] or pairs[:1]
    fulls, best = {}, None
    spread = _spread(X)
    for _, C, E in pairs:
        if C not in fulls:
            fulls[C] = clustered_pca(X, C, max(e for _, c, e in pairs if c == C), seed=seed)
        model = truncated(fulls[C], E)
        err = _relative_error(X, model, spread)
        if best is None or err < best[1] or err <= budget:
            best = (model, err)
        if err <= budget:
            break
    model, err = best
    return model, err, X.size / model.stored_floats
