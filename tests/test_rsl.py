"""Rotatable square lights (core/methods/rsl/shading.py, Xu et al. 2006) against brute force and REFERENCE."""

from __future__ import annotations

import time

import numpy as np
import pytest

from prt_relight.core.shading import brdf
from prt_relight.core.shading import materials
from prt_relight.core.methods.rsl import cpca, shading as rsl
from prt_relight.core.scene import distance_tables
from prt_relight.core.methods.rsl import square_lights
from prt_relight.core.sphere import directions, envmap
from prt_relight.core.scene import mesh, visibility
from prt_relight.core.methods.reference import shading as reference

CUBE = directions.cubemap(32)


def _sky_with_sun(h=64, w=128, sun=(20, 37), sun_value=5.0e4):
    rng = np.random.default_rng(3)
    img = np.full((h, w, 3), 0.3, dtype=np.float32) + 0.2 * rng.random((h, w, 3)).astype(np.float32)
    img[h // 2:] *= 0.2                                       # darker ground
    img[sun] = sun_value
    return img


def test_decomposition_preserves_energy_and_partitions_the_sphere():
    img = _sky_with_sun()
    lighting = envmap.WorldLighting(image=img).to_cubemap(32)
    total = (lighting.radiance.astype(np.float64) * CUBE.solid_angles[:, None]).sum(0)
    for K in (10, 30, 100):
        lights = square_lights.decompose(lighting, CUBE, K)
        assert lights.count == K
        np.testing.assert_allclose(lights.energy.sum(0), total, rtol=1e-10)
        assert lights.solid_angles.sum() == pytest.approx(4 * np.pi, rel=1e-12)
        assert set(np.unique(lights.labels)) == set(range(K))
        np.testing.assert_allclose(np.linalg.norm(lights.centres, axis=1), 1.0)
        # intensity * |S| is the region's energy (I = integral L / 2r², §4.1.1)
        np.testing.assert_allclose(lights.intensity * lights.solid_angles[:, None],
                                   lights.energy)


def test_subregions_are_connected():
    lighting = envmap.WorldLighting(image=_sky_with_sun()).to_cubemap(32)
    lights = square_lights.decompose(lighting, CUBE, 30)
    pairs = square_lights.texel_neighbours(CUBE)
    for k in range(lights.count):
        members = np.nonzero(lights.labels == k)[0]
        inside = np.zeros(CUBE.size, bool)
        inside[members] = True
        edges = pairs[inside[pairs[:, 0]] & inside[pairs[:, 1]]]
        seen = {members[0]}
        frontier = [members[0]]
        adj = {}
        for a, b in edges:
            adj.setdefault(a, []).append(b)
            adj.setdefault(b, []).append(a)
        while frontier:
            x = frontier.pop()
            for y in adj.get(x, []):
                if y not in seen:
                    seen.add(y)
                    frontier.append(y)
        assert len(seen) == len(members)


def test_one_pixel_sun_becomes_one_tiny_light():
    h, w = 256, 512
    row, col = 70, 151
    sun_only = np.zeros((h, w, 3), np.float32)
    sun_only[row, col] = 1.0
    # the chosen pixel lies inside one cubemap texel (else "one texel" is not possible)
    assert np.count_nonzero(envmap.WorldLighting(image=sun_only).to_cubemap(32).radiance[:, 0]) == 1
    img = _sky_with_sun(h, w, sun=(row, col), sun_value=5.0e5)
    lighting = envmap.WorldLighting(image=img).to_cubemap(32)
    lights = square_lights.decompose(lighting, CUBE, 30)
    brightest = int(np.argmax(lights.intensity @ envmap.LUMINANCE))
    assert np.count_nonzero(lights.labels == brightest) == 1
    assert lights.solid_angles[brightest] < 1.5 * 4 * np.pi / CUBE.size
    # at the sun's true direction (pixel centre), not the texel centre's
    theta = (row + 0.5) / h * np.pi
    phi = (0.5 - (col + 0.5) / w) * 2 * np.pi
    sun = np.array([np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi), np.cos(theta)])
    assert np.degrees(np.arccos(np.clip(lights.centres[brightest] @ sun, -1, 1))) < 0.2
    sun_energy = 5.0e5 * (np.cos(row * np.pi / h) - np.cos((row + 1) * np.pi / h)) * 2 * np.pi / w
    assert lights.energy[brightest, 0] == pytest.approx(sun_energy, rel=0.01)


def test_error_budget_mode_stops_at_the_budget():
    lighting = envmap.WorldLighting(image=_sky_with_sun()).to_cubemap(32)
    f30 = square_lights.decompose(lighting, CUBE, 30).fit_error
    loose = square_lights.decompose(lighting, CUBE, None, error_budget=f30)
    tight = square_lights.decompose(lighting, CUBE, None, error_budget=f30 / 4)
    assert loose.fit_error <= f30 and tight.fit_error <= f30 / 4
    assert tight.count > loose.count >= 1
    assert loose.count <= 30
    assert square_lights.decompose(lighting, CUBE, 10, error_budget=1e9).count == 10


