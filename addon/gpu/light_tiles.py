"""Screen tiles of the lamp pass's light list (addon/gpu/lights.py): with many lights, each
pixel loops over the lights that can reach its tile of the screen instead of all of them.

A light's reach is a world box: a spot's cone cut to the sphere around its apex that holds
the scene, clipped to the scene's box; an area lamp the scene's box unless all of it is
behind the lamp; a point lamp or a distant source the whole scene.  The box's corners are
projected by the frame's view-projection; the tiles its screen rectangle meets list the
light (a box reaching behind the camera: every tile).  ``lights_frag.glsl`` (LIGHT_TILES)
reads the list from a float texture: per tile a texel (its lights of each group: distant,
point and spot, area; lights.py's srcTex order) and the light indices four per texel, a
row of tiles per texture row, the last row's first texel (origin x, y of the viewport, tile
size, texels per tile)."""

from __future__ import annotations

import math

import numpy as np

#: lights from which the pass culls per tile (fewer: every pixel loops over all, one
#: texture read less per light)
TILED_FROM = 9
#: tile side in pixels (doubled while a row of tiles would pass the texture's width)
TILE = 16
TEXTURE_SIDE = 16384


def spot_box(apex, axis, cos_half, reach) -> tuple[np.ndarray, np.ndarray]:
    """The world box of a cone (``apex``, unit ``axis``, half angle acos ``cos_half``) cut
    to the ball of radius ``reach`` about its apex: per world axis the cap's extreme
    directions, cos(max(angle to the axis - half angle, 0))."""
    half = math.acos(max(-1.0, min(1.0, cos_half)))
    ang = np.arccos(np.clip(np.asarray(axis, np.float64), -1.0, 1.0))    # to +x, +y, +z
    hi = np.cos(np.maximum(ang - half, 0.0))
    lo = -np.cos(np.maximum(math.pi - ang - half, 0.0))
    apex = np.asarray(apex, np.float64)
    return apex + reach * np.minimum(lo, 0.0), apex + reach * np.maximum(hi, 0.0)


def _corners(lo, hi) -> np.ndarray:
    return np.array([[(lo, hi)[i >> k & 1][k] for k in range(3)] for i in range(8)])


def influence_boxes(sources, lo, hi) -> list:
    """Per source (``addon.frame.sources.DrawnSource``, in the pass's order) the world box
    (lo, hi) it can light within the scene's box ``lo``, ``hi``, None for all of it, or an
    empty box (lo > hi) where it lights nothing."""
    lo, hi = np.asarray(lo, np.float64), np.asarray(hi, np.float64)
    out = []
    for s in sources:
        if not s.local:
            out.append(None)
        elif s.area is not None:
            behind = (_corners(lo, hi) - s.position) @ s.direction <= 0.0
            out.append((hi, lo) if behind.all() else None)
        elif s.spot is not None:
            reach = float(np.max(np.linalg.norm(_corners(lo, hi) - s.position, axis=1)))
            a, b = spot_box(s.position, s.spot[0], float(s.spot[1]), reach)
            out.append((np.maximum(a, lo), np.minimum(b, hi)))
        else:
            out.append(None)
    return out


def screen_rects(boxes, view_projection, width, height) -> np.ndarray:
    """(N, 4) pixel rectangles (x0, y0, x1, y1), inclusive, of the boxes projected to a
    ``width`` × ``height`` viewport; x0 > x1 where a box is empty or off screen."""
    M = np.asarray(view_projection, np.float64)
    out = np.tile(np.array([0, 0, width - 1, height - 1], np.int64), (len(boxes), 1))
    for k, box in enumerate(boxes):
        if box is None:
            continue
        lo, hi = box
        if np.any(lo > hi):
            out[k] = (1, 1, 0, 0)
            continue
        clip = np.c_[_corners(lo, hi), np.ones(8)] @ M.T
        if np.any(clip[:, 3] <= 1e-6 * np.abs(clip[:, :3]).max()):
            continue                          # reaches behind the camera: every tile
        ndc = clip[:, :2] / clip[:, 3:4]
        x = (np.array([ndc[:, 0].min(), ndc[:, 0].max()]) + 1.0) * 0.5 * width
        y = (np.array([ndc[:, 1].min(), ndc[:, 1].max()]) + 1.0) * 0.5 * height
        # a pixel whose centre is in the rectangle, one pixel of margin
        out[k] = (max(int(math.floor(x[0])) - 1, 0), max(int(math.floor(y[0])) - 1, 0),
                  min(int(math.ceil(x[1])) + 1, width - 1),
                  min(int(math.ceil(y[1])) + 1, height - 1))
    return out


def tile_table(rects, width, height, groups, origin=(0, 0)) -> np.ndarray:
    """The LIGHT_TILES texture (rows, texels, 4) float32 of the lights' pixel ``rects``,
    whose ``groups`` (counts: distant, point and spot, area) follow one another."""
    n = len(rects)
    assert sum(groups) == n, (groups, n)
    tile = TILE
    while True:
        tx, ty = -(-width // tile), -(-height // tile)
        member = np.zeros((ty, tx, n), bool)
        for k, (x0, y0, x1, y1) in enumerate(rects):
            if x0 <= x1 and y0 <= y1:
                member[y0 // tile:y1 // tile + 1, x0 // tile:x1 // tile + 1, k] = True
        counts = member.sum(-1)
        stride = 1 + -(-int(counts.max(initial=0)) // 4)
        if tx * stride <= TEXTURE_SIDE and ty < TEXTURE_SIDE:
            break
        tile *= 2
    table = np.full((ty + 1, tx, stride * 4), -1.0, np.float32)
    ends = np.cumsum(groups)
    for g in range(3):                      # each group's lights in the tile
        table[:ty, :, g] = member[..., ends[g] - groups[g]:ends[g]].sum(-1)
    # each tile's members first, in the pass's order (a stable sort of "not a member")
    order = np.argsort(~member, axis=-1, kind="stable")[..., :(stride - 1) * 4]
    order = np.where(np.arange(order.shape[-1]) < counts[..., None], order, -1)
    table[:ty, :, 4:4 + order.shape[-1]] = order
    table[ty, 0, :4] = (origin[0], origin[1], tile, stride)
    return table.reshape(ty + 1, tx * stride, 4)
