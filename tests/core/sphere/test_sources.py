"""Compact sources split off the environment (core/sphere/sources.py): the split itself, without
Blender.  The per-pixel pass is tested in tests/addon/gpu/test_lights.py."""

from __future__ import annotations

import math

import numpy as np

from prt_relight.core.sphere import envmap, sources as lights


def _sky(h=128, w=256):
    """A smooth overcast-like sky: brighter at the zenith, dim below the horizon."""
    theta = (np.arange(h) + 0.5) / h * np.pi
    rows = 0.2 + 0.8 * np.clip(np.cos(theta), 0.0, 1.0)
    return np.repeat(rows[:, None, None] * np.array([[[0.7, 0.8, 1.0]]]), w, axis=1) \
        .astype(np.float32)


def _solid_angles(h, w):
    edges = np.cos(np.linspace(0.0, np.pi, h + 1))
    return ((edges[:-1] - edges[1:]) * (2.0 * np.pi / w))[:, None, None]


def _energy(img):
    return (img.astype(np.float64) * _solid_angles(*img.shape[:2])).sum(axis=(0, 1))


def _pixel_direction(h, w, row, col):
    dirs, _ = envmap.equirect_directions(h, w, 1)
    return dirs[row, col]


def _angle(a, b):
    return math.degrees(math.acos(min(1.0, float(np.dot(a, b) / np.linalg.norm(a)
                                               / np.linalg.norm(b)))))


def test_an_overcast_sky_has_no_source_and_stays_as_it_is():
    sky = _sky()
    sources, residual = lights.extract_sources(sky)
    assert sources == [] and residual is sky


def test_a_one_pixel_sun_is_one_source_in_its_direction_and_the_split_is_exact():
    sky = _sky()
    img = sky.copy()
    img[30, 70] = (2e4, 1.9e4, 1.7e4)
    sources, residual = lights.extract_sources(img)
    assert len(sources) == 1
    s = sources[0]
    assert _angle(s.direction, _pixel_direction(128, 256, 30, 70)) < 1e-6
    assert s.pixels == 1 and s.radius < math.radians(1.0)
    # residual + the source's energy is the image's, channel by channel; nothing negative
    np.testing.assert_allclose(_energy(residual) + s.power, _energy(img), rtol=1e-6)
    assert residual.min() >= 0.0
    np.testing.assert_array_equal(residual[np.arange(128) != 30], img[np.arange(128) != 30])
    # the clipped pixel keeps its colour at the threshold's luminance
    mean = (_energy(img) @ lights.LUMINANCE) / (4.0 * math.pi)
    np.testing.assert_allclose(residual[30, 70] @ lights.LUMINANCE, 8.0 * mean, rtol=1e-5)


def test_a_softbox_has_its_angular_size():
    """A uniform disc of 6 degrees radius over a dim sky: one source of about that radius
    (the mean squared angle of a uniform disc is r^2 / 2) and its excess energy."""
    h, w = 256, 512
    img = _sky(h, w) * 0.1
    dirs, _ = envmap.equirect_directions(h, w, 1)
    axis = np.array([0.3, -0.4, 0.866])
    axis /= np.linalg.norm(axis)
    inside = dirs @ axis > math.cos(math.radians(6.0))
    img[inside] = 40.0
    sources, residual = lights.extract_sources(img)
    assert len(sources) == 1
    s = sources[0]
    assert _angle(s.direction, axis) < 0.3
    assert abs(math.degrees(s.radius) - 6.0) < 0.6
    np.testing.assert_allclose(_energy(residual) + s.power, _energy(img), rtol=1e-6)


def test_sources_are_kept_by_energy_share_and_compactness():
    h, w = 128, 256
    img = _sky(h, w) * 0.05
    img[20, 10] = 5e3            # the strongest
    img[40, 200] = 2e3
    img[60, 100] = 3.0           # bright but a negligible share of the energy
    sources, _ = lights.extract_sources(img)
    assert [s.pixels for s in sources] == [1, 1]
    assert _angle(sources[0].direction, _pixel_direction(h, w, 20, 10)) < 1e-6
    one, _ = lights.extract_sources(img, max_sources=1)
    assert len(one) == 1 and _angle(one[0].direction, sources[0].direction) < 1e-9
    none, residual = lights.extract_sources(img, max_sources=0)
    assert none == [] and residual is img
    # a wide bright region is not compact: it stays in the residual
    wide = _sky(h, w) * 0.05
    wide[10:40, :] = 50.0
    assert lights.extract_sources(wide)[0] == []


def test_a_source_across_the_seam_is_one_source():
    """The equirect's left and right columns are neighbours."""
    h, w = 64, 128
    img = _sky(h, w) * 0.05
    img[20:23, :2] = 1e3
    img[20:23, -2:] = 1e3
    sources, _ = lights.extract_sources(img)
    assert len(sources) == 1 and sources[0].pixels == 12
    # its direction is at u = 0 (the -X half-plane's seam: atan2(y, x) = pi)
    assert sources[0].direction[0] < -0.8 and abs(sources[0].direction[1]) < 1e-6


def test_components_join_diagonals_and_wrap():
    mask = np.zeros((5, 8), bool)
    mask[1, 1] = mask[2, 2] = True           # diagonal neighbours
    mask[3, 0] = mask[3, 7] = True           # across the seam
    mask[0, 5] = True                        # alone
    labels = lights.mask_components(mask)
    assert labels[1, 1] == labels[2, 2] != 0
    assert labels[3, 0] == labels[3, 7] != 0
    assert len({labels[1, 1], labels[3, 0], labels[0, 5]}) == 3
    assert (labels[~mask] == 0).all()
