"""The stored visibility's blob: a shading point's bit-packed visibility over the 6N^2 cubemap
texels, one row per point, compressed as it is traced (core.common.codec)."""

import numpy as np

from ..common import codec

#: the bit-packed visibility of every precomputed object (what all methods start from)
VISIBILITY = "visibility"
#: a dynamic object's shadow fields (core.scene.shadow_fields.dynamic_arrays)
SHADOW_FIELD = "shadow_field"
#: a static object's bounce transfer: its points' gather clusters and rows (core.transport)
BOUNCE = "bounce"


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


#: the cubemap the bounce's cluster samples are traced at (the light they bounce is smooth)
BOUNCE_SAMPLE_RESOLUTION = 16


def bounce_blob(columns, weights, rest, front, back, samples: dict, cluster_rows: dict,
                clusters: int) -> bytes:
    """The blob of a static object's bounce transfer (core.transport): each of its points'
    row over the gather clusters (P, W) as cluster ids and float16 weights, and the sum of
    the entries past its W largest (P,) float16 (core.transport.transfer.row_width); the
    cluster of each of its triangles' front side (T,) and back side (T,) when it is
    two-sided; the
    cluster samples lying on it (``samples``: cluster, weight, position, normal,
    bit-packed visibility at 6 x BOUNCE_SAMPLE_RESOLUTION^2); the rows of the clusters
    it holds (``cluster_rows``: ids, columns, weights).  ``clusters``: the scene's count."""
    arrays = {"columns": np.asarray(columns, np.int32),
              "weights": np.asarray(weights, np.float16),
              "rest": np.asarray(rest, np.float16),
              "front": np.asarray(front, np.int32),
              "sample_cluster": np.asarray(samples["cluster"], np.int32),
              "sample_weight": np.asarray(samples["weight"], np.float32),
              "sample_position": np.asarray(samples["position"], np.float32),
              "sample_normal": np.asarray(samples["normal"], np.float32),
              "sample_bits": np.asarray(samples["bits"], np.uint8),
              "cluster_ids": np.asarray(cluster_rows["ids"], np.int32),
              "cluster_columns": np.asarray(cluster_rows["columns"], np.int32),
              "cluster_weights": np.asarray(cluster_rows["weights"], np.float16)}
    if back is not None:
        arrays["back"] = np.asarray(back, np.int32)
    return codec.pack(arrays, {"clusters": int(clusters),
                               "sample_resolution": BOUNCE_SAMPLE_RESOLUTION})


def bounce_arrays(arrays: dict, meta: dict) -> dict:
    """A :func:`bounce_blob`'s unpacked arrays, weights as float32, with ``clusters`` and
    ``sample_resolution``."""
    out = dict(arrays)
    out["weights"] = arrays["weights"].astype(np.float32)
    # rows stored before the rest was kept had it scaled into their entries
    out["rest"] = arrays["rest"].astype(np.float32) if "rest" in arrays \
        else np.zeros(len(arrays["weights"]), np.float32)
    out["cluster_weights"] = arrays["cluster_weights"].astype(np.float32)
    out["clusters"] = int(meta["clusters"])
    out["sample_resolution"] = int(meta["sample_resolution"])
    return out
