"""core.scene.distance_tables (Xu, Jia, Hu, Tai 2006, §4.3, eq. 9): summed-area box
integrals against brute-force sums, visibility distance tables against straight boundaries,
a disc and brute-force distances, the disk maps of the hemisphere's visibility and the
threaded derivation of the tables.  No bpy."""

from __future__ import annotations

import numpy as np
import pytest

from prt_relight.core.methods.rsl import shading as rsl
from prt_relight.core.scene import distance_tables
from prt_relight.core.sphere import directions
from prt_relight.core.scene import visibility

from ..methods.rsl.scenes import CUBE, occluded_grid


def _brute_box(values, x0, x1, y0, y1):
    """Exact integral of the piecewise-constant grid function over a box (disk units)."""
    n = values.shape[-1]
    edges = np.linspace(-1, 1, n + 1)
    ox = np.clip(np.minimum(edges[1:], x1) - np.maximum(edges[:-1], x0), 0, None)
    oy = np.clip(np.minimum(edges[1:], y1) - np.maximum(edges[:-1], y0), 0, None)
    return float(oy @ values @ ox) / (2.0 / n) ** 2


def test_sat_box_integrals_equal_brute_force_sums():
    rng = np.random.default_rng(1)
    vals = rng.random((16, 16))                              # per-texel integrals
    S = distance_tables.summed_area(vals)
    for _ in range(200):
        px, py = rng.uniform(-1.2, 1.2, 2)
        half = rng.uniform(0.01, 0.6)
        got = distance_tables.box_integral(S, np.array(px), np.array(py), np.array(half))
        want = _brute_box(vals, px - half, px + half, py - half, py + half)
        assert got == pytest.approx(want, abs=1e-12)


def test_vdt_equals_box_integral_for_straight_boundaries():
    n = 32
    h = 2.0 / n
    rng = np.random.default_rng(4)
    for edge in (7, 16, 23):
        x_b = -1 + edge * h                                   # boundary on a texel edge
        maps = np.zeros((2, n, n), np.float32)
        maps[0, :, edge:] = 1.0                               # visible for x > x_b
        maps[1, :edge, :] = 1.0                               # visible for y < y_b (rows)
        vdt = distance_tables.visibility_distance_table(maps)
        for _ in range(50):
            half = rng.uniform(0.02, 0.3)
            px, py = rng.uniform(-1 + half, 1 - half, 2)      # inside the domain
            want0 = np.clip((px + half - x_b) / (2 * half), 0, 1)
            want1 = np.clip((x_b - (py - half)) / (2 * half), 0, 1)
            got = distance_tables.vdt_box(vdt, np.array([px, px]), np.array([py, py]), half,
                              lead=np.arange(2))
            np.testing.assert_allclose(got, [want0, want1], atol=1e-6)
            sat = distance_tables.visibility_sat(maps)
            got_sat = rsl.visible_fraction("SAT", sat, np.array([[px], [px]]),
                                           np.array([[py], [py]]), half)[:, 0]
            np.testing.assert_allclose(got_sat, [want0, want1], atol=1e-5)


def test_vdt_is_the_signed_distance():
    n = 32
    maps = np.zeros((1, n, n), np.float32)
    yy, xx = np.mgrid[0:n, 0:n]
    maps[0][(xx - 15.5) ** 2 + (yy - 15.5) ** 2 < 8 ** 2] = 1.0  # a disc of radius ~8 texels
    vdt = distance_tables.visibility_distance_table(maps)[0]
    h = 2.0 / n
    r = np.hypot(xx - 15.5, yy - 15.5) * h
    # true signed distance to the circle, up to the texel staircase (< one texel)
    assert np.max(np.abs(vdt - (8 * h - r))) < 0.8 * h
    assert np.all((vdt > 0) == (maps[0] > 0.5))


