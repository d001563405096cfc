"""The cases the BLOCKS tests share: structured visibility maps, a random scene of vertices
under sharp lighting, and the materials (Blender-free)."""

from __future__ import annotations

import numpy as np

from prt_relight.core.shading import materials
from prt_relight.core.sphere.directions import cubemap
from prt_relight.core.sphere.envmap import CubeLighting


def structured_bits(n, rng, P=6):
    """Random + structured binary maps (P, 6N^2) bool, packed."""
    D = 6 * n * n
    maps = [np.zeros(D, bool), np.ones(D, bool)]
    f, r, c = np.meshgrid(np.arange(6), np.arange(n), np.arange(n), indexing="ij")
    maps.append(((r + c) % 2 == 0).reshape(-1))                    # checkerboard
    maps.append((r < n // 3).reshape(-1) | (f == 2).reshape(-1))   # horizon-like spans
    d = cubemap(n).directions
    maps.append(d[:, 2] > 0.2 * np.sin(7 * d[:, 0]))               # wavy horizon
    while len(maps) < P:
        maps.append(rng.random(D) < rng.uniform(0.05, 0.95))
    v = np.stack(maps)
    return v, np.packbits(v, axis=1)


def random_scene(n, rng, P=40):
    """Random vertices with hemisphere-limited, structured visibility and sharp lighting
    (a few very bright texels, like a sun)."""
    cube = cubemap(n)
    D = cube.size
    nrm = rng.normal(size=(P, 3))
    nrm[:, 2] = np.abs(nrm[:, 2]) + 0.3
    nrm /= np.linalg.norm(nrm, axis=1, keepdims=True)
    pos = rng.normal(size=(P, 3)) * 0.5
    d = cube.directions
    above = nrm @ d.T > 0.0
    wavy = d[None, :, 2] > 0.15 * np.sin(5 * d[None, :, 0] + rng.uniform(0, 6, (P, 1)))
    vis = above & (wavy | (rng.random((P, 1)) < 0.3))
    vis[0] = above[0]                                      # one fully open vertex
    rad = rng.random((D, 3)).astype(np.float32) * np.where(rng.random((D, 1)) < 0.01, 200.0, 1.0)
    dirs = d * rng.uniform(0.95, 1.0, (D, 1))               # mean light directions, |w| <= 1
    return pos, nrm, np.packbits(vis, axis=1), CubeLighting(rad.astype(np.float32), dirs)


MATERIALS = {
    "glossy beckmann": materials.Material(diffuse_albedo=(0.0, 0.0, 0.0), specular_color=(1.0, 0.9, 0.8),
                                     roughness=0.25, distribution="BECKMANN"),
    "principled": materials.principled_material(base_color=(0.7, 0.3, 0.2), roughness=0.3),
    "diffuse": materials.Material(diffuse_albedo=(0.8, 0.6, 0.4), specular_color=(0.0, 0.0, 0.0)),
    "metal f82": materials.Material(diffuse_albedo=(0.0, 0.0, 0.0), specular_color=(0.9, 0.6, 0.3),
                               roughness=0.35, distribution="MULTI_GGX", fresnel="F82",
                               f82_tint=(0.8, 0.9, 1.0)),
}
