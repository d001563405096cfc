"""The shading points' stored visibility as a GPU texture, shared by the passes that read it
per pixel or per point (the sharp pass, REFERENCE's glossy pass): np.packbits rows, three
bytes per float (exact integers below 2^24), four floats per texel, point p's texels from
texel p * stride in rows of drawing.ROW_TEXELS."""

from __future__ import annotations

import numpy as np

from ...core.scene import visibility as core_visibility
from ..frame import keys
from . import drawing

# per (object, bits): the texture and its stride
_TEXTURES = drawing.gpu_cache({})


def texels(bits: np.ndarray):
    """(rows, drawing.ROW_TEXELS, 4) float32 of bit-packed visibility (P, nbytes), and the
    stride in texels per point."""
    floats = core_visibility.bytes_to_float24(bits)              # (P, nbytes / 3)
    P, F = floats.shape
    stride = -(-F // 4)
    flat = np.zeros((P, stride * 4), np.float32)
    flat[:, :F] = floats
    total = max(P * stride, 1)
    rows = -(-total // drawing.ROW_TEXELS)
    out = np.zeros(rows * drawing.ROW_TEXELS * 4, np.float32)
    out[:flat.size] = flat.reshape(-1)
    return out.reshape(rows, drawing.ROW_TEXELS, 4), stride


def texture(st):
    """(GPU texture, stride) of an object's visibility bits ``st.bits``, kept while they are."""
    def make():
        rgba, stride = texels(st.bits)
        return drawing.float_texture(rgba), stride
    return keys.per_visibility(_TEXTURES, (st.name, id(st.bits)), st.bits, make, limit=16)
