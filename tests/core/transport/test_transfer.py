"""core.transport.transfer: receiver rows from the traced rays, against brute-force
one-bounce quadrature (each ray's hit point lit exactly)."""

import numpy as np
import pytest

from prt_relight.core.methods.reference import shading as reference
from prt_relight.core.scene import mesh, visibility
from prt_relight.core.sphere.directions import cubemap
from prt_relight.core.sphere.envmap import CubeLighting
from prt_relight.core.transport import bounce, clusters, transfer

from .scenes import floor_and_wall

OFFSET = 3e-4
RHO = 0.8


def _sky(cube):
    """A sky three times brighter at the zenith than at the horizon (and below it)."""
    d = cube.directions
    return CubeLighting(((1.0 + 2.0 * np.maximum(d[:, 2], 0.0))[:, None]
                         * np.ones(3)).astype(np.float32), d.copy())


def _transfer(objs, cube, width=transfer.ROW_WIDTH, keep_sum=True):
    pts = [mesh.shading_points(o) for o in objs]
    P = np.concatenate([p.positions for p in pts])
    N = np.concatenate([p.normals for p in pts])
    scene = visibility.build_occluder_scene(
        np.concatenate([mesh.occluder_triangles(o)[0] for o in objs]))
    patches = transfer.Patches.of_meshes(objs)
    cluster_of, k, cell = clusters.cluster_patches(patches.centroids, patches.normals,
                                                   patches.areas, len(P) // 24)
    hits = transfer.HitMap.of_meshes(objs, patches, cluster_of)
    rows = transfer.TransferRows(len(P), k, hits, cube, width, keep_sum=keep_sum)
    bits = visibility.trace_visibility(
        scene, P, N, cube, OFFSET,
        hits=lambda a, b, blocked, prim: rows.add(a, b, N[a:b], blocked, prim))
    return P, N, bits, scene, patches, cluster_of, k, cell, hits, rows


def _brute(i, P, N, scene, hits, cube, sky):
    """One-bounce irradiance at receiver i: every hemisphere texel's ray, the hit point's
    exact irradiance (its own traced hemisphere) times RHO / pi, front sides only."""
    mask = visibility.hemisphere_mask(N[i:i + 1], cube)[0]
    dirs = cube.directions[mask]
    w = np.maximum(dirs @ N[i], 0.0) * cube.solid_angles[mask]
    o = np.repeat((P[i] + OFFSET * N[i])[None], len(dirs), 0).astype(np.float32)
    r = scene.run(o, dirs.astype(np.float32), query="INTERSECT", output=1)
    hit = r["primID"] >= 0
    if not hit.any():
        return np.zeros(3)
    hp = o[hit] + r["tfar"][hit][:, None] * dirs[hit]
    ng = hits.normal(r["primID"][hit])
    front = np.einsum("ij,ij->i", dirs[hit], ng) < 0.0
    hn = np.where(front[:, None], ng, -ng)
    E = reference.diffuse_irradiance(visibility.trace_visibility(scene, hp, hn, cube, OFFSET),
                                     hn, cube, sky)
    E[~front] = 0.0
    return (w[hit][:, None] * RHO / np.pi * E).sum(axis=0)


def test_one_bounce_matches_brute_force_quadrature():
    cube = cubemap(8)
    P, N, bits, scene, patches, cluster_of, k, cell, hits, rows = _transfer(
        floor_and_wall(16), cube)
    patch, owner, weight = clusters.sample_sets(cluster_of, patches.centroids,
                                                patches.areas, k, cell)
    scube = cubemap(16)
    sb = visibility.trace_visibility(scene, patches.centroids[patch], patches.normals[patch],
                                     scube, OFFSET)
    E = reference.diffuse_irradiance(sb, patches.normals[patch], scube, _sky(scube))
    direct = np.stack([np.bincount(owner, weights=weight * E[:, c], minlength=k)
                       for c in range(3)], axis=1)
    got = bounce.receive(rows.columns, rows.weights,
                         bounce.bounce(direct, np.full((k, 3), RHO), rows.columns[:k] * 0,
                                       rows.weights[:k] * 0, 1))
    idx = np.random.default_rng(1).choice(len(P), 60, replace=False)
    truth = np.array([_brute(i, P, N, scene, hits, cube, _sky(cube)) for i in idx])
    err = np.linalg.norm(got[idx] - truth) / np.linalg.norm(truth)
    assert err < 0.06, err                         # measured 2.6 % (cube 8, 16 cuts)
    assert got[idx].sum() / truth.sum() == pytest.approx(1.0, abs=0.05)


def test_rows_keep_the_share_of_the_hemisphere_that_sees_the_scene():
    """A row's sum is sum(cos dw) over the rays that hit a surface's traced side: a row
    cut to two entries keeps it, so with every cluster equally bright it bounces what the
    full row does; and it is at most the blocked share of the hemisphere."""
    cube = cubemap(8)
    P, N, bits, *_, full = _transfer(floor_and_wall(8), cube, width=10_000)
    *_, short = _transfer(floor_and_wall(8), cube, width=2)
    np.testing.assert_allclose(short.weights.sum(axis=1), full.weights.sum(axis=1),
                               rtol=1e-5, atol=1e-7)
    blocked = visibility.hemisphere_mask(N, cube) & ~visibility.unpack_visibility(
        bits, cube.size)
    limit = (np.maximum(N @ cube.directions.T, 0.0) * cube.solid_angles * blocked).sum(1)
    assert np.all(full.weights.sum(axis=1) <= limit + 1e-5)
    assert full.weights.sum() > 0.9 * limit.sum()       # hits behind a crease are few


def test_back_hits_read_the_back_side_or_nothing():
    """A ray reaching a one-sided surface from behind gathers nothing; with the surface's
    back side traced it gathers the back side's cluster, never the front's."""
    wall = floor_and_wall(4)[1]
    for arrays in (wall, mesh.with_back_sides(wall)):
        patches = transfer.Patches.of_meshes([arrays])
        cluster_of, k, _ = clusters.cluster_patches(patches.centroids, patches.normals,
                                                    patches.areas, 4)
        hits = transfer.HitMap.of_meshes([arrays], patches, cluster_of)
        # the wall faces -y: a receiver at +y sees its back
        rows = transfer.TransferRows(1, k, hits, cubemap(8))
        scene = visibility.build_occluder_scene(mesh.occluder_triangles(arrays)[0])
        p, n = np.array([[0.0, 2.0, 1.0]]), np.array([[0.0, -1.0, 0.0]])
        visibility.trace_visibility(scene, p, n, cubemap(8), OFFSET,
                                    hits=lambda a, b, blocked, prim: rows.add(
                                        a, b, n, blocked, prim))
        used = set(rows.columns[0][rows.weights[0] > 0].tolist())
        front = set(hits.front.tolist())
        if arrays.two_sided:
            assert used and used.isdisjoint(front) and used <= set(hits.back.tolist())
        else:
            assert not used


def test_sparse_and_dense_top_entries_agree():
    rng = np.random.default_rng(0)
    rows, cols = rng.integers(0, 5, 400), rng.integers(0, 30, 400)
    w = rng.random(400)
    dense = np.zeros((5, 30))
    np.add.at(dense, (rows, cols), w)
    c1, w1, _ = transfer.top_entries(dense, 6)
    c2, w2, _ = transfer.sparse_top(rows, cols, w, 5, 6)
    for r in range(5):
        a = dict(zip(c1[r].tolist(), w1[r].tolist()))
        b = dict(zip(c2[r].tolist(), w2[r].tolist()))
        assert a.keys() == b.keys()
        assert all(abs(a[x] - b[x]) < 1e-5 for x in a)
    np.testing.assert_allclose(w1.sum(1), dense.sum(1), rtol=1e-6)
    # unscaled: the largest entries as they are, the rest of the row's sum beside them
    for c, kw, rest in (transfer.top_entries(dense, 6, keep_sum=False),
                        transfer.sparse_top(rows, cols, w, 5, 6, keep_sum=False)):
        np.testing.assert_allclose(kw, np.take_along_axis(dense, c, 1), rtol=1e-6)
        np.testing.assert_allclose(kw.sum(1) + rest, dense.sum(1), rtol=1e-6)



@pytest.mark.parametrize("width, bound", [(3, 0.04), (1, 0.04)])     # measured 2.5, 2.0 %
def test_rows_cut_to_the_budget_stay_near_the_quadrature(width, bound):
    """A row cut to its largest entries keeps the sum of the rest, read at the mean
    radiance its own triangles' clusters see (their rows' gather over their rows' sum)."""
    cube = cubemap(8)
    objs = floor_and_wall(16)
    pts = [mesh.shading_points(o) for o in objs]
    P, N, bits, scene, patches, cluster_of, k, cell, hits, rows = _transfer(
        objs, cube, width, keep_sum=False)
    patch, owner, weight = clusters.sample_sets(cluster_of, patches.centroids,
                                                patches.areas, k, cell)
    scube = cubemap(16)
    own = transfer.TransferRows(len(patch), k, hits, scube)
    sp, sn = patches.centroids[patch], patches.normals[patch]
    sb = visibility.trace_visibility(
        scene, sp, sn, scube, OFFSET,
        hits=lambda a, b, blocked, prim: own.add(a, b, sn[a:b], blocked, prim))
    E = reference.diffuse_irradiance(sb, sn, scube, _sky(scube))
    direct = np.stack([np.bincount(owner, weights=weight * E[:, c], minlength=k)
                       for c in range(3)], axis=1)
    L = bounce.bounce(direct, np.full((k, 3), RHO), np.zeros((k, 1), np.int32),
                      np.zeros((k, 1), np.float32), 1)
    k_cols, k_w = transfer.cluster_rows(owner, weight, own.columns, own.weights, k)
    seen = bounce.seen_radiance(k_cols, k_w, L)
    light = []
    for i, (o, pt) in enumerate(zip(objs, pts)):
        tri = o.triangles[:o.front_triangles]
        light.append(bounce.rest_radiance(seen, cluster_of[patches.of_mesh(i, o)[0]],
                                          pt.point_of_corner[tri],
                                          mesh.triangle_areas(o.positions[o.corner_verts[tri]]),
                                          pt.count))
    got = bounce.receive(rows.columns, rows.weights, L, rows.rest, np.concatenate(light))
    idx = np.random.default_rng(1).choice(len(P), 60, replace=False)
    truth = np.array([_brute(i, P, N, scene, hits, cube, _sky(cube)) for i in idx])
    err = np.linalg.norm(got[idx] - truth) / np.linalg.norm(truth)
    assert err < bound, err


def test_row_width_fits_the_budget_and_says_so():
    full = transfer.ROW_WIDTH * transfer.ENTRY_BYTES + transfer.INNER_BYTES
    assert transfer.row_width(1000, 1000 * full / 2 ** 20) == (transfer.ROW_WIDTH, "")
    width, note = transfer.row_width(5_000_000, 256)
    assert width == int((256 * 2 ** 20 / 5e6 - transfer.INNER_BYTES) // transfer.ENTRY_BYTES)
    assert 1 <= width < transfer.ROW_WIDTH
    assert f"{width} entries" in note and "256 MiB" in note
    assert transfer.row_width(10 ** 9, 0)[0] == 1            # never no row at all


def test_cluster_rows_made_a_block_at_a_time_are_the_rows_made_at_once():
    rng = np.random.default_rng(3)
    owner = np.sort(rng.integers(0, 50, 400))
    weight = rng.uniform(0.1, 1.0, 400)
    cols = rng.integers(0, 50, (400, 8)).astype(np.int32)
    w = rng.uniform(0.0, 1.0, (400, 8)).astype(np.float32)
    one = transfer.cluster_rows(owner, weight, cols, w, 50, width=6, block=10 ** 9)
    few = transfer.cluster_rows(owner, weight, cols, w, 50, width=6, block=40)
    ref = transfer.sparse_top(np.repeat(owner, 8), cols.reshape(-1).astype(np.int64),
                              (w * weight[:, None]).reshape(-1), 50, 6)[:2]
    def dense(cols, w):                # the rows as a matrix: the entries' order not compared
        out = np.zeros((50, 50))
        np.add.at(out, (np.repeat(np.arange(50), cols.shape[1]), cols.reshape(-1)),
                  w.reshape(-1))
        return out
    for got in (one, few):
        np.testing.assert_allclose(dense(*got), dense(*ref), rtol=1e-6, atol=1e-9)
