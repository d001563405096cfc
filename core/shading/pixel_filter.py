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
"""

from __future__ import annotations

import numpy as np


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