def test_decomposition_is_fast():
    """6x32² -> 30 lights; the bench prints the time, here only a generous bound."""
    lighting = envmap.WorldLighting(image=_sky_with_sun()).to_cubemap(32)
    t0 = time.perf_counter()
    square_lights.decompose(lighting, CUBE, 30)
    assert time.perf_counter() - t0 < 10.0


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


@pytest.mark.parametrize("material", [
    materials.Material(specular_color=(1, 1, 1), roughness=0.4, distribution="GGX"),
    materials.principled_material(roughness=0.5),
])
def test_brdf_sat_matches_quadrature(material):
    """Square averages of the SAT equal a fine quadrature of BRDF x cosine (eq. 8)."""
    tables = rsl.brdf_tables(material, 32, 32, sub=4)
    rng = np.random.default_rng(2)
    theta = 0.5 * np.pi * 10 / 31                             # on a view node
    view = np.array([[np.sin(theta), 0.0, np.cos(theta)]])
    for _ in range(6):
        px, py = rng.uniform(-0.6, 0.6, 2)
        half = rng.uniform(0.08, 0.25)
        m = 96
        c = (np.arange(m) + 0.5) / m * 2 - 1
        qy, qx = np.meshgrid(py + half * c, px + half * c, indexing="ij")
        inside = (qx ** 2 + qy ** 2 < 1).reshape(-1)
        dirs = directions.rsl_disk_to_hemisphere(qx, qy).reshape(-1, 3)[inside]
        f = brdf.reflectance_cosine(material, np.array([[0, 0, 1.0]]), view, dirs)[0]
        want = f.sum(0) / (m * m)
        diffuse = np.asarray(material.diffuse_albedo) / np.pi * brdf.diffuse_view_weight(
            material, np.array([[0, 0, 1.0]]), view)[0]
        got = diffuse * rsl.brdf_box(tables, None, None, px, py, half)
        weights = [w[0] for _, w in brdf.specular_terms(material, np.array([[0, 0, 1.0]]), view,
                                                        np.array([[0, 0, 1.0]]))]
        for k, wk in enumerate(weights):
            got = got + wk * rsl.brdf_box(tables, k, np.array(theta), px, py, half)
        np.testing.assert_allclose(got, want, rtol=0.03, atol=1e-3 * want.max())


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


def test_sat_visibility_averages_the_part_of_the_square_inside_the_table():
    """A square near the horizon reaches past the map's [-1, 1]² (no values there): the
    SAT option averages over its inside part (not over the whole square, which would
    count the outside as occluded); a square wholly outside is fully visible."""
    n = 32
    maps = np.zeros((1, n, n), np.float32)
    maps[0, :, 24:] = 1.0                                 # visible for x > -1 + 24·2/n = 0.5
    sat = distance_tables.visibility_sat(maps)
    rng = np.random.default_rng(11)
    for _ in range(40):
        half = rng.uniform(0.1, 0.4)
        px = rng.uniform(1.0 - half, 1.0 + 0.9 * half)     # straddles the right edge
        py = rng.uniform(-0.5, 0.5)
        lo, hi = px - half, min(px + half, 1.0)
        want = max(0.0, hi - max(lo, 0.5)) / (hi - lo)
        got = rsl.visible_fraction("SAT", sat, np.array([[px]]), np.array([[py]]), half)
        assert got[0, 0] == pytest.approx(want, abs=1e-5)
    outside = rsl.visible_fraction("SAT", sat, np.array([[1.5]]), np.array([[0.0]]), 0.2)
    assert outside[0, 0] == 1.0


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
    pos, nrm, bits = _scene(6)
    maps = distance_tables.visibility_maps(bits, nrm, CUBE, 32)
    vdt = distance_tables.visibility_tables(bits, nrm, CUBE, "VDT", threads=2, block=5)
    np.testing.assert_array_equal(vdt, distance_tables.visibility_distance_table(maps))
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


def _scene(cuts=10):
    g = mesh.grid(size=2.0, cuts=cuts)
    sp = mesh.shading_points(g)
    box = np.array([[[0.2, -0.5, 0.0], [0.8, -0.5, 0.0], [0.8, -0.5, 0.8]],
                    [[0.2, -0.5, 0.0], [0.8, -0.5, 0.8], [0.2, -0.5, 0.8]],
                    [[0.2, -0.5, 0.8], [0.8, -0.5, 0.8], [0.8, 0.5, 0.8]],
                    [[0.2, -0.5, 0.8], [0.8, 0.5, 0.8], [0.2, 0.5, 0.8]]])
    rng = np.random.default_rng(0)
    nrm = sp.normals + 0.3 * rng.normal(size=sp.normals.shape)
    nrm /= np.linalg.norm(nrm, axis=1, keepdims=True)
    scene = visibility.build_occluder_scene(np.concatenate([g.triangle_positions, box]))
    bits = visibility.trace_visibility(scene, sp.positions, nrm, CUBE, 1e-4)
    return sp.positions, nrm, bits


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


