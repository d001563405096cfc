"""core.scene.shadow_fields (Zhou et al. 2005; Xu et al. 2006 §4.3.2, §5.1) against exact
ray casting with Embree: the static scene's grid field near its corners, the corners a point
sees, and an object's own visibility turned with it.

Every reference is an Embree cast of the same triangles (``query="OCCLUDED"``), made here
from the geometry, never an earlier output of the module.  No bpy."""


import numpy as np
import pytest

from prt_relight.core.sphere import directions
from prt_relight.core.scene import shadow_fields as sf
from prt_relight.core.scene.visibility import build_occluder_scene
from .occluders import L_BOXES, aabb, aabbs, cast, outside, quad, rotation


# --------------------------------------------------------------------------- helpers


# --------------------------------------------------------------------------- 3. static field

def _ground_and_wall():
    ground = quad((-3, -3, 0), (3, -3, 0), (3, 3, 0), (-3, 3, 0))
    wall = quad((0, -3, 0), (0, 3, 0), (0, 3, 2.5), (0, -3, 2.5))     # x = 0, up to 2.5
    return np.concatenate([ground, wall])


@pytest.fixture(scope="module")
def static_scene():
    tri = _ground_and_wall()
    cube = directions.cubemap(8)
    field = sf.build_static_field(tri, (-2, -2, 0), (2, 2, 2), cube, samples=300, threads=2)
    return tri, cube, field, build_occluder_scene(tri)


def test_static_field_near_corners_matches_exact(static_scene):
    """Static field is exact at its corners (indexing) and close to exact cast near them."""
    tri, cube, field, scene = static_scene
    pos = field.positions()
    assert len(pos) == np.prod(field.dims) == len(field.bits)
    ids, w = sf.static_corners(field, pos)
    vis = sf.static_visibility(field, ids, w)
    np.testing.assert_allclose(vis, ~cast(scene, pos, cube.directions), atol=1e-6)
    rng = np.random.default_rng(4)
    keep = (pos[:, 2] > 0) & (np.abs(pos[:, 0]) > 0.2 * field.spacing)
    p = pos[keep] + rng.uniform(-0.1, 0.1, (keep.sum(), 3)) * field.spacing
    ids, w = sf.static_corners(field, p)
    np.testing.assert_allclose(w.sum(1), 1.0, atol=1e-12)
    inside = ((p > pos.min(0)) & (p < pos.max(0))).all(1)       # not clamped to the grid
    assert inside.mean() > 0.5
    np.testing.assert_allclose(np.einsum("pc,pcj->pj", w, pos[ids])[inside], p[inside],
                               atol=1e-9)
    vis = sf.static_visibility(field, ids, sf.seen_corners(scene, field, p, ids, w))
    agree = ((vis >= 0.5) == ~cast(scene, p, cube.directions)).mean()
    assert agree >= 0.97, agree


def test_seen_corners_drops_corners_behind_wall_and_under_ground(static_scene):
    """Corners under the ground/behind the wall get weight 0, rest renormalised; blend improves."""
    tri, cube, field, scene = static_scene
    pos = field.positions()
    rng = np.random.default_rng(5)
    n = 200
    ground = np.c_[rng.uniform(-1.8, 1.8, (n, 2)), rng.uniform(0.01, 0.15, n)]
    wall = np.c_[rng.choice([-1.0, 1.0], n) * rng.uniform(0.01, 0.15, n),
                 rng.uniform(-1.8, 1.8, n), rng.uniform(0.3, 1.8, n)]
    for p in (ground, wall):
        ids, w = sf.static_corners(field, p)
        seen = sf.seen_corners(scene, field, p, ids, w)
        c = pos[ids]
        under = c[..., 2] < 0
        across = np.sign(c[..., 0]) != np.sign(p[:, None, 0])
        t = p[:, None, 0] / (p[:, None, 0] - c[..., 0])           # where x = 0 is crossed
        z = p[:, None, 2] + t * (c[..., 2] - p[:, None, 2])
        hidden = under | (across & (z > 0) & (z < 2.5))
        assert hidden.any(axis=1).mean() > 0.9
        want = np.where(hidden, 0.0, w)
        want /= want.sum(axis=1, keepdims=True)
        np.testing.assert_allclose(seen, want, atol=1e-9)
        exact = ~cast(scene, p, cube.directions)
        plain = sf.static_visibility(field, ids, w)
        blend = sf.static_visibility(field, ids, seen)
        assert np.abs(blend - exact).mean() < 0.5 * np.abs(plain - exact).mean()
        assert ((blend >= 0.5) == exact).mean() >= 0.92


def test_seen_corners_keeps_plain_weights_when_no_corner_is_seen(static_scene):
    """A point that sees no corner keeps the plain weights (no division by zero)."""
    tri, cube, field, _ = static_scene
    p = np.array([[0.7, 0.3, 0.9]])
    shut = build_occluder_scene(aabb(p[0] - 0.05, p[0] + 0.05))
    ids, w = sf.static_corners(field, p)
    np.testing.assert_array_equal(sf.seen_corners(shut, field, p, ids, w), w)


# --------------------------------------------------------------------------- 4. turned bits

def test_turned_bits_match_visibility_traced_at_turned_pose():
    """Bits turned by R match a trace at the turned pose (>= 97 %); turning by R^T does not."""
    boxes = L_BOXES + (((-1.0, -0.5, 0.3), (-0.8, 0.5, 0.8)),)
    tri = aabbs(boxes)
    rng = np.random.default_rng(7)
    pts = rng.uniform((-1.5, -1.0, -0.8), (1.5, 1.0, 1.6), (600, 3))
    pts = pts[outside(pts, boxes)][:150]
    cube = directions.cubemap(16)

    def traced(tri_, pts_):
        return np.packbits(~cast(build_occluder_scene(tri_), pts_, cube.directions), axis=1)

    def unpack(b):
        return np.unpackbits(b, axis=1, count=cube.size).astype(bool)

    bits0 = unpack(traced(tri, pts))
    assert (sf.turn_texels(cube, np.eye(3)) == np.arange(cube.size)).all()
    for seed in range(3):
        R = rotation(seed)
        now = unpack(traced(tri @ R.T, pts @ R.T))
        turned = unpack(sf.turned_bits(np.packbits(bits0, axis=1), cube, R))
        agree = (turned == now).mean()
        either = ~turned | ~now
        assert agree >= 0.97, (seed, agree)
        assert (turned == now)[either].mean() >= 0.9
        wrong = unpack(sf.turned_bits(np.packbits(bits0, axis=1), cube, R.T))
        assert (wrong == now).mean() < agree - 0.03
