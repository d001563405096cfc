"""addon.gpu.light_tiles: a spot's box holds its cone, and every point a light can reach
falls in a screen tile whose list names it (the per-tile culling drops no light)."""

from __future__ import annotations

import math

import numpy as np

from prt_relight.addon.frame import sources
from prt_relight.addon.gpu import light_tiles
from prt_relight.core.sg.lamp_lobes import Lamp


def _cone_points(rng, apex, axis, cos_half, reach, n):
    d = rng.normal(size=(n * 20, 3))
    d /= np.linalg.norm(d, axis=1)[:, None]
    d = d[d @ axis > cos_half][:n]
    return apex + d * (reach * rng.uniform(0.0, 1.0, len(d)) ** (1 / 3))[:, None]


def test_a_spot_box_holds_its_cone():
    rng = np.random.default_rng(5)
    for _ in range(100):
        axis = rng.normal(size=3)
        axis /= np.linalg.norm(axis)
        cos_half = math.cos(rng.uniform(0.05, 1.5))
        apex = rng.normal(size=3)
        lo, hi = light_tiles.spot_box(apex, axis, cos_half, 3.0)
        p = _cone_points(rng, apex, axis, cos_half, 3.0, 300)
        assert (p >= lo - 1e-9).all() and (p <= hi + 1e-9).all()


def _perspective(eye, target, fov=1.0, aspect=4 / 3, near=0.1, far=100.0):
    f = np.asarray(target, float) - eye
    f /= np.linalg.norm(f)
    r = np.cross(f, [0.0, 0.0, 1.0])
    r /= np.linalg.norm(r)
    u = np.cross(r, f)
    V = np.eye(4)
    V[0, :3], V[1, :3], V[2, :3] = r, u, -f
    V[:3, 3] = -V[:3, :3] @ eye
    t = 1.0 / math.tan(fov / 2)
    P = np.zeros((4, 4))
    P[0, 0], P[1, 1] = t / aspect, t
    P[2, 2], P[2, 3], P[3, 2] = -(far + near) / (far - near), -2 * far * near / (far - near), -1
    return P @ V


def test_every_point_a_light_reaches_is_in_a_tile_that_lists_it():
    """A sun, 40 spots of random cones, a point lamp and area lamps over a 10 m room seen in
    perspective: a point of the room inside a spot's cone (or in front of an area lamp)
    projects into a tile whose list holds the light, and the lists are shorter than all.
    The lights come in the pass's groups (the sun, the point and spot lamps, the area
    lamps): each tile counts its lights per group, listed in that order."""
    rng = np.random.default_rng(7)
    lo, hi = np.array([-5.0, -5.0, 0.0]), np.array([5.0, 5.0, 2.0])
    lamps = [Lamp("SPOT", position=(*rng.uniform(-5, 5, 2), 3.0),
                  direction=(*rng.normal(0, 0.4, 2), -1.0), spot_size=rng.uniform(0.2, 2.5))
             for _ in range(40)]
    lamps = [Lamp("SUN", direction=(0.2, 0.1, -1.0))] + lamps
    lamps += [Lamp("POINT", position=(1.0, 1.0, 2.5)),
              Lamp("AREA", position=(0.0, 0.0, 2.5), direction=(0.3, 0.0, -1.0),
                   half_x=(0.5, 0, 0), half_y=(0, 0.5, 0)),
              Lamp("AREA", position=(0.0, 0.0, 3.0), direction=(0.0, 0.0, 1.0),
                   half_x=(0.5, 0, 0), half_y=(0, 0.5, 0))]
    drawn = sources.lamp_sources(lamps)
    boxes = light_tiles.influence_boxes(drawn, lo, hi)
    assert boxes[-3] is None and boxes[-2] is None
    assert np.any(boxes[-1][0] > boxes[-1][1])                     # the upward one: nothing
    M = _perspective(np.array([0.0, -9.0, 5.0]), (0.0, 0.0, 0.5))
    w, h = 160, 120
    groups = (1, 41, 2)
    table = light_tiles.tile_table(light_tiles.screen_rects(boxes, M, w, h), w, h, groups)
    x0, y0, tile, stride = table[-1, 0]
    tile, stride = int(tile), int(stride)
    for k, s in enumerate(drawn):
        p = rng.uniform(lo, hi, size=(4000, 3))
        if s.spot is not None:
            p = p[(p - s.position) @ s.spot[0] > s.spot[1] * np.linalg.norm(p - s.position,
                                                                            axis=1)]
        elif s.area is not None:
            p = p[(p - s.position) @ s.direction > 0.0]
        clip = np.c_[p, np.ones(len(p))] @ M.T
        ndc = clip[:, :2] / clip[:, 3:4]
        seen = (np.abs(ndc) < 1.0).all(1) & (clip[:, 3] > 0)
        px = ((ndc[seen] + 1.0) * 0.5 * (w, h)).astype(int)
        for x, y in px:
            cell = table[y // tile, (x // tile) * stride:(x // tile + 1) * stride]
            count = cell[0, :3].astype(int)
            listed = cell[1:].reshape(-1)[:count.sum()].astype(int)
            assert k in listed, (k, x, y)
            # each group's lights in its own run: the sun, the local lamps, the areas
            assert count[0] == 1 and listed[0] == 0, (x, y)
            assert np.all((listed[1:1 + count[1]] >= 1) & (listed[1:1 + count[1]] < 42))
            assert np.all(listed[1 + count[1]:] >= 42), (x, y)
    # the lists are shorter than all the lights where spots are apart; the downward area
    # lamp reaches every tile, the upward one none
    counts = table[:-1, ::stride, :3].sum(-1)
    assert counts.mean() < 0.8 * len(drawn)
    assert np.all(table[:-1, ::stride, 2] == 1)
