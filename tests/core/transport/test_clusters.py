"""core.transport.clusters: patches grouped by cell and facing, samples per half-cell."""

import numpy as np

from prt_relight.core.scene import mesh
from prt_relight.core.transport import clusters, transfer

from .scenes import floor_and_wall


def test_two_sides_and_two_facings_never_share_a_cluster():
    objs = [mesh.with_back_sides(o) for o in floor_and_wall(8)]
    p = transfer.Patches.of_meshes(objs)
    cluster_of, k, _ = clusters.cluster_patches(p.centroids, p.normals, p.areas, 16)
    bucket = clusters.normal_bucket(p.normals)
    for c in range(k):
        assert len(set(bucket[cluster_of == c].tolist())) == 1
    # about the target count: 4 sides of 8 m^2 in 16 cells of 0.5 m^2 each
    assert 16 <= k <= 64


def test_sample_weights_are_area_shares_summing_to_one():
    p = transfer.Patches.of_meshes(floor_and_wall(8))
    cluster_of, k, cell = clusters.cluster_patches(p.centroids, p.normals, p.areas, 8)
    patch, owner, weight = clusters.sample_sets(cluster_of, p.centroids, p.areas, k, cell)
    np.testing.assert_allclose(np.bincount(owner, weights=weight, minlength=k), 1.0)
    assert np.all(cluster_of[patch] == owner)
    # a flat cluster is sampled in its half-cells: more than one sample where it is big
    assert np.bincount(owner, minlength=k).max() >= 4


def test_cluster_means_are_area_weighted():
    c = np.array([0, 0, 1])
    v = np.array([[1.0], [3.0], [5.0]])
    a = np.array([1.0, 3.0, 2.0])
    np.testing.assert_allclose(clusters.cluster_means(c, v, a, 2), [[2.5], [5.0]])


def test_clusters_are_numbered_by_cell_then_facing():
    """One packed key per patch numbers the clusters as (cell x, y, z, facing) sorted."""
    rng = np.random.default_rng(2)
    c = rng.uniform(-3.0, 5.0, (2000, 3)).astype(np.float32)
    n = rng.normal(size=(2000, 3)).astype(np.float32)
    a = rng.uniform(0.01, 0.1, 2000).astype(np.float32)
    cluster_of, k, h = clusters.cluster_patches(c, n, a, 40)
    cell = np.floor((c - c.min(axis=0)) / h).astype(np.int64)
    key = np.column_stack([cell, clusters.normal_bucket(n)])
    _, expect = np.unique(key, axis=0, return_inverse=True)
    np.testing.assert_array_equal(cluster_of, expect.reshape(-1))
    assert k == len(np.unique(key, axis=0))
    # the samples of each half-cell, in cluster order
    patch, owner, _ = clusters.sample_sets(cluster_of, c, a, k, h)
    assert np.all(np.diff(owner) >= 0) and np.all(cluster_of[patch] == owner)
    half = np.floor((c - c.min(axis=0)) / (0.5 * h)).astype(np.int64)
    assert len(patch) == len(np.unique(np.column_stack([cluster_of, half]), axis=0))
