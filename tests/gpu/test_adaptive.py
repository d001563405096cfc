"""Adaptive anti-aliasing (addon/gpu/drawing.render_offscreen, shaders/passes/adaptive_frag.glsl):
a one-sample pilot frame picks the pixels that get every sample (core.shading.pixel_filter.
refine_mask); the frame stays within a small error of the uniform one."""

from __future__ import annotations

import numpy as np
import pytest

from prt_relight.core.shading import pixel_filter

bpy = pytest.importorskip("bpy")

from ..cases.small import small_scene  # noqa: E402


@pytest.mark.parametrize("method", ["REFERENCE", "SSDF_SG"])
def test_adaptive_frame_is_the_uniform_frame_where_it_matters(registered_addon, method):
    """Suzanne on a ground under 'sunset' (its sun a compact source with a shadow): the
    pilot leaves some pixels to their one sample and refines the others; the adaptive
    frame is within 0.5 % (rel-L2) of every pixel taking 3 x 3 samples, and where every
    pixel is refined it is that frame."""
    from prt_relight.addon.frame.engine import in_render, render_pixels, render_view
    from prt_relight.addon.frame.state import FrameState
    small_scene()
    scene = bpy.context.scene
    scene.prt.method = method
    assert bpy.ops.prt.precompute() == {"FINISHED"}

    def frames(depsgraph):
        state = FrameState()
        state.sync(depsgraph)
        view, proj, w, h, persp = render_view(scene, depsgraph)
        args = (state, view, proj, w, h, False, persp)
        pilot = render_pixels(*args, 1)
        return (pilot, render_pixels(*args, 3, 1.5), render_pixels(*args, 3, 1.5, 0.05),
                render_pixels(*args, 3, 1.5, 1e-9))

    pilot, uniform, adaptive, everywhere = in_render(scene, frames)
    mask = pixel_filter.refine_mask(pilot, 0.05)
    assert 0.05 < mask.mean() < 0.95
    rel = np.linalg.norm(adaptive[..., :3] - uniform[..., :3]) / np.linalg.norm(uniform[..., :3])
    assert rel < 0.005, rel
    assert np.isfinite(adaptive).all()
    assert pixel_filter.refine_mask(pilot, 1e-9).all()         # no two pixels alike
    np.testing.assert_allclose(everywhere, uniform, rtol=1e-5, atol=1e-6)
