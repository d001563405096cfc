# SPDX-License-Identifier: GPL-3.0-or-later
"""core.sphere.envmap against analytic values: the equirect mapping and pixel solid angles,
Blender's XYZ Euler rotation, the world's lighting (a one-pixel sun, a uniform colour,
rotation, refused and clamped input), EXR loading, colour spaces and the equirect's mip
atlas.  Pure numpy (+ OpenImageIO for the EXR round trip); no bpy."""

from __future__ import annotations

import numpy as np
import pytest

from prt_relight.core.sphere import directions, envmap


def unit(v):
    v = np.asarray(v, dtype=np.float64)
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def random_unit(rng, n):
    return unit(rng.normal(size=(n, 3)))


def pixel_centre_direction(row, col, h, w):
    """Texture-space direction of an equirect pixel centre, from the Blender
    convention u = 0.5 - atan2(y, x)/2pi, v = acos(z)/pi (inverted by hand)."""
    theta = (row + 0.5) * np.pi / h
    phi = (0.5 - (col + 0.5) / w) * 2.0 * np.pi
    return np.array([np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi), np.cos(theta)])


# --------------------------------------------------------------------------- #
# envmap: convention
# --------------------------------------------------------------------------- #

@pytest.mark.parametrize("d,u,v", [
    ([1, 0, 0], 0.5, 0.5),
    ([0, 1, 0], 0.25, 0.5),
    ([0, -1, 0], 0.75, 0.5),
    ([-1, 0, 0], 0.0, 0.5),
    ([0, 0, 1], None, 0.0),
    ([0, 0, -1], None, 1.0),
    ([1, 1, 0], 0.375, 0.5),
    ([1, 0, 1], 0.5, 0.25),
])
def test_direction_to_equirect_uv_known(d, u, v):
    uu, vv = envmap.direction_to_equirect_uv(unit(np.array(d, dtype=np.float64)))
    if u is not None:
        assert float(np.mod(uu - u + 0.5, 1.0) - 0.5) == pytest.approx(0.0, abs=1e-12)
    assert float(vv) == pytest.approx(v, abs=1e-12)


def test_direction_to_equirect_uv_formula_random():
    rng = np.random.default_rng(11)
    d = random_unit(rng, 5000)
    u, v = envmap.direction_to_equirect_uv(d)
    assert np.all((u >= 0) & (u < 1)) and np.all((v >= 0) & (v <= 1))
    ref_u = 0.5 - np.arctan2(d[:, 1], d[:, 0]) / (2 * np.pi)
    np.testing.assert_allclose(np.mod(u - ref_u + 0.5, 1.0) - 0.5, 0.0, atol=1e-12)
    np.testing.assert_allclose(v, np.arccos(d[:, 2]) / np.pi, atol=1e-12)


@pytest.mark.parametrize("h,w,s", [(8, 16, 1), (16, 32, 3), (33, 70, 2)])
def test_equirect_directions(h, w, s):
    dirs, sa = envmap.equirect_directions(h, w, s)
    assert dirs.shape == (h * s, w * s, 3) and sa.shape == (h * s, w * s)
    np.testing.assert_allclose(sa.sum(), 4 * np.pi, rtol=1e-12)
    assert np.all(sa > 0)
    np.testing.assert_allclose(np.linalg.norm(dirs, axis=-1), 1.0, atol=1e-12)
    u, v = envmap.direction_to_equirect_uv(dirs)
    # (sub-)pixel centres map back to their own (sub-)pixel centres
    np.testing.assert_allclose(u, ((np.arange(w * s) + 0.5) / (w * s))[None, :].repeat(h * s, 0),
                               atol=1e-12)
    np.testing.assert_allclose(v, ((np.arange(h * s) + 0.5) / (h * s))[:, None].repeat(w * s, 1),
                               atol=1e-12)
    # exact pixel solid angle: (cos th0 - cos th1) * 2pi / W
    r = 0
    exact = (np.cos(r * np.pi / (h * s)) - np.cos((r + 1) * np.pi / (h * s))) * 2 * np.pi / (w * s)
    np.testing.assert_allclose(sa[0, 0], exact, rtol=1e-12)