@pytest.mark.parametrize("graded", [False, True])
def test_horizon_is_cut_once(graded):
    """Unoccluded points under a smooth sky: eq. 5 needs only the cosine to cut a light
    that straddles the horizon.  A visibility that also fell to 0 below the horizon
    counts the cut twice (the old maps: 5 % too dark at K = 30, 1.6 % at K = 100)."""
    nrm = directions.fibonacci_sphere(400)
    bits = np.packbits(visibility.hemisphere_mask(nrm, CUBE), axis=1)
    img = np.ones((64, 128, 3), np.float32)
    if graded:                                              # bright towards the nadir
        img *= (0.2 + np.linspace(0.0, 1.0, 64) ** 2)[:, None, None].astype(np.float32)
    lighting = envmap.WorldLighting(image=img).to_cubemap(32)
    mat = materials.Material()
    ref = reference.shade_points(bits, np.zeros_like(nrm), nrm, np.zeros(len(nrm), int), [mat],
                                 None, CUBE, lighting)
    table = distance_tables.visibility_distance_table(distance_tables.visibility_maps(bits, nrm, CUBE, 32))
    tables = rsl.brdf_tables(mat)
    for K, bound in ((30, 0.01), (100, 0.004)):
        ev = rsl.Evaluator(square_lights.decompose(lighting, CUBE, K))
        V, C = ev.diffuse_factors(nrm, "VDT", table, tables)
        out = ev.shade(mat, tables, nrm, None, V, C)
        assert np.linalg.norm(out - ref) / np.linalg.norm(ref) < bound
        assert abs(out.sum() / ref.sum() - 1.0) < bound / 2


def test_merges_follow_fig5():
    """Each step merges the adjacent pair whose *merged* subregion has the least eq. 7
    cost (Fig. 5), checked against a brute-force greedy merge on a 6x4² cubemap."""
    cube = directions.cubemap(4)
    rng = np.random.default_rng(11)
    img = (rng.random((16, 32, 3)) ** 4 * 10).astype(np.float32)
    lighting = envmap.WorldLighting(image=img).to_cubemap(4)
    Y = np.maximum(lighting.radiance.astype(np.float64) @ envmap.LUMINANCE, 0.0)
    dw = cube.solid_angles.astype(np.float64)
    regions = [{i} for i in range(cube.size)]
    texel_pairs = square_lights.texel_neighbours(cube)

    def cost(members):
        m = np.array(sorted(members))
        A = dw[m].sum()
        M = (cube.mean_directions[m] * dw[m, None]).sum(0)
        return square_lights.square_fit_error(A, (Y[m] * dw[m]).sum(), (Y[m] ** 2 * dw[m]).sum(), M) * A

    while len(regions) > 12:
        owner = np.empty(cube.size, int)
        for k, reg in enumerate(regions):
            owner[list(reg)] = k
        pairs = {tuple(sorted(p)) for p in owner[texel_pairs] if p[0] != p[1]}
        i, j = min(pairs, key=lambda p: cost(regions[p[0]] | regions[p[1]]))
        regions[i] |= regions.pop(j)
    lights = square_lights.decompose(lighting, cube, 12)
    got = sorted(sorted(np.nonzero(lights.labels == k)[0].tolist()) for k in range(12))
    assert got == sorted(sorted(reg) for reg in regions)


@pytest.mark.parametrize("kind", ["VDT", "SAT"])
def test_rsl_converges_to_reference(kind):
    """eq. 5 with more lights approaches REFERENCE; with a light per texel only the
    square/box approximations are left."""
    pos, nrm, bits = _scene()
    img = envmap.load_equirect(str(_hdri("forest"))) if _hdri("forest") else _sky_with_sun()
    lighting = envmap.WorldLighting(image=img).to_cubemap(32)
    mat = materials.principled_material(roughness=0.5)
    eye = np.array([3.0, -4.0, 2.5])
    ref = reference.shade_points(bits, pos, nrm, np.zeros(len(nrm), int), [mat], eye, CUBE,
                                 lighting)
    maps = distance_tables.visibility_maps(bits, nrm, CUBE, 32)
    table = distance_tables.visibility_distance_table(maps) if kind == "VDT" else distance_tables.visibility_sat(maps)
    tables = rsl.brdf_tables(mat)
    views = reference.view_directions(pos, eye)
    errs = []
    for K in (10, 100, CUBE.size):
        ev = rsl.Evaluator(square_lights.decompose(lighting, CUBE, K))
        V, C = ev.diffuse_factors(nrm, kind, table, tables)
        out = ev.shade(mat, tables, nrm, views, V, C)
        errs.append(np.linalg.norm(out - ref) / np.linalg.norm(ref))
    assert errs[0] > 2 * errs[1]  # (the VDT's K = 6144 floor, 1.5 %, is above K = 100's 1.3 %)
    assert errs[0] < 0.07         # 7.8-8.0 % when the horizon was cut twice (V = 0 below it)
    assert errs[1] < 0.015
    assert errs[2] < 0.02


