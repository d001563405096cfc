"""core.scene.shadow_fields against exact ray casting with Embree: the occluder field's eq. 9
fractions, its PCA, the static scene's grid field, and an object's own visibility turned.

Every reference is an Embree cast of the same triangles (``query="OCCLUDED"``), made here
from the geometry, never an earlier output of the module.  Layouts and cubemaps are small
so the file runs in seconds on two cores.
"""

import math

import numpy as np
import pytest

from prt_relight.core.sphere import directions
from prt_relight.core.scene import shadow_fields as sf
from prt_relight.core.scene import occluder_fields
from prt_relight.core.scene.distance_tables import visibility_distance_table
from prt_relight.core.scene.visibility import build_occluder_scene

# --------------------------------------------------------------------------- helpers

#: An L-shaped occluder (a slab and a post on one end): non-convex, off-centre.
L_BOXES = (((-1.0, -0.5, -0.3), (1.0, 0.5, 0.3)), ((0.5, -0.5, 0.3), (1.0, 0.5, 1.2)))


def _box(lo, hi):
    """(12, 3, 3) triangles of the axis-aligned box ``[lo, hi]``."""
    c = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1])
                  for z in (lo[2], hi[2])], dtype=np.float64)
    quads = [(0, 1, 3, 2), (4, 6, 7, 5), (0, 4, 5, 1), (2, 3, 7, 6), (0, 2, 6, 4), (1, 5, 7, 3)]
    return np.array([[c[q[0]], c[q[i]], c[q[i + 1]]] for q in quads for i in (1, 2)])


def _boxes(boxes):
    return np.concatenate([_box(lo, hi) for lo, hi in boxes])


def _quad(a, b, c, d):
    return np.array([[a, b, c], [a, c, d]], dtype=np.float64)


def _outside(points, boxes, pad=0.02):
    """Mask of the points outside every box (with a little padding)."""
    inside = np.zeros(len(points), bool)
    for lo, hi in boxes:
        inside |= ((points > np.asarray(lo) - pad) & (points < np.asarray(hi) + pad)).all(1)
    return ~inside


def _rotation(seed):
    """A random rotation matrix (uniform unit quaternion)."""
    q = np.random.default_rng(seed).normal(size=4)
    w, x, y, z = q / np.linalg.norm(q)
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                     [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                     [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])


def _cast(scene, origins, dirs):
    """(P, D) bool, True where the ray from each origin along each direction is blocked."""
    P, D = len(origins), len(dirs)
    org = np.repeat(np.asarray(origins, np.float32), D, axis=0)
    d = np.ascontiguousarray(np.tile(np.asarray(dirs, np.float32), (P, 1)))
    return (np.asarray(scene.run(org, d, query="OCCLUDED")) != -1).reshape(P, D)


def _texel_rays(res, sub):
    """(6 res², sub², 3) directions of a sub x sub grid inside every cubemap texel (same
    face axes and order as :func:`directions.cubemap`), and (6 res², sub²) weights
    proportional to the solid angle each sub-square covers (summing to one per texel)."""
    k = (np.arange(sub) + 0.5) / sub
    c = -1.0 + 2.0 * (np.arange(res)[:, None] + k[None]) / res        # (res, sub)
    t, s = np.broadcast_arrays(c[:, None, :, None], c[None, :, None, :])  # row, col, sub, sub
    A = directions.FACE_AXES[:, None, None, None, None]
    d = A[..., 0, :] + s[None, ..., None] * A[..., 1, :] + t[None, ..., None] * A[..., 2, :]
    d /= np.linalg.norm(d, axis=-1, keepdims=True)
    w = np.broadcast_to((1.0 + s * s + t * t) ** -1.5, (6,) + s.shape).reshape(-1, sub * sub)
    return d.reshape(-1, sub * sub, 3), w / w.sum(axis=1, keepdims=True)


def _exact_fractions(scene, points, res, sub=4):
    """(P, 6 res²) exact visible fraction of every cubemap texel seen from each point
    (``sub²`` rays per texel, weighted by solid angle)."""
    dirs, w = _texel_rays(res, sub)
    blocked = _cast(scene, points, dirs.reshape(-1, 3)).reshape(len(points), -1, sub * sub)
    return 1.0 - (blocked * w[None]).sum(axis=-1)


