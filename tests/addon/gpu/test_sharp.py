"""Glossy lobes too narrow for the cubemap drawn per pixel (addon/gpu/sharp.py): every
method draws a mirror ball alike."""

from __future__ import annotations

import bpy
import numpy as np
import pytest

from prt_relight.bench import scenes

from ...cases.glossy import mirror_ball


pytestmark = pytest.mark.usefixtures("registered_addon")

METHODS = ["REFERENCE", "SSDF_SG", "RSL", "BLOCKS", "SH", "WAVELET", "AUTO"]


# --------------------------------------------------------------------------- scenes

def test_every_method_draws_the_mirror_ball_alike(tmp_path):
    """The ball is a pure Glossy BSDF at roughness 0: no Lambert base, so every method's
    pixels are the per-pixel lobe alone (and none is negative or blotchy)."""
    mirror_ball(size=(48, 36), ground=False)
    bpy.ops.prt.precompute()
    scene = bpy.context.scene
    scene.prt.supersampling = 1
    scene.render.filter_size = 0.0
    frames = {}
    for method in METHODS:
        scene.prt.method = method
        frames[method] = scenes.render_exr(tmp_path / f"{method}.exr")
    ref = frames["REFERENCE"]
    ball = ref[..., 3] > 0.5
    for method, frame in frames.items():
        assert np.isfinite(frame).all() and frame.min() >= 0.0, method
    bright = ref[..., :3].max(axis=-1) > 0.05
    assert (ball & bright).sum() > 50                       # the sky is reflected, not black
    for method, frame in frames.items():
        sel = ball & bright
        np.testing.assert_allclose(frame[sel], ref[sel], rtol=2e-4, atol=1e-5, err_msg=method)