def test_world_rotation_rotates_the_lights():
    """Rotating the lighting (Mapping node) = rotating the RSL centres: RSL with rotated
    centres stays as close to the rotated REFERENCE as unrotated RSL to REFERENCE."""
    pos, nrm, bits = _scene(8)
    img = _sky_with_sun()
    R = envmap.euler_xyz_matrix(0.3, -0.2, 1.1)
    mat = materials.Material()
    lights = square_lights.decompose(envmap.WorldLighting(image=img).to_cubemap(32), CUBE, 100)
    maps = distance_tables.visibility_maps(bits, nrm, CUBE, 32)
    sat = distance_tables.visibility_sat(maps)
    tables = rsl.brdf_tables(mat)
    ref = reference.shade_points(bits, pos, nrm, np.zeros(len(nrm), int), [mat], None, CUBE,
                                 envmap.WorldLighting(image=img, rotation=R).to_cubemap(32))
    ev = rsl.Evaluator(lights, R)
    V, C = ev.diffuse_factors(nrm, "SAT", sat, tables)
    out = ev.shade(mat, tables, nrm, None, V, C)
    rotated_error = np.linalg.norm(out - ref) / np.linalg.norm(ref)
    assert rotated_error < 0.1       # the sun's shadow edges in a 32² disk map: about 6 %
    ev0 = rsl.Evaluator(lights)
    V0, C0 = ev0.diffuse_factors(nrm, "SAT", sat, tables)
    unrotated = ev0.shade(mat, tables, nrm, None, V0, C0)
    assert np.linalg.norm(unrotated - ref) / np.linalg.norm(ref) > 3 * rotated_error


def _hdri(name):
    import pathlib
    import prt_relight
    root = pathlib.Path(prt_relight.__file__).parent
    hits = list((root / ".venv/lib").glob(f"python3*/site-packages/bpy/*/datafiles/studiolights/"
                                           f"world/{name}.exr"))
    return hits[0] if hits else None


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


def test_offset_sat_keeps_float32_precision():
    """§4.2's GPU precision problem: a SAT of large positive values loses the small
    boxes' integrals in float32; the SAT of ``f - mean`` (mean added back) keeps them."""
    rng = np.random.default_rng(6)
    n = 32
    cell = (2.0 / n) ** 2
    integ = (50.0 + rng.random((n, n))) * cell
    exact = distance_tables.summed_area(integ)
    plain = exact.astype(np.float32)
    offset_sat, mean = rsl.offset_sat(integ, cell)
    offset_sat = offset_sat.astype(np.float32)
    err_plain, err_offset = [], []
    for _ in range(300):
        half = rng.uniform(0.005, 0.03)
        px, py = rng.uniform(0.3, 0.9, 2)                 # far corner: large SAT values
        want = distance_tables.box_integral(exact, px, py, half)
        got_plain = distance_tables.box_integral(plain.astype(np.float64), px, py, half)
        got_offset = (distance_tables.box_integral(offset_sat.astype(np.float64), px, py, half)
                      + mean * rsl.clipped_area(px, py, half))
        err_plain.append(abs(got_plain - want) / want)
        err_offset.append(abs(got_offset - want) / want)
    assert np.max(err_offset) < 1e-4
    assert np.max(err_plain) > 10 * np.max(err_offset)


def test_texel_of_components_equals_the_face_axis_lookup():
    rng = np.random.default_rng(8)
    d = rng.normal(size=(20000, 3))
    d = np.concatenate([d, directions.fibonacci_sphere(500), np.eye(3), -np.eye(3),
                        CUBE.directions, [[1, 1, 0], [1, -1, 1], [-1, -1, -1], [0, 1, -1]]])
    face, s, t = directions.face_coordinates(d)              # FACE_AXES dot products
    col = np.clip(((s + 1.0) * 0.5 * 32).astype(np.int64), 0, 31)
    row = np.clip(((t + 1.0) * 0.5 * 32).astype(np.int64), 0, 31)
    np.testing.assert_array_equal(directions.direction_to_texel(d, 32),
                                  (face * 32 + row) * 32 + col)
