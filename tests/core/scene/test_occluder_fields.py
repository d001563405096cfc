"""core.scene.occluder_fields (Zhou et al. 2005 in the form of Xu et al. 2006 §4.3.2, §5.1)
against exact ray casting with Embree: the occluder field's eq. 9 fractions, the cone pairs,
the outer shell's cut-off, its PCA, the layout's checks and radii, the bounding sphere.

Every reference is an Embree cast of the same triangles (``query="OCCLUDED"``), made here
from the geometry, never an earlier output of the module.  Layouts and cubemaps are small
so the file runs in seconds on two cores.  No bpy."""

import math

import numpy as np
import pytest

from prt_relight.core.sphere import directions
from prt_relight.core.scene import occluder_fields
from prt_relight.core.scene.distance_tables import visibility_distance_table
from prt_relight.core.scene.visibility import build_occluder_scene
from .occluders import L_BOXES, aabbs, cast, outside


# --------------------------------------------------------------------------- helpers

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
    blocked = cast(scene, points, dirs.reshape(-1, 3)).reshape(len(points), -1, sub * sub)
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
    tri = aabbs(L_BOXES)
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
    pts = pts[outside(pts, L_BOXES)][:100]
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


def test_occluder_fractions_are_read_in_bounded_blocks(l_field):
    """Points near the object are read in blocks of ``max_pairs`` (point, texel) pairs: the
    same pairs and fractions as all at once, in bounded memory (scene fuzzer seeds 44 and
    46: 512 points at 6x32² directions held 1 GB of temporaries at once)."""
    import tracemalloc
    _, field = l_field
    cube = directions.cubemap(32)
    rng = np.random.default_rng(4)
    u = rng.normal(size=(600, 3))
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    pts = field.centre + u * field.radius * rng.uniform(0.6, 2.0, (600, 1))
    pts = pts[outside(pts, L_BOXES)][:256]
    half = occluder_fields.texel_half_sides(cube)
    tracemalloc.start()
    blocks = occluder_fields.occluder_fractions(field, pts, cube.directions, half,
                                                max_pairs=1 << 15)
    peak = tracemalloc.get_traced_memory()[1] / 2**20
    tracemalloc.stop()
    whole = occluder_fields.occluder_fractions(field, pts, cube.directions, half,
                                               max_pairs=1 << 30)
    assert len(whole[0]) > 400_000              # ~100 MB of temporaries read at once
    for a, b in zip(blocks, whole):     # per pair alike; a vector kernel's tail may differ
        np.testing.assert_allclose(a, b, rtol=1e-6, atol=1e-7)
    assert peak < 40.0, peak                    # the results (~25 MB) and one block


def test_occluder_pairs_cover_every_blocked_texel(l_field):
    """No blocked texel lies outside the cone pairs (else its shadow is silently lost)."""
    tri, field = l_field
    scene = build_occluder_scene(tri)
    rng = np.random.default_rng(2)
    u = rng.normal(size=(200, 3))
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    d = field.radius * np.exp(rng.uniform(math.log(0.5), math.log(5.9), len(u)))
    pts = field.centre + u * d[:, None]
    pts = pts[outside(pts, L_BOXES)]
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
    blocked = np.diag(cast(build_occluder_scene(tri), far, toward))
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
    tri = aabbs(L_BOXES)
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
    tri = aabbs(L_BOXES)
    field = occluder_fields.build_occluder_field(tri, occluder_fields.FieldLayout(shells=3, face=8, map=16, eigen=16),
                                    threads=2)
    ids, ref = _traced_tables(field, tri)
    order = np.random.default_rng(3).permutation(len(ids))
    tab = field.tables(ids[order])
    assert tab.shape == ref.shape and tab.dtype == np.float32
    np.testing.assert_allclose(tab, ref[order], atol=4e-3)
    assert ((tab > 0) == (ref[order] > 0)).all()


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
    tri = aabbs(L_BOXES)
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