def _texel_radius(cube):
    """Largest angle between a texel's centre and its corners (radians)."""
    n = cube.resolution
    e = np.linspace(-1.0, 1.0, n + 1)
    m = 0.5 * (e[:-1] + e[1:])

    def unit(a, b):
        v = np.stack(np.broadcast_arrays(a, b, 1.0), -1)
        return v / np.linalg.norm(v, axis=-1, keepdims=True)

    corner, centre = unit(e[:, None], e[None, :]), unit(m[:, None], m[None, :])
    cos = np.minimum.reduce([np.sum(centre * corner[a:n + a, b:n + b], -1)
                             for a in (0, 1) for b in (0, 1)])
    return float(np.arccos(cos.min()))


@pytest.fixture(scope="module")
def l_field():
    """The L occluder's field: 16 shells as in Xu et al. 2006 §5.1 (fewer shells blur the
    silhouette between shells), otherwise small."""
    tri = _boxes(L_BOXES)
    layout = occluder_fields.FieldLayout(shells=16, face=8, map=16, eigen=8)
    return tri, occluder_fields.build_occluder_field(tri, layout, threads=2)


# --------------------------------------------------------------------------- 1. occluder field

def test_occluder_fractions_match_exact_cast(l_field):
    """Eq. 9 fractions at 0.5-5 r match exact texel casts: the method's accuracy claim."""
    tri, field = l_field
    scene = build_occluder_scene(tri)
    rng = np.random.default_rng(1)
    u = rng.normal(size=(400, 3))
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    d = field.radius * np.exp(rng.uniform(math.log(0.5), math.log(5.0), len(u)))
    pts = field.centre + u * d[:, None]
    pts = pts[_outside(pts, L_BOXES)][:100]
    cube = directions.cubemap(8)
    exact = _exact_fractions(scene, pts, 8)
    pi, ki, frac = occluder_fields.occluder_fractions(field, pts, cube.directions,
                                         occluder_fields.texel_half_sides(cube),
                                         margin=_texel_radius(cube))
    ex = exact[pi, ki]
    # the pairs that matter: blocked at least a little in the exact cast or in the field
    matter = (ex < 0.999) | (frac < 0.999)
    assert matter.sum() > 2000
    agree = ((ex < 0.5) == (frac < 0.5))[matter].mean()
    assert agree >= 0.90, agree
    # a field that blocks nothing would score far lower on the same pairs
    assert (ex >= 0.5)[matter].mean() < 0.7
    assert np.abs(ex - frac)[matter].mean() < 0.16
    assert np.abs(ex - frac).mean() < 0.09


def test_occluder_pairs_cover_every_blocked_texel(l_field):
    """No blocked texel lies outside the cone pairs (else its shadow is silently lost)."""
    tri, field = l_field
    scene = build_occluder_scene(tri)
    rng = np.random.default_rng(2)
    u = rng.normal(size=(200, 3))
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    d = field.radius * np.exp(rng.uniform(math.log(0.5), math.log(5.9), len(u)))
    pts = field.centre + u * d[:, None]
    pts = pts[_outside(pts, L_BOXES)]
    # an 8-texel cubemap needs the margin widened to its texel radius (0.175 rad); the
    # default 0.05 rad covers a 32-texel one (0.044 rad), the smallest the add-on offers
    for res, kw, count in ((8, {"margin": _texel_radius(directions.cubemap(8))}, 100),
                           (32, {}, 16)):
        cube = directions.cubemap(res)
        p = pts[:count]
        exact = _exact_fractions(scene, p, res)
        pi, ki, _ = occluder_fields.occluder_fractions(field, p, cube.directions,
                                          occluder_fields.texel_half_sides(cube), **kw)
        listed = np.zeros(exact.shape, bool)
        listed[pi, ki] = True
        assert (exact < 1.0).sum() > 100
        assert (exact[~listed] == 1.0).all(), (res, (exact[~listed] < 1.0).sum())


def test_occluder_casts_nothing_beyond_outer_shell(l_field):
    """Beyond the outer shell no pairs come back, though the object still blocks: the cut-off."""
    tri, field = l_field
    cube = directions.cubemap(8)
    u = directions.fibonacci_sphere(20)
    far = field.centre + u * field.radius * field.layout.outer * 1.01
    pi, ki, frac = occluder_fields.occluder_fractions(field, far, cube.directions,
                                         occluder_fields.texel_half_sides(cube))
    assert len(pi) == len(ki) == len(frac) == 0
    toward = -far / np.linalg.norm(far, axis=1)[:, None]      # the origin is in the slab
    blocked = np.diag(_cast(build_occluder_scene(tri), far, toward))
    assert blocked.all()
    # just inside the outer shell the same points do get pairs
    near = field.centre + u * field.radius * field.layout.outer * 0.99
    assert len(np.unique(occluder_fields.occluder_fractions(field, near, cube.directions,
                                               occluder_fields.texel_half_sides(cube))[0])) == len(u)


