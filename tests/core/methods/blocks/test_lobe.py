"""core.methods.blocks.lobe: the fused float32 Beckmann lobe against the float64 general
formula, near_horizon's conservative cut and the level rule following the lobe
(Inger, Farbman, Lischinski 2013, Appendix A).  No bpy."""

from __future__ import annotations

import numpy as np
import pytest

from prt_relight.core.methods.blocks import light_tables
from prt_relight.core.methods.blocks import encoding as E
from prt_relight.core.methods.blocks import lobe as Lobe
from prt_relight.core.shading import brdf
from prt_relight.core.shading import materials
from prt_relight.core.sphere.directions import cubemap
from prt_relight.core.sphere.envmap import CubeLighting

from .cases import MATERIALS


@pytest.mark.parametrize("roughness", [0.1, 0.25, 0.6, 1.0])
def test_fused_beckmann_lobe_equals_the_general_formula(roughness):
    """GlossyLobe.dense's fused float32 Beckmann path (matrix products with the sums folded
    in) against the float64 general formula, at directions all around the sphere: below
    the horizon (0), grazing light (Lambda_i > 0), grazing and backward views, wi = -wo."""
    rng = np.random.default_rng(7)
    P, D = 64, 400
    nrm = rng.normal(size=(P, 3))
    nrm /= np.linalg.norm(nrm, axis=1, keepdims=True)
    views = rng.normal(size=(P, 3))
    views[:8] = -nrm[:8] + 0.01 * rng.normal(size=(8, 3))     # views from below: bent
    views[8:16] -= nrm[8:16] * np.einsum("ij,ij->i", views[8:16], nrm[8:16])[:, None]
    views /= np.linalg.norm(views, axis=1, keepdims=True)
    d = rng.normal(size=(D, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    d[:P // 4] = -views[:P // 4]                              # wi = -wo for a few vertices
    mat = materials.Material(diffuse_albedo=(0.0, 0.0, 0.0), specular_color=(1.0, 0.9, 0.8),
                        roughness=roughness, distribution="BECKMANN")
    fast = Lobe.GlossyLobe(mat).prepare(nrm, views)
    assert fast._fused is not None
    slow = Lobe.GlossyLobe(mat, np.float64).prepare(nrm, views)
    with np.errstate(all="ignore"):
        got = sum(f[:, :, None] * w[:, None, :] for f, w in fast.dense(np.arange(P), d))
        want = sum(f[:, :, None] * w[:, None, :] for f, w in slow.dense(np.arange(P), d))
    assert np.isfinite(got).all() and (got >= 0.0).all()
    scale = float(np.abs(want).max())
    # float32 rounding of 1 / cos_h^2 moves the exponent by ~3e-7 / alpha^2; where
    # |wo + wi|^2 < 0.05 (wi ~ -wo, grazing views) float32 cannot resolve the half-vector,
    # nor the horizon at |cos_i| < 1e-5: only finite there
    v = Lobe.GlossyLobe(mat).prepare(nrm, views).v
    resolved = ((2.0 + 2.0 * v @ d.T) > 0.05) & (np.abs(nrm @ d.T) > 1e-5)
    np.testing.assert_allclose(got[resolved], want[resolved], rtol=2e-4 + 1e-6 / mat.alpha ** 2,
                               atol=1e-6 * scale)
    assert (got[(nrm @ d.T) < -1e-5] == 0.0).all()


@pytest.mark.parametrize("n", [32, 64])
def test_pairs_off_the_horizon_have_every_direction_above_the_cut(n):
    """near_horizon is conservative: a (vertex, block) pair it lets skip the horizon and
    grazing-light checks has every sample direction (the lighting's unit directions) above
    the lobe's horizon_cos; and most pairs well above the horizon are let through."""
    rng = np.random.default_rng(11)
    P = 300
    nrm = rng.normal(size=(P, 3))
    nrm /= np.linalg.norm(nrm, axis=1, keepdims=True)
    mat = materials.Material(diffuse_albedo=(0.0, 0.0, 0.0), specular_color=(1.0, 1.0, 1.0),
                        roughness=0.25, distribution="BECKMANN")
    lobe = Lobe.GlossyLobe(mat).prepare(nrm, nrm)
    cube = cubemap(n)
    light = CubeLighting(np.ones((cube.size, 3), np.float32),
                         cube.directions * rng.uniform(0.9, 1.0, (cube.size, 1)))
    tables = light_tables.light_tables(light, n)
    geometry = E.block_geometry(n)
    nb = geometry.centre.shape[0]
    p = np.repeat(np.arange(P), nb)
    b = np.tile(np.arange(nb), P)
    edge = Lobe.near_horizon(lobe, p, b, geometry)
    cos_min = np.einsum("kc,kjc->kj", lobe.n32[p], tables.unit_dirs32[b]).min(axis=1)
    assert (cos_min[~edge] > lobe.horizon_cos()).all()
    assert (~edge[cos_min > 0.5]).mean() > 0.9


def test_level_rule_follows_the_lobe():
    """Pixel basis around the mirror direction, coarser further away, skipped far away."""
    n = 64
    nrm = np.array([[0.0, 0.0, 1.0]])
    view = np.array([[np.sin(0.5), 0.0, np.cos(0.5)]])
    mat = MATERIALS["glossy beckmann"]
    lobe = Lobe.GlossyLobe(mat).prepare(nrm, view)
    geo = E.block_geometry(n)
    blocks = np.arange(E.block_count(n))
    levels = Lobe.glossy_levels(lobe, np.zeros(blocks.size, int), blocks, geo,
                             Lobe.DEFAULT_LEVEL_THRESHOLDS)
    mirror = np.array([-np.sin(0.5), 0.0, np.cos(0.5)])
    angle = np.arccos(np.clip(geo.centre @ mirror, -1, 1))
    assert (levels[angle < 0.05] == E.PIXEL).all()
    assert levels[np.argmin(angle)] == E.PIXEL
    # far from the lobe (and from -wo, where the half-vector of a nearby direction can
    # swing anywhere and the rule stays conservative) the block is skipped
    far = (angle > np.pi / 2) & (geo.centre @ view[0] > -0.5)
    assert far.sum() > 20 and (levels[far] == 0).all()
    # more coefficients closer to the lobe (monotone on average)
    front = geo.centre @ view[0] > -0.5
    means = [angle[front & (levels == lv)].mean() for lv in (E.PIXEL, 16, 4, 1, 0)
             if (front & (levels == lv)).any()]
    assert means == sorted(means)
    # the skipped blocks really are negligible: the lobe's largest value there
    d = geo.texel_dirs[levels == 0].reshape(-1, 3)
    f = brdf.specular_cosine(mat, nrm, view, d)
    assert f.max() < 1e-6 * brdf.specular_cosine(mat, nrm, view, mirror[None]).max()
