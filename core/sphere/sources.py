"""Compact bright sources split off an environment (pure numpy).

Per-vertex transport over a 6N² cubemap cannot carry a sun's shadow edge or a softbox's
highlight; production renderers shade the few compact, bright sources per pixel with their
own visibility and the smooth remainder by precomputed transport.  This module makes the
split, in the equirect's texture space (a Mapping rotation turns the sources with the
world, no re-extraction):

* a pixel is *bright* when its luminance exceeds ``threshold`` times the environment's mean
  radiance (its total power over 4π);
* each connected group of bright pixels (8-neighbours, wrapping around in longitude) is a
  candidate; its *excess* ``S = I - T`` over the threshold level ``T`` (per pixel, the
  colour of the pixel scaled to luminance T) is its light;
* candidates are kept by the energy of their excess, largest first, while each carries at
  least ``min_share`` of the environment's energy and is compact (its disc's angular
  radius, below, at most ``max_radius``), up to ``max_sources``;
* the residual is ``I - S`` over the kept sources' pixels and ``I`` elsewhere, so
  ``residual + sources == image`` exactly and both are non-negative.

A source is drawn as a disc: its luminance-weighted mean direction, an angular radius with
the excess's spread about it (the energy-weighted mean squared angle of a uniform disc is
r²/2: a sun inside a wide glow is as small as its energy says), and the uniform RGB
radiance that gives the disc the excess's energy.  An overcast sky has no pixel over the
threshold: no source, and the residual is the image itself.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .envmap import equirect_directions

#: Rec. 709 luminance weights (as envmap's luminance-weighted directions)
LUMINANCE = np.array([0.2126, 0.7152, 0.0722])

#: defaults of :func:`extract_sources` (shown and overridable in the panel)
THRESHOLD = 8.0
MIN_SHARE = 0.01
MAX_SOURCES = 8
MAX_RADIUS = math.radians(8.0)


@dataclass
class Source:
    """One compact source in texture space (a world direction d reads it where
    ``R @ d`` is near :attr:`direction`)."""

    direction: np.ndarray        # (3,) unit, luminance-weighted mean of its pixels
    radius: float                # angular radius of the disc (rad)
    radiance: np.ndarray         # (3,) uniform radiance of the disc carrying its energy
    pixels: int                  # how many equirect pixels its excess covers
    pixel_solid_angle: float     # sr, of those pixels

    @property
    def solid_angle(self) -> float:
        """Of the disc: 2π(1 - cos r)."""
        return 2.0 * math.pi * (1.0 - math.cos(self.radius))

    @property
    def power(self) -> np.ndarray:
        """RGB energy ∫ L dω over the disc (irradiance at normal incidence, unshadowed)."""
        return self.radiance * self.solid_angle


def mask_components(mask: np.ndarray):
    """Labels of 8-connected groups of ``mask`` (H, W), wrapping in longitude (the
    equirect's left and right edges meet); 0 = not in the mask.  Union-find over runs."""
    h, w = mask.shape
    labels = np.zeros((h, w), np.int64)
    parent = [0]

    def find(a):
        while parent[a] != a:
            parent[a] = parent[parent[a]]
            a = parent[a]
        return a

    def union(a, b):
        ra, rb = find(a), find(b)
        if ra != rb:
            parent[max(ra, rb)] = min(ra, rb)

    for y in range(h):
        row = mask[y]
        if not row.any():
            continue
        xs = np.flatnonzero(row)
        # runs of consecutive columns
        breaks = np.flatnonzero(np.diff(xs) > 1)
        starts = np.concatenate([[0], breaks + 1])
        ends = np.concatenate([breaks, [len(xs) - 1]])
        for a, b in zip(starts, ends):
            x0, x1 = int(xs[a]), int(xs[b])
            parent.append(len(parent))
            lab = len(parent) - 1
            labels[y, x0:x1 + 1] = lab
            if y > 0:
                above = labels[y - 1, max(x0 - 1, 0):min(x1 + 2, w)]
                for other in np.unique(above[above > 0]):
                    union(lab, int(other))
                if x0 == 0 and labels[y - 1, w - 1] > 0:
                    union(lab, int(labels[y - 1, w - 1]))
                if x1 == w - 1 and labels[y - 1, 0] > 0:
                    union(lab, int(labels[y - 1, 0]))
        # a run touching both edges of the same row joins across the seam
        if row[0] and row[w - 1]:
            union(int(labels[y, 0]), int(labels[y, w - 1]))
    if len(parent) == 1:
        return labels
    roots = np.array([find(i) for i in range(len(parent))])
    return roots[labels]


def extract_sources(image: np.ndarray, threshold: float = THRESHOLD,
                    min_share: float = MIN_SHARE, max_sources: int = MAX_SOURCES,
                    max_radius: float = MAX_RADIUS):
    """Split an equirect ``image`` (H, W, 3), top row first, into compact sources and a
    residual image: ``(sources, residual)`` with ``residual + Σ sources' excess == image``.
    ``max_sources = 0`` keeps every pixel in the residual."""
    img = np.asarray(image, dtype=np.float32)
    h, w, _ = img.shape
    if max_sources <= 0 or h < 2 or w < 2:
        return [], img
    Y = img.astype(np.float64) @ LUMINANCE
    edges = np.cos(np.linspace(0.0, np.pi, h + 1))
    band = (edges[:-1] - edges[1:]) * (2.0 * np.pi / w)               # pixel solid angle
    total = float((Y * band[:, None]).sum())
    if not np.isfinite(total) or total <= 0.0:
        return [], img
    level = float(threshold) * total / (4.0 * np.pi)
    mask = Y > level
    if not mask.any():
        return [], img
    labels = mask_components(mask)
    ids, inverse = np.unique(labels[mask], return_inverse=True)
    rows, cols = np.nonzero(mask)
    # excess over the threshold level, in the pixel's own colour
    scale = np.where(Y[rows, cols] > 0.0, 1.0 - level / np.maximum(Y[rows, cols], 1e-300), 0.0)
    excess = img[rows, cols].astype(np.float64) * scale[:, None]
    sa = band[rows]
    energy = np.bincount(inverse, weights=(excess @ LUMINANCE) * sa, minlength=len(ids))
    area = np.bincount(inverse, weights=sa, minlength=len(ids))
    order = np.argsort(-energy, kind="stable")
    dirs, _ = equirect_directions(h, w, 1)
    residual = img.copy()
    sources = []
    for k in order:
        if len(sources) >= max_sources or energy[k] < min_share * total:
            break
        sel = inverse == k
        r, c = rows[sel], cols[sel]
        e = excess[sel]
        wgt = (e @ LUMINANCE) * sa[sel]
        mean = (dirs[r, c] * wgt[:, None]).sum(axis=0)
        norm = np.linalg.norm(mean)
        if norm <= 0.0:
            continue
        axis = mean / norm
        theta2 = np.arccos(np.clip(dirs[r, c] @ axis, -1.0, 1.0)) ** 2
        # a uniform disc of radius r has mean squared angle r^2 / 2; at least half a pixel
        radius = max(math.sqrt(2.0 * float((theta2 * wgt).sum() / wgt.sum())),
                     0.5 * math.pi / h)
        if radius > max_radius:
            continue
        disc = 2.0 * math.pi * (1.0 - math.cos(radius))
        rgb_energy = (e * sa[sel][:, None]).sum(axis=0)
        sources.append(Source(direction=axis, radius=radius, radiance=rgb_energy / disc,
                              pixels=int(sel.sum()), pixel_solid_angle=float(area[k])))
        residual[r, c] = (img[r, c].astype(np.float64) - e).astype(np.float32)
    np.maximum(residual, 0.0, out=residual)
    return sources, residual
