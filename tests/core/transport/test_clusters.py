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