# --------------------------------------------------------------------------- 2. PCA

def _traced_tables(field, tri):
    """VDTs of every sample's map traced here (the module's frames and map directions)."""
    L = field.layout
    n, M = L.face, L.map
    frames = occluder_fields.sample_frames(n).reshape(-1, 3, 3)
    shell_dirs = occluder_fields.shell_directions(n).reshape(-1, 3)
    np.testing.assert_allclose(frames[:, 2], -shell_dirs, atol=1e-12)   # z toward centre
    np.testing.assert_allclose(np.einsum("pij,pkj->pik", frames, frames),
                               np.broadcast_to(np.eye(3), frames.shape), atol=1e-12)
    ids = np.arange(L.shells * 6 * n * n)
    shell, rest = np.divmod(ids, 6 * n * n)
    pos = field.centre + L.radii(field.radius)[shell, None] * shell_dirs[rest]
    world = np.einsum("mk,pkj->pmj", occluder_fields.map_directions(M), frames[rest]).reshape(-1, 3)
    org = np.repeat(pos.astype(np.float32), M * M, axis=0)
    hit = np.asarray(build_occluder_scene(tri).run(
        org, np.ascontiguousarray(world, np.float32), query="OCCLUDED")) != -1
    return ids, visibility_distance_table((~hit).reshape(-1, M, M).astype(np.float32))


def test_pca_error_falls_with_eigen_and_reaches_half_precision():
    """Reported error is the true RMS; it falls with eigen to float16 level at full rank."""
    tri = _boxes(L_BOXES)
    errors = {}
    for k in (1, 2, 4, 16):     # 16 samples per segment (face 8): 16 is the full rank
        field = occluder_fields.build_occluder_field(tri, occluder_fields.FieldLayout(shells=3, face=8, map=16, eigen=k),
                                        threads=2)
        ids, ref = _traced_tables(field, tri)
        tab = field.tables(ids)
        true = math.sqrt(((tab - ref) ** 2).sum() / (ref ** 2).sum())
        assert field.error == pytest.approx(true, rel=0.02, abs=2e-5), (k, field.error, true)
        errors[k] = field.error
    assert errors[1] > errors[2] > errors[4] > errors[16]
    assert errors[4] > 0.005
    assert errors[16] < 1e-3                      # float16's unit roundoff is 4.9e-4


def test_tables_equal_traced_vdt_at_full_rank():
    """At full rank tables(ids) are the traced maps' VDTs (id decoding, frames, PCA)."""
    tri = _boxes(L_BOXES)
    field = occluder_fields.build_occluder_field(tri, occluder_fields.FieldLayout(shells=3, face=8, map=16, eigen=16),
                                    threads=2)
    ids, ref = _traced_tables(field, tri)
    order = np.random.default_rng(3).permutation(len(ids))
    tab = field.tables(ids[order])
    assert tab.shape == ref.shape and tab.dtype == np.float32
    np.testing.assert_allclose(tab, ref[order], atol=4e-3)
    assert ((tab > 0) == (ref[order] > 0)).all()


# --------------------------------------------------------------------------- 3. static field

def _ground_and_wall():
    ground = _quad((-3, -3, 0), (3, -3, 0), (3, 3, 0), (-3, 3, 0))
    wall = _quad((0, -3, 0), (0, 3, 0), (0, 3, 2.5), (0, -3, 2.5))     # x = 0, up to 2.5
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
    np.testing.assert_allclose(vis, ~_cast(scene, pos, cube.directions), atol=1e-6)
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
    agree = ((vis >= 0.5) == ~_cast(scene, p, cube.directions)).mean()
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
        exact = ~_cast(scene, p, cube.directions)
        plain = sf.static_visibility(field, ids, w)
        blend = sf.static_visibility(field, ids, seen)
        assert np.abs(blend - exact).mean() < 0.5 * np.abs(plain - exact).mean()
        assert ((blend >= 0.5) == exact).mean() >= 0.92


