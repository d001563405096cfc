"""The GPU's pixel filter (shaders/passes/resolve_frag.glsl, addon/gpu/drawing.resolve)
against core.shading.pixel_filter.resolve, which Cycles' Blackman-Harris defines."""

from __future__ import annotations

import numpy as np
import pytest

from prt_relight.core.shading import pixel_filter


bpy = pytest.importorskip("bpy")

from ..viewport import gpu_context  # noqa: E402


@pytest.mark.parametrize("s, width", [(3, 1.5), (2, 1.5), (3, 0.0), (4, 0.6)])
def test_gpu_resolve_equals_the_filter(registered_addon, s, width):
    """A random supersampled frame of odd size (borders renormalised on every side, a
    bright isolated sample) resolved on the GPU matches the CPU filter to float32."""
    import gpu
    from prt_relight.addon.frame.engine import in_render
    from prt_relight.addon.gpu import drawing
    gpu_context()
    h, w = 7, 11
    rng = np.random.default_rng(s)
    big = rng.random((h * s, w * s, 4)).astype(np.float32)
    big[5, 9] = 500.0

    def resolve(_depsgraph):
        flat = np.ascontiguousarray(big).reshape(-1)
        tex = gpu.types.GPUTexture((w * s, h * s), format="RGBA32F",
                                   data=gpu.types.Buffer("FLOAT", flat.size, flat))
        return drawing.resolve(tex, w, h, s, width)

    got = in_render(bpy.context.scene, resolve)
    want = pixel_filter.resolve(big, s, width)
    assert got.shape == (h, w, 4)
    np.testing.assert_allclose(got, want, rtol=1e-5, atol=1e-5)
