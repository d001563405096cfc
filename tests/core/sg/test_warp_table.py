"""core.sg.warp_table: GGX_WARP_TABLE as its fit defines it -- every node's amplitude shares
non-negative and summing to one, every lobe's axis above the horizon -- and fitting GGX's
view slice better than the plain warp of eq. 17-21 at oblique views (both measured by the
slice's own quadrature, core.sg.ggx_warp.ggx_warp_error).  No bpy; the refits of stored
nodes are tests/integration/numerics/test_sg_table_refits.py."""

from __future__ import annotations

import math

import numpy as np
import pytest

from prt_relight.core.sg import ggx_warp
from prt_relight.core.sg.ndf import SG_ALPHA_MIN, iso_ndf_lobes
from prt_relight.core.sg.warp_table import GGX_WARP_TABLE

K = ggx_warp.GGX_WARP_LOBES


def test_one_node_per_roughness_and_view_cosine():
    assert GGX_WARP_TABLE.shape == (len(ggx_warp.WARP_R), len(ggx_warp.WARP_MU), 3 * K)
    assert np.isfinite(GGX_WARP_TABLE).all()


def test_amplitude_shares_are_a_partition_of_the_slice():
    shares = GGX_WARP_TABLE[..., 2 * K:]
    assert (shares >= 0.0).all()
    np.testing.assert_allclose(shares.sum(axis=-1), 1.0, atol=1e-9)


def test_every_lobe_points_above_the_horizon():
    """Lobe k's axis is the mirror direction tilted by d_k in the plane of incidence: its
    elevation from the normal, acos(n.o) + d_k, stays within 90 degrees (node 0 is fitted
    at n.o = WARP_MU_MIN)."""
    mu = np.maximum(ggx_warp.WARP_MU, ggx_warp.WARP_MU_MIN)
    el = np.arccos(mu)[None, :, None] + GGX_WARP_TABLE[..., :K]
    assert (np.abs(el) <= 0.5 * math.pi + 1e-9).all()


def _plain_warp_params(r, mu):
    """The plain warp of eq. 17-21 as table parameters: GGX's two coaxial NDF lobes, each
    at the mirror direction (d = 0) with its sharpness over 4 n.o, amplitudes as fitted to
    the NDF."""
    a = max(r * r, SG_ALPHA_MIN)
    lam, amp = iso_ndf_lobes("GGX", a)
    l = np.log(lam * a * a / 2.0)                     # lam / (4 n.o) over the warp's 2 / (4 a^2 n.o)
    pad = K - lam.size
    return np.concatenate([np.zeros(K), l, np.zeros(pad), amp / amp.sum(), np.zeros(pad)])


@pytest.mark.parametrize("ir, j, gain", [(10, 20, 0.05), (10, 6, 0.4), (6, 10, 0.5), (16, 12, 0.25)])
def test_the_table_fits_the_slice_better_than_the_plain_warp(ir, j, gain):
    """At the nodes tests/integration refits (measured fitted / plain: 0.45 / 13.8, 15.7 /
    43.6, 15.6 / 33.2, 3.6 / 17.6 %)."""
    r, mu = ggx_warp.WARP_R[ir], ggx_warp.WARP_MU[j]
    stored = ggx_warp.ggx_warp_error(r, mu, GGX_WARP_TABLE[ir, j])
    plain = ggx_warp.ggx_warp_error(r, mu, _plain_warp_params(r, mu))
    assert stored < gain * plain, (stored, plain)