def test_euler_xyz_matrix():
    rng = np.random.default_rng(5)
    for rx, ry, rz in rng.uniform(-np.pi, np.pi, size=(10, 3)):
        R = envmap.euler_xyz_matrix(rx, ry, rz)
        np.testing.assert_allclose(R @ R.T, np.eye(3), atol=1e-12)
        assert np.linalg.det(R) == pytest.approx(1.0, abs=1e-12)
    # known axis rotations (right handed, counter-clockwise)
    q = np.pi / 2
    np.testing.assert_allclose(envmap.euler_xyz_matrix(q, 0, 0) @ [0, 1, 0], [0, 0, 1], atol=1e-12)
    np.testing.assert_allclose(envmap.euler_xyz_matrix(0, q, 0) @ [0, 0, 1], [1, 0, 0], atol=1e-12)
    np.testing.assert_allclose(envmap.euler_xyz_matrix(0, 0, q) @ [1, 0, 0], [0, 1, 0], atol=1e-12)
    # Blender XYZ Euler: X first, then Y, then Z -> Rz @ Ry @ Rx
    rx, ry, rz = 0.3, -1.1, 2.0
    cx, sx, cy, sy, cz, sz = np.cos(rx), np.sin(rx), np.cos(ry), np.sin(ry), np.cos(rz), np.sin(rz)
    Rx = np.array([[1, 0, 0], [0, cx, -sx], [0, sx, cx]])
    Ry = np.array([[cy, 0, sy], [0, 1, 0], [-sy, 0, cy]])
    Rz = np.array([[cz, -sz, 0], [sz, cz, 0], [0, 0, 1]])
    np.testing.assert_allclose(envmap.euler_xyz_matrix(rx, ry, rz), Rz @ Ry @ Rx, atol=1e-14)
    # X then Z by 90 degrees each: +Y -> +Z -> +Z ; +X -> +X -> +Y
    R = envmap.euler_xyz_matrix(q, 0, q)
    np.testing.assert_allclose(R @ [0, 1, 0], [0, 0, 1], atol=1e-12)
    np.testing.assert_allclose(R @ [1, 0, 0], [0, 1, 0], atol=1e-12)


# --------------------------------------------------------------------------- #
# envmap: WorldLighting / resampling
# --------------------------------------------------------------------------- #

def cube_energy(lighting, cube):
    return (lighting.radiance.astype(np.float64) * cube.solid_angles[:, None]).sum(axis=0)


def _sun_image(h, w, row, col, value=1e6):
    img = np.zeros((h, w, 3), np.float32)
    img[row, col] = value
    return img


@pytest.mark.parametrize("angles", [(0.0, 0.0, np.pi / 2), (0.4, -0.7, 2.5), (np.pi / 2, 0.0, 0.0)])
def test_rotation_moves_sun(angles):
    h, w, n = 512, 1024, 32
    row, col = 150, 600
    R = envmap.euler_xyz_matrix(*angles)
    img = _sun_image(h, w, row, col)
    wl = envmap.WorldLighting(img, rotation=R)
    cl = wl.to_cubemap(n)
    cube = directions.cubemap(n)
    t = pixel_centre_direction(row, col, h, w)         # texture-space sun
    d = R.T @ t                                         # world-space sun: L(d) = E(R d)
    k = int(cube.texel_index(d))
    e = cl.radiance[:, 0].astype(np.float64) * cube.solid_angles
    assert e[k] == pytest.approx(e.sum(), rel=1e-6)
    np.testing.assert_allclose(e.sum(), wl.total_power()[0], rtol=1e-6)
    assert np.degrees(np.arccos(np.clip(cl.unit_directions[k] @ d, -1, 1))) < 0.2
    assert float(wl.radiance(d)[0]) == pytest.approx(1e6)
    # unrotated world puts the sun elsewhere (for a non-trivial rotation)
    k0 = int(cube.texel_index(t))
    assert k0 != k


