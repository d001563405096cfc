"""core.methods.rsl.shading (Xu, Jia, Hu, Tai 2006): BRDF SATs against quadrature (eq. 8),
the visible fraction of a square, the offset SAT's float32 precision (§4.2), the horizon cut
once, eq. 5 converging to REFERENCE and the world's rotation turning the lights.  No bpy."""

from __future__ import annotations

import numpy as np
import pytest

from prt_relight.core.shading import brdf
from prt_relight.core.shading import materials
from prt_relight.core.methods.rsl import shading as rsl
from prt_relight.core.scene import distance_tables
from prt_relight.core.methods.rsl import square_lights
from prt_relight.core.sphere import directions, envmap
from prt_relight.core.scene import visibility
from prt_relight.core.methods.reference import shading as reference

from .scenes import CUBE, occluded_grid, sky_with_sun


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


def test_world_rotation_rotates_the_lights():
    """Rotating the lighting (Mapping node) = rotating the RSL centres: RSL with rotated
    centres stays as close to the rotated REFERENCE as unrotated RSL to REFERENCE."""
    pos, nrm, bits = occluded_grid(8)
    img = sky_with_sun()
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


@pytest.mark.parametrize("mat", [
    materials.principled_material(base_color=(0.9, 0.2, 0.1), roughness=0.4),
    materials.Material(diffuse_albedo=(0.9, 0.2, 0.1), specular_color=(0.6, 0.5, 0.4),
                       roughness=0.3, fresnel="F82", distribution="MULTI_GGX")])
def test_glossy_tables_ignore_a_base_colour_that_reaches_no_lobe(mat):
    """table_material sets the base colour aside where no metal lobe reads it: the tables
    made with any base colour are the same (a textured slot's white and black variants
    share theirs); a part-metal Principled keeps its own."""
    from dataclasses import replace
    black = replace(mat, diffuse_albedo=(0.0, 0.0, 0.0))
    a, b = rsl.brdf_tables(mat, 8, 4, 2), rsl.brdf_tables(black, 8, 4, 2)
    assert len(a.glossy) == len(b.glossy) > 0
    for x, y in zip(a.glossy, b.glossy):               # two fits: within their rounding
        np.testing.assert_allclose(x, y, rtol=1e-5, atol=1e-7 * np.abs(x).max())
    assert rsl.table_material(mat) == rsl.table_material(black)
    metal = materials.principled_material(base_color=(0.9, 0.2, 0.1), metallic=0.5)
    assert rsl.table_material(metal) == metal
