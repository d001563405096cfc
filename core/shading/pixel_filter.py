"""Pixel reconstruction filter for supersampled frames (Cycles' Blackman-Harris).

A supersampled frame (``s`` × ``s`` samples per pixel, sample centres at
``(k + 1/2) / s`` in pixel units) is resolved to pixels by a separable filter.  Cycles'
default pixel filter is Blackman-Harris with *Filter Width* ``w`` = 1.5 px, and its
support is ``|x| < w`` on each axis (Cycles' ``filter_table`` doubles the width it hands
to the window function), so a pixel also takes samples from its neighbours.  A plain
``s × s`` box mean differs from that wherever the image has detail at the pixel scale:
a glossy highlight on a finely tessellated mesh, a shadow edge, a silhouette. Resolving
with the same filter makes an F12 frame comparable with Cycles pixel by pixel.

``width <= 0`` keeps the box mean over each pixel's own samples.

Adaptive anti-aliasing (:func:`refine_mask`): a pilot frame of one sample per pixel tells
which pixels need their ``s × s`` samples (edges, silhouettes, highlights, texture detail:
where a pixel differs from a neighbour); the others keep the pilot's sample for all of
theirs, so the expensive per-pixel passes run on a fraction of the samples.
"""

from __future__ import annotations

import numpy as np

from ..scene.textures import LUMINANCE

#: the relative luminance contrast |a - b| / (a + b) between neighbouring pilot pixels above
#: which both are drawn with every sample (addon: scene.prt.aa_threshold's default)
REFINE_THRESHOLD = 0.05
#: contrast is measured above this share of the frame's mean luminance (noise in the dark)
DARK_FLOOR = 1e-3


def blackman_harris(offset, width: float) -> np.ndarray:
    """Cycles' Blackman-Harris pixel filter at ``offset`` pixels from the pixel centre,
    for Filter Width ``width`` (support ``|offset| < width``), unnormalised."""
    v = np.asarray(offset, dtype=np.float64)
    x = 2.0 * np.pi * (v / (2.0 * width) + 0.5)
    f = 0.35875 - 0.48829 * np.cos(x) + 0.14128 * np.cos(2.0 * x) - 0.01168 * np.cos(3.0 * x)
    return np.where(np.abs(v) < width, f, 0.0)


def resolve_taps(pixels: int, samples_per_pixel: int, width: float):
    """One axis of the filter as taps: ``(margin, weights)``, pixel ``p`` taking samples
    ``p·s − margin + t`` for ``t < T`` with ``weights[p, t]`` ((pixels, T) float32, each row
    summing to 1).  Samples beyond the frame do not exist (weight 0: border pixels
    renormalise over the samples inside it); a width too small to reach any sample falls
    back to the pixel's own box.  The GPU's resolve (addon/gpu/drawing.py) reads these."""
    s = max(1, int(samples_per_pixel))
    margin = int(np.ceil(width * s)) if width > 0.0 else 0
    p = np.arange(int(pixels))[:, None]
    j = p * s - margin + np.arange(s + 2 * margin)[None, :]
    inside = (j >= 0) & (j < int(pixels) * s)
    own = (np.floor_divide(j, s) == p) & inside
    if width > 0.0:
        w = blackman_harris((j + 0.5) / s - (p + 0.5), float(width))
        w = np.where(inside, np.clip(w, 0.0, None), 0.0)
        empty = w.sum(axis=1) <= 0.0
        w[empty] = own[empty]
    else:
        w = own.astype(np.float64)
    return margin, (w / w.sum(axis=1, keepdims=True)).astype(np.float32)


def _filter_axis(image: np.ndarray, axis: int, s: int, width: float) -> np.ndarray:
    pixels = image.shape[axis] // s
    margin, weights = resolve_taps(pixels, s, width)
    shape = [1] * image.ndim
    shape[axis] = pixels
    out = 0.0
    for t in range(weights.shape[1]):
        idx = np.clip(np.arange(pixels) * s - margin + t, 0, image.shape[axis] - 1)
        out = out + np.take(image, idx, axis=axis) * weights[:, t].reshape(shape)
    return out


def resolve(image: np.ndarray, samples_per_pixel: int, width: float) -> np.ndarray:
    """(H·s, W·s, C) supersampled frame → (H, W, C) pixels with the filter above, on the
    CPU (a data pass; the frame itself is resolved on the GPU with the same taps)."""
    s = max(1, int(samples_per_pixel))
    image = np.asarray(image, dtype=np.float32)
    return _filter_axis(_filter_axis(image, 0, s, width), 1, s, width).astype(np.float32)


def refine_mask(pilot: np.ndarray, threshold: float = REFINE_THRESHOLD) -> np.ndarray:
    """Which pixels of a one-sample pilot frame (H, W, 4) to draw with every sample, (H, W)
    bool: those whose luminance differs from one of their 8 neighbours' by a relative
    contrast ``|a - b| / (a + b + floor)`` above ``threshold`` (``floor``: DARK_FLOOR of the
    frame's mean) or whose coverage (alpha) differs, grown by one pixel (the pixel filter
    reaches the neighbours' samples).  Non-finite pixels are always refined."""
    img = np.asarray(pilot, dtype=np.float32)
    y = np.nan_to_num(np.maximum(img[..., :3] @ LUMINANCE.astype(np.float32), 0.0),
                      posinf=np.float32(3e38))
    cov = np.nan_to_num(img[..., 3])
    floor = np.float32(DARK_FLOOR * max(float(y.mean()), 1e-12))
    flag = ~np.isfinite(img).all(axis=-1)
    H, W = y.shape
    for dy, dx in ((0, 1), (1, 0), (1, 1), (1, -1)):
        # pairs (i, j) -- (i + dy, j + dx) inside the frame
        a = (slice(0, H - dy), slice(max(0, -dx), W - max(0, dx)))
        b = (slice(dy, H), slice(max(0, dx), W - max(0, -dx)))
        ya, yb = y[a], y[b]
        hit = (np.abs(ya - yb) > threshold * (ya + yb + floor)) | (cov[a] != cov[b])
        flag[a] |= hit
        flag[b] |= hit
    grown = flag.copy()
    for dy in (-1, 0, 1):
        for dx in (-1, 0, 1):
            src = flag[max(0, -dy):H - max(0, dy), max(0, -dx):W - max(0, dx)]
            grown[max(0, dy):H - max(0, -dy), max(0, dx):W - max(0, -dx)] |= src
    return grown