def test_vdt_equals_brute_force_distances():
    """Random blobs (and empty/full maps) against the distance to every texel centre of
    the other value, sign(d - h/2), by brute force."""
    n = 16
    h = 2.0 / n
    rng = np.random.default_rng(8)
    maps = (rng.random((6, n, n)) < np.linspace(0.05, 0.95, 6)[:, None, None])
    maps = maps.astype(np.float32)
    maps[4] = 1.0
    maps[5] = 0.0
    got = distance_tables.visibility_distance_table(maps, chunk=4)      # chunks of fewer maps too
    yy, xx = np.mgrid[0:n, 0:n]
    for m, table in zip(maps, got):
        vis = m >= 0.5
        if vis.all() or not vis.any():
            assert np.all(table == (2.0 if vis.all() else -2.0))
            continue
        for i in range(n):
            for j in range(n):
                other = vis != vis[i, j]
                d = np.sqrt(((yy[other] - i) ** 2 + (xx[other] - j) ** 2).min()) * h
                want = (d - h / 2) * (1 if vis[i, j] else -1)
                assert table[i, j] == pytest.approx(want, abs=1e-6)


def test_visibility_tables_equal_the_maps_pipeline():
    """The fused, threaded derivation (blocks of a few points on 2 threads) gives the
    VDT / SAT of the maps, in the requested type; a progress callback that raises stops it."""
    pos, nrm, bits = occluded_grid(6)
    maps = distance_tables.visibility_maps(bits, nrm, CUBE, 32)
    vdt = distance_tables.visibility_tables(bits, nrm, CUBE, "VDT", threads=2, block=5)
    np.testing.assert_allclose(vdt, distance_tables.visibility_distance_table(maps), atol=1e-6)
    sat = distance_tables.visibility_tables(bits, nrm, CUBE, "SAT", threads=2, block=5)
    np.testing.assert_allclose(sat, distance_tables.visibility_sat(maps), atol=1e-6)
    half = distance_tables.visibility_tables(bits, nrm, CUBE, "VDT", dtype=np.float16, threads=1, block=7)
    assert half.dtype == np.float16
    np.testing.assert_allclose(half, vdt, atol=2e-3)
    seen = []

    def stop(fraction):
        seen.append(fraction)
        raise KeyboardInterrupt
    with pytest.raises(KeyboardInterrupt):
        distance_tables.visibility_tables(bits, nrm, CUBE, "VDT", threads=2, block=5, progress=stop)
    assert seen == [5 / len(nrm)]


def test_visibility_maps_are_the_hemisphere_visibility():
    """Disk texels read the cube bits (here one ray per texel); below the horizon
    (outside the unit disk) the map continues the visibility at the same azimuth
    instead of dropping to 0, so an open hemisphere has no boundary at all and an
    occluder meeting the horizon continues straight across it."""
    nrm = directions.fibonacci_sphere(20)
    open_bits = np.packbits(visibility.hemisphere_mask(nrm, CUBE), axis=1)
    for sub in (1, 2):
        assert np.all(distance_tables.visibility_maps(open_bits, nrm, CUBE, 32, sub) == 1.0)  # no rim
    maps = distance_tables.visibility_maps(open_bits, nrm, CUBE, 32)
    vdt = distance_tables.visibility_distance_table(maps)
    assert np.all(vdt > 0)
    # an occluder covering the half space w . a < 0 (a great circle through the horizon)
    a = np.array([0.3, -0.8, 0.52])
    a /= np.linalg.norm(a)
    lit = (CUBE.directions @ a > 0)[None, :] & visibility.hemisphere_mask(nrm, CUBE)
    maps = distance_tables.visibility_maps(np.packbits(lit, axis=1), nrm, CUBE, 32, sub=1)
    px, py, _, _ = distance_tables.disk_texel_samples(32, 1)
    r = np.hypot(px, py)
    z0 = 2.0 / CUBE.resolution
    scale = np.minimum(1.0, np.sqrt(1.0 - z0) / r)            # outside: read at height z0
    local = directions.rsl_disk_to_hemisphere(px * scale, py * scale)
    t, b = directions.orthonormal_frame(nrm)
    for p in range(len(nrm)):
        world = local @ np.stack([t[p], b[p], nrm[p]])
        s = world @ a
        clear = np.abs(s) > 0.06                            # away from the texel staircase
        np.testing.assert_array_equal(maps[p][clear], (s > 0)[clear].astype(np.float32))
        outside = clear & (r > 1.0)
        assert outside.any() and (maps[p][outside] == 0).any() and (maps[p][outside] == 1).any()