def test_uniform_world():
    wl = envmap.WorldLighting(None, color=(0.2, 0.5, 1.0), strength=2.0)
    cube = directions.cubemap(32)
    cl = wl.to_cubemap(32)
    np.testing.assert_allclose(cl.radiance, np.tile([0.4, 1.0, 2.0], (cube.size, 1)), rtol=1e-6)
    np.testing.assert_allclose(cl.directions, cube.mean_directions)
    np.testing.assert_allclose(wl.total_power(), 4 * np.pi * np.array([0.4, 1.0, 2.0]), rtol=1e-12)
    np.testing.assert_allclose(cube_energy(cl, cube), wl.total_power(), rtol=1e-6)
    rng = np.random.default_rng(2)
    np.testing.assert_allclose(wl.radiance(random_unit(rng, 10)),
                               np.tile([0.4, 1.0, 2.0], (10, 1)), rtol=1e-6)


@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_world_rejects_non_finite(bad):
    img = np.ones((8, 16, 3), np.float32)
    img[3, 4, 1] = bad
    with pytest.raises(envmap.EnvironmentError_):
        envmap.WorldLighting(img)
    assert envmap.count_non_finite(img) == 1
    with pytest.raises(envmap.EnvironmentError_):
        envmap.WorldLighting(None, strength=float(bad))


def test_world_clamps_negative_and_as_rgb():
    img = np.ones((4, 8, 4), np.float32)
    img[0, 0, 0] = -5.0
    wl = envmap.WorldLighting(img)
    assert wl.image.shape == (4, 8, 3) and wl.image.min() == 0.0
    grey = envmap.as_rgb(np.arange(6, dtype=np.float32).reshape(2, 3))
    assert grey.shape == (2, 3, 3)
    np.testing.assert_array_equal(grey[..., 0], grey[..., 2])


def test_load_equirect_roundtrip(tmp_path):
    oiio = pytest.importorskip("OpenImageIO")
    h, w = 6, 12
    rng = np.random.default_rng(9)
    img = rng.uniform(0, 100, size=(h, w, 3)).astype(np.float32)
    img[0, :, :] = 1000.0          # top row marker (zenith)
    img[-1, :, :] = 0.001
    path = tmp_path / "env.exr"
    out = oiio.ImageOutput.create(str(path))
    assert out is not None
    spec = oiio.ImageSpec(w, h, 3, "float")
    assert out.open(str(path), spec)
    assert out.write_image(img)
    out.close()
    back = envmap.load_equirect(str(path))
    assert back.dtype == np.float32 and back.shape == (h, w, 3)
    np.testing.assert_array_equal(back, img)
    # and the top row is the zenith for lighting
    wl = envmap.WorldLighting(back)
    assert float(wl.radiance(np.array([0.0, 0.0, 1.0]))[0]) == 1000.0
    # RGBA is reduced to RGB
    path4 = tmp_path / "env4.exr"
    out = oiio.ImageOutput.create(str(path4))
    img4 = np.concatenate([img, np.full((h, w, 1), 0.5, np.float32)], axis=2)
    assert out.open(str(path4), oiio.ImageSpec(w, h, 4, "float"))
    assert out.write_image(img4)
    out.close()
    np.testing.assert_array_equal(envmap.load_equirect(str(path4)), img)


def test_load_equirect_missing(tmp_path):
    pytest.importorskip("OpenImageIO")
    with pytest.raises(envmap.EnvironmentError_):
        envmap.load_equirect(str(tmp_path / "does_not_exist.exr"))

GREY = 128 / 255
GREY_LINEAR = ((GREY + 0.055) / 1.055) ** 2.4          # 0.21586