def test_seen_corners_keeps_plain_weights_when_no_corner_is_seen(static_scene):
    """A point that sees no corner keeps the plain weights (no division by zero)."""
    tri, cube, field, _ = static_scene
    p = np.array([[0.7, 0.3, 0.9]])
    shut = build_occluder_scene(_box(p[0] - 0.05, p[0] + 0.05))
    ids, w = sf.static_corners(field, p)
    np.testing.assert_array_equal(sf.seen_corners(shut, field, p, ids, w), w)


# --------------------------------------------------------------------------- 4. turned bits

def test_turned_bits_match_visibility_traced_at_turned_pose():
    """Bits turned by R match a trace at the turned pose (>= 97 %); turning by R^T does not."""
    boxes = L_BOXES + (((-1.0, -0.5, 0.3), (-0.8, 0.5, 0.8)),)
    tri = _boxes(boxes)
    rng = np.random.default_rng(7)
    pts = rng.uniform((-1.5, -1.0, -0.8), (1.5, 1.0, 1.6), (600, 3))
    pts = pts[_outside(pts, boxes)][:150]
    cube = directions.cubemap(16)

    def traced(tri_, pts_):
        return np.packbits(~_cast(build_occluder_scene(tri_), pts_, cube.directions), axis=1)

    def unpack(b):
        return np.unpackbits(b, axis=1, count=cube.size).astype(bool)

    bits0 = unpack(traced(tri, pts))
    assert (sf.turn_texels(cube, np.eye(3)) == np.arange(cube.size)).all()
    for seed in range(3):
        R = _rotation(seed)
        now = unpack(traced(tri @ R.T, pts @ R.T))
        turned = unpack(sf.turned_bits(np.packbits(bits0, axis=1), cube, R))
        agree = (turned == now).mean()
        either = ~turned | ~now
        assert agree >= 0.97, (seed, agree)
        assert (turned == now)[either].mean() >= 0.9
        wrong = unpack(sf.turned_bits(np.packbits(bits0, axis=1), cube, R.T))
        assert (wrong == now).mean() < agree - 0.03


# --------------------------------------------------------------------------- 5. small parts

@pytest.mark.parametrize("kw", [
    dict(shells=1), dict(face=0), dict(face=7), dict(map=3),
    dict(inner=0.0), dict(inner=-0.1), dict(inner=6.0), dict(inner=7.0, outer=6.0),
    dict(inner=float("nan")), dict(outer=float("inf")), dict(eigen=-1),
])
def test_field_layout_rejects_bad_values(kw):
    """Unusable layouts are refused when made, not after (or silently during) a trace."""
    with pytest.raises(ValueError):
        occluder_fields.FieldLayout(**kw)


def test_mean_only_field_reads_back():
    """eigen=0 (means only) is a valid field whose error is its true RMS against traced VDTs."""
    tri = _boxes(L_BOXES)
    field = occluder_fields.build_occluder_field(tri, occluder_fields.FieldLayout(shells=2, face=4, map=8, eigen=0),
                                    threads=2)
    ids, ref = _traced_tables(field, tri)
    tab = field.tables(ids)
    assert tab.shape == ref.shape
    assert field.error == pytest.approx(
        math.sqrt(((tab - ref) ** 2).sum() / (ref ** 2).sum()), rel=0.02)


def test_field_layout_radii():
    """Shell radii run from inner r to outer r, evenly spaced in log radius (§5.1)."""
    L = occluder_fields.FieldLayout(shells=5, inner=0.5, outer=8.0)
    r = L.radii(2.0)
    np.testing.assert_allclose(r, [1.0, 2.0, 4.0, 8.0, 16.0])


def test_bounding_sphere_ignores_non_finite_vertices():
    """NaN/inf vertices (Embree drops them) move neither centre nor radius."""
    good = np.array([[0.0, 0.0, 0.0], [2.0, 0.0, 0.0], [0.0, 2.0, 1.0]])
    bad = np.array([[np.nan, 1.0, 1.0], [np.inf, 0.0, 0.0], [0.0, -np.inf, 0.0]])
    c, r = occluder_fields.bounding_sphere(np.concatenate([good[:1], bad, good[1:]]))
    np.testing.assert_allclose(c, [1.0, 1.0, 0.5])
    assert r == pytest.approx(math.sqrt(2.25))
    c, r = occluder_fields.bounding_sphere(bad)
    assert r == 0.0 and np.isfinite(c).all()
