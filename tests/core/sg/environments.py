"""The cubemap environments the SG lighting and prefilter tests share: a smooth sky of two SG
lights over a gradient, the same with a one-texel sun, and random unit directions
(Blender-free)."""

from __future__ import annotations

import numpy as np

from prt_relight.core.sg import algebra as sg


def smooth_env(cube):
    """Radiance (size, 3) at the texels of ``cube`` (anything with ``directions`` and
    ``size``): a constant, two SG lights (sharpness 40 and 5) and a sky gradient."""
    d = np.asarray(cube.directions)
    L = np.zeros((cube.size, 3)) + [0.05, 0.07, 0.1]
    L += sg.evaluate(d, np.array([0.3, 0.2, 0.93]) / np.linalg.norm([0.3, 0.2, 0.93]), 40.0, 3.0)[:, None] * [1, 0.8, 0.6]
    L += sg.evaluate(d, np.array([-0.6, 0.5, 0.6]) / np.linalg.norm([-0.6, 0.5, 0.6]), 5.0, 0.5)[:, None] * [0.3, 0.5, 1]
    L += np.maximum(d[:, 2:3], 0) * [0.2, 0.3, 0.5]           # sky gradient
    return L


def sun_env(cube, radiance=2e4):
    """The smooth sky dimmed to 0.3 with a one-texel sun of ``radiance``."""
    L = smooth_env(cube) * 0.3
    k = cube.texel_index(np.array([0.5, -0.5, 0.707]))
    L[k] += radiance
    return L


def random_dirs(n, seed):
    """``n`` random unit vectors (isotropic)."""
    p = np.random.default_rng(seed).normal(size=(n, 3))
    return p / np.linalg.norm(p, axis=1, keepdims=True)
