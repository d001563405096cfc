"""core.shading.pixel_filter: the supersampled frame's resolve with Cycles' Blackman-Harris filter."""

from __future__ import annotations

import numpy as np
import pytest

from prt_relight.core.shading import pixel_filter as pf


def test_blackman_harris_shape():
    w = 1.5
    assert pf.blackman_harris(0.0, w) == pytest.approx(1.0, abs=1e-12)   # the coefficients sum to 1
    x = np.linspace(-w, w, 101)
    f = pf.blackman_harris(x, w)
    assert np.allclose(f, f[::-1])                              # symmetric
    assert np.all(f[1:-1] > 0.0) and f[0] == 0.0 and f[-1] == 0.0  # support |x| < width
    assert np.all(np.diff(f[50:]) < 0)                          # falls off from the centre
    assert pf.blackman_harris(1.6, w) == 0.0
    # The 4-term window's value a third of the way out (offset w/3 of a half-width 2w/2).
    x = 2 * np.pi * (0.5 / 3.0 + 0.5)
    direct = 0.35875 - 0.48829 * np.cos(x) + 0.14128 * np.cos(2 * x) - 0.01168 * np.cos(3 * x)
    assert pf.blackman_harris(0.5, 1.5) == pytest.approx(direct)


def test_constant_frame_stays_constant_including_borders():
    img = np.full((5 * 3, 7 * 3, 4), 0.7, np.float32)
    out = pf.resolve(img, 3, 1.5)
    assert out.shape == (5, 7, 4)
    assert np.allclose(out, 0.7, atol=1e-6)


def test_zero_width_is_the_box_mean():
    rng = np.random.default_rng(1)
    img = rng.random((4 * 3, 6 * 3, 4)).astype(np.float32)
    box = img.reshape(4, 3, 6, 3, 4).mean(axis=(1, 3))
    assert np.allclose(pf.resolve(img, 3, 0.0), box, atol=1e-6)


def test_resolve_equals_a_brute_force_weighted_sum():
    """Each pixel is Σ f(dx) f(dy) sample / Σ f(dx) f(dy) over the samples inside the frame."""
    rng = np.random.default_rng(2)
    s, h, w, width = 3, 6, 5, 1.5
    img = rng.random((h * s, w * s, 2))
    out = pf.resolve(img, s, width)
    for y in range(h):
        for x in range(w):
            num, den = np.zeros(2), 0.0
            for j in range(h * s):
                for i in range(w * s):
                    dy = (j + 0.5) / s - (y + 0.5)
                    dx = (i + 0.5) / s - (x + 0.5)
                    wt = float(pf.blackman_harris(dx, width) * pf.blackman_harris(dy, width))
                    num += wt * img[j, i]
                    den += wt
            assert np.allclose(out[y, x], num / den, atol=1e-5), (y, x)


def test_a_width_reaching_no_sample_falls_back_to_the_pixel_box():
    img = np.arange(2 * 2 * 2 * 2, dtype=np.float32).reshape(4, 4, 1)
    # Samples sit at ±1/4 px from the centre; a 0.2 px filter reaches none of them.
    out = pf.resolve(img, 2, 0.2)
    assert np.allclose(out, img.reshape(2, 2, 2, 2, 1).mean(axis=(1, 3)))


def test_filter_spreads_an_isolated_bright_sample_to_the_neighbours():
    img = np.zeros((9 * 3, 9 * 3, 1), np.float32)
    img[13, 13] = 9.0                          # the centre sample of pixel (4, 4)
    box = pf.resolve(img, 3, 0.0)
    bh = pf.resolve(img, 3, 1.5)
    assert box[4, 4, 0] == pytest.approx(1.0) and box.sum() == pytest.approx(1.0)
    assert 0.0 < bh[4, 4, 0] < 1.0 and bh[3, 4, 0] > 0.0 and bh[5, 5, 0] > 0.0
    assert bh[2, 4, 0] == 0.0                   # 2 px away: outside the 1.5 px support


def _pilot(h=9, w=11, value=1.0):
    img = np.full((h, w, 4), value, np.float32)
    img[..., 3] = 1.0
    return img


def test_refine_mask_keeps_smooth_frames_and_grows_around_a_bright_pixel():
    flat = _pilot()
    assert not pf.refine_mask(flat).any()
    # a gentle gradient stays below the contrast threshold
    ramp = _pilot()
    ramp[..., :3] *= (1.0 + 0.01 * np.arange(11))[None, :, None]
    assert not pf.refine_mask(ramp).any()
    spot = _pilot()
    spot[4, 5, :3] = 3.0
    mask = pf.refine_mask(spot)
    # the pixel and its 8 neighbours differ; grown by one more pixel: a 5 x 5 block
    want = np.zeros(mask.shape, bool)
    want[2:7, 3:8] = True
    np.testing.assert_array_equal(mask, want)
    # relative contrast: the same frame ten times brighter gives the same mask
    np.testing.assert_array_equal(pf.refine_mask(10.0 * spot), mask)


def test_refine_mask_takes_silhouettes_and_bad_pixels():
    edge = _pilot()
    edge[:, 6:, 3] = 0.0                      # coverage ends: the object's silhouette
    mask = pf.refine_mask(edge)
    assert mask[:, 4:8].all() and not mask[:, :4].any() and not mask[:, 8:].any()
    bad = _pilot()
    bad[0, 0, 1] = np.nan
    assert pf.refine_mask(bad)[0, 0]
    # a threshold of 0 refines every pixel with any difference; a huge one only edges
    noisy = _pilot() + np.random.default_rng(1).normal(0, 0.01, (9, 11, 4)).astype(np.float32)
    noisy[..., 3] = 1.0
    assert pf.refine_mask(noisy, 0.0).all()
    assert not pf.refine_mask(noisy, 1.0).any()
