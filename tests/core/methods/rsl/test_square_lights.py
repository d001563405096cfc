"""core.methods.rsl.square_lights (Xu, Jia, Hu, Tai 2006, §4.1): the light decomposition
keeps the energy and partitions the sphere into connected subregions, a one-pixel sun is one
tiny light, the error budget stops it, and each merge is Fig. 5's (against a brute-force
greedy merge).  No bpy."""

from __future__ import annotations

import time

import numpy as np
import pytest

from prt_relight.core.methods.rsl import square_lights
from prt_relight.core.sphere import directions, envmap

from .scenes import CUBE, sky_with_sun


def test_decomposition_preserves_energy_and_partitions_the_sphere():
    img = sky_with_sun()
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
    lighting = envmap.WorldLighting(image=sky_with_sun()).to_cubemap(32)
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
    img = sky_with_sun(h, w, sun=(row, col), sun_value=5.0e5)
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
    lighting = envmap.WorldLighting(image=sky_with_sun()).to_cubemap(32)
    f30 = square_lights.decompose(lighting, CUBE, 30).fit_error
    loose = square_lights.decompose(lighting, CUBE, None, error_budget=f30)
    tight = square_lights.decompose(lighting, CUBE, None, error_budget=f30 / 4)
    assert loose.fit_error <= f30 and tight.fit_error <= f30 / 4
    assert tight.count > loose.count >= 1
    assert loose.count <= 30
    assert square_lights.decompose(lighting, CUBE, 10, error_budget=1e9).count == 10


def test_decomposition_is_fast():
    """6x32² -> 30 lights; the bench prints the time, here only a generous bound."""
    lighting = envmap.WorldLighting(image=sky_with_sun()).to_cubemap(32)
    t0 = time.perf_counter()
    square_lights.decompose(lighting, CUBE, 30)
    assert time.perf_counter() - t0 < 10.0


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
