"""The stored visibility's blob: a shading point's bit-packed visibility over the 6N^2 cubemap
texels, one row per point, compressed as it is traced (core.common.codec)."""

import numpy as np

from ..common import codec

#: the bit-packed visibility of every precomputed object (what all methods start from)
VISIBILITY = "visibility"
#: a dynamic object's shadow fields (core.scene.shadow_fields.dynamic_arrays)
SHADOW_FIELD = "shadow_field"


def visibility_blob(bits: np.ndarray, resolution: int) -> bytes:
    """The blob of (P, 6N^2/8) bit-packed visibility traced at 6xNxN (any thread)."""
    bits = np.asarray(bits)
    if bits.dtype != np.uint8 or bits.ndim != 2 or bits.shape[1] * 8 != 6 * resolution ** 2:
        raise ValueError(f"visibility must be (points, {6 * resolution ** 2 // 8}) uint8 at "
                         f"6x{resolution}^2, got {bits.dtype} {bits.shape}")
    return codec.pack({"bits": bits}, {"resolution": int(resolution)})


def visibility_writer(points: int, resolution: int) -> codec.RowWriter:
    """A writer of the same blob as :func:`visibility_blob`, fed rows of (points,
    6N^2/8) uint8 in order as they are traced (any thread; nothing but the compressed
    bytes is held)."""
    return codec.RowWriter("bits", np.uint8, (int(points), 6 * int(resolution) ** 2 // 8),
                           {"resolution": int(resolution)})


def visibility_of_blob(blob: bytes) -> np.ndarray:
    """The bits of a :func:`visibility_blob` (read-only)."""
    return codec.unpack(blob)[0]["bits"]