# --------------------------------------------------------------------------- core

def test_core_srgb_128_is_0_21586_and_non_color_is_identity():
    px = np.full((2, 4, 3), GREY, np.float32)
    lin = envmap.to_working_space(px, "sRGB")
    np.testing.assert_allclose(lin, 0.21586, atol=2e-5)
    np.testing.assert_allclose(lin, GREY_LINEAR, rtol=1e-6)
    np.testing.assert_array_equal(envmap.to_working_space(px, "Non-Color"), px)
    np.testing.assert_array_equal(envmap.to_working_space(px, "Linear Rec.709"), px)
    np.testing.assert_array_equal(envmap.to_working_space(px, "Filmic sRGB", is_data=True), px)
    # The curve's linear toe, its knee and values past 1 (float images).
    c = np.array([0.0, 0.04045, 0.5, 1.0, 2.0], np.float32)
    want = np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)
    np.testing.assert_allclose(envmap.srgb_to_linear(c), want, rtol=1e-6)


def test_core_other_spaces_without_a_config_are_refused_by_name():
    px = np.full((2, 4, 3), 0.5, np.float32)
    with pytest.raises(envmap.EnvironmentError_, match="'Filmic sRGB'"):
        envmap.to_working_space(px, "Filmic sRGB", config_path=None)
    with pytest.raises(envmap.EnvironmentError_, match="'sRGB'"):     # sRGB into Rec.2020
        envmap.to_working_space(px, "sRGB", "Linear Rec.2020", config_path=None)


def _energy(level):
    h = level.shape[0]
    edges = np.cos(np.linspace(0.0, np.pi, h + 1))
    band = (edges[:-1] - edges[1:]) * (2.0 * np.pi / level.shape[1])
    return np.einsum("h,hwc->c", band, level.astype(np.float64))


def _levels(atlas, sizes):
    row = 0
    for h, w in sizes:
        yield atlas[row:row + h, :w, :3]
        row += h


def test_mip_atlas_keeps_each_levels_energy():
    rng = np.random.default_rng(3)
    img = rng.random((64, 128, 3)).astype(np.float32) ** 4 * 10.0      # peaky
    sizes = envmap.equirect_mip_sizes(*img.shape[:2])
    atlas = envmap.equirect_mip_atlas(img)
    assert atlas.shape == (sum(h for h, _ in sizes), sizes[0][1], 4)
    assert sizes[-1][1] == 4
    for level in _levels(atlas, sizes):
        np.testing.assert_allclose(_energy(level), _energy(img), rtol=1e-6)
    odd = envmap.equirect_mip_atlas(img[:37, :70])          # odd sizes: shapes, finite
    assert odd.shape[0] == sum(h for h, _ in envmap.equirect_mip_sizes(37, 70))
    assert np.isfinite(odd).all() and odd.min() >= 0.0
    constant = envmap.equirect_mip_atlas(np.full((16, 32, 3), 0.7, np.float32))
    for level in _levels(constant, envmap.equirect_mip_sizes(16, 32)):
        np.testing.assert_allclose(level, 0.7, rtol=1e-6)


def test_a_turned_world_checks_its_image_once():
    """Worlds of one pixel array (every frame of a turned HDRI) share its checked pixels;
    new pixels are checked again (a NaN refused, negatives drawn as zero)."""
    img = np.ones((8, 16, 3), np.float32)
    a = envmap.WorldLighting(img, rotation=envmap.euler_xyz_matrix(0.0, 0.0, 0.3))
    b = envmap.WorldLighting(img, rotation=envmap.euler_xyz_matrix(0.0, 0.0, 1.1))
    assert a.image is b.image
    bad = img.copy()
    bad[2, 3, 0] = np.nan
    with pytest.raises(envmap.EnvironmentError_):
        envmap.WorldLighting(bad)
    negative = -img
    assert not envmap.WorldLighting(negative).image.any()
