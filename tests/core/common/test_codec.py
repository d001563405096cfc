"""core.common.codec: the versioned blob every stored result goes through (no Blender)."""

from __future__ import annotations

import struct
import zlib

import numpy as np
import pytest

from prt_relight.core.common import codec
from prt_relight.core.sphere import directions
from prt_relight.core.scene import visibility


def _ground_and_ball_visibility(n=32, cuts=24):
    """Traced visibility of a grid under a floating box, points in vertex order."""
    g = np.linspace(-2.0, 2.0, cuts)
    pts = np.array([[x, y, 0.0] for y in g for x in g])
    nrm = np.tile([0.0, 0.0, 1.0], (len(pts), 1))
    v = np.array([[x, y, z] for x in (-0.5, 0.5) for y in (-0.5, 0.5) for z in (0.3, 1.3)])
    quads = [(0, 1, 3, 2), (4, 6, 7, 5), (0, 4, 5, 1), (2, 3, 7, 6), (0, 2, 6, 4), (1, 5, 7, 3)]
    tris = np.array([[v[a], v[b], v[c]] for a, b, c, d in quads]
                    + [[v[a], v[c], v[d]] for a, b, c, d in quads])
    cube = directions.cubemap(n)
    scene = visibility.build_occluder_scene(tris)
    return visibility.trace_visibility(scene, pts, nrm, cube, 1e-4, threads=1)


def test_visibility_round_trip_exact():
    rng = np.random.default_rng(3)
    cases = [rng.integers(0, 256, (257, 768), dtype=np.uint8),       # random bits
             np.zeros((0, 768), np.uint8),                            # no points
             rng.integers(0, 256, (1, 768), dtype=np.uint8)]          # one point
    if visibility.have_embree():
        cases.append(_ground_and_ball_visibility())                   # traced
    for bits in cases:
        arrays, meta = codec.unpack(codec.pack({"bits": bits}, {"resolution": 32}))
        assert meta == {"resolution": 32}
        assert arrays["bits"].dtype == np.uint8 and arrays["bits"].shape == bits.shape
        np.testing.assert_array_equal(arrays["bits"], bits)
        assert not arrays["bits"].flags.writeable          # shared by caches


@pytest.mark.skipif(not visibility.have_embree(), reason="needs embreex")
def test_traced_visibility_compresses_far_below_128_bytes_per_point():
    bits = _ground_and_ball_visibility()
    per_point = len(codec.pack({"bits": bits})) / len(bits)
    assert per_point < 64, per_point                     # 768 bytes raw


def test_typed_arrays_and_meta_round_trip_bit_identical():
    rng = np.random.default_rng(4)
    arrays = {"f4": rng.normal(size=(33, 7)).astype(np.float32),
              "f8": rng.normal(size=5),
              "i4": rng.integers(-9, 9, 40).astype(np.int32),
              "i8": rng.integers(0, 2 ** 40, 3),
              "u2": rng.integers(0, 60000, 11).astype(np.uint16),
              "b": rng.random(9) > 0.5,
              "big_endian": np.arange(6, dtype=">f4"),
              "strided": rng.normal(size=(8, 8)).astype(np.float32)[:, ::2],
              "empty": np.zeros((3, 0), np.float32)}
    meta = {"pi": float(np.pi), "tiny": 5e-324, "n": 7, "s": "Ünïcode", "flag": True,
            "rotation": rng.normal(size=9).tolist(), "nested": {"a": [1, 2]}}
    back, meta_back = codec.unpack(codec.pack(arrays, meta))
    assert list(back) == list(arrays) and meta_back == meta
    for name, a in arrays.items():
        assert back[name].shape == a.shape and back[name].dtype == a.dtype.newbyteorder("=")
        assert back[name].tobytes() == np.ascontiguousarray(a, a.dtype.newbyteorder("<")).tobytes()
    assert codec.read_meta(codec.pack(arrays, meta)) == meta


def test_bad_input_is_a_clear_error():
    with pytest.raises(TypeError, match="cannot store arrays of"):
        codec.pack({"c": np.zeros(3, np.complex64)})
    with pytest.raises(TypeError, match="meta must hold"):
        codec.pack({}, {"x": np.zeros(2)})


def _with_header(blob, edit):
    """``blob`` with its JSON header changed by ``edit(header_dict)``."""
    import json
    magic, version, length = struct.unpack_from("<4sHI", blob)
    header = json.loads(blob[10:10 + length])
    edit(header)
    new = json.dumps(header).encode()
    return struct.pack("<4sHI", magic, version, len(new)) + new + blob[10 + length:]


def test_newer_layout_or_codec_is_reported_never_misread():
    blob = codec.pack({"bits": np.ones((4, 768), np.uint8)}, {"resolution": 32})
    newer = blob[:4] + struct.pack("<H", codec.FORMAT + 1) + blob[6:]
    with pytest.raises(codec.NewerFormatError, match="newer prt_relight"):
        codec.unpack(newer)
    with pytest.raises(codec.NewerFormatError):
        codec.read_meta(newer)

    def other_codec(h):
        h["arrays"][0][3] = "zstd"
    with pytest.raises(codec.NewerFormatError, match="unknown codec 'zstd'"):
        codec.unpack(_with_header(blob, other_codec))


def test_damaged_blobs_raise_format_error():
    bits = np.random.default_rng(5).integers(0, 256, (20, 768), dtype=np.uint8)
    blob = codec.pack({"bits": bits})

    def wrong_shape(h):
        h["arrays"][0][2] = [21, 768]

    def bad_dtype(h):
        h["arrays"][0][1] = "object"
    flipped = bytearray(blob)
    flipped[-10] ^= 0xFF
    for bad in [b"", b"PRTB", b"NOPE" + blob[4:], blob[:-1], blob + b"\0", bytes(flipped),
                _with_header(blob, wrong_shape), _with_header(blob, bad_dtype),
                blob[:6] + struct.pack("<I", 10 ** 6) + blob[10:]]:
        with pytest.raises(codec.FormatError):
            codec.unpack(bad)
    # a valid zlib stream of the wrong length is refused too
    short = zlib.compress(bits[:10].tobytes())

    def short_payload(h):
        h["arrays"][0][4] = len(short)
    head = _with_header(blob, short_payload)
    head = head[:10 + struct.unpack_from("<I", head, 6)[0]]
    with pytest.raises(codec.FormatError, match="bytes where"):
        codec.unpack(head + short)


def test_row_writer_makes_the_blob_pack_makes():
    """Rows written in blocks of any size compress to the very blob of the whole array
    (zlib's stream does not depend on how its input was split)."""
    rng = np.random.default_rng(3)
    bits = (rng.random((1000, 96)) < 0.2).astype(np.uint8) * rng.integers(0, 255, 96,
                                                                          dtype=np.uint8)
    bits[200:600] = bits[200]                      # long runs, as neighbouring points have
    whole = codec.pack({"bits": bits}, {"resolution": 16})
    for sizes in ([1000], [1, 999], [7] * 142 + [6], [333, 333, 334]):
        w = codec.RowWriter("bits", np.uint8, bits.shape, {"resolution": 16})
        at = 0
        for n in sizes:
            w.write(bits[at:at + n])
            at += n
        assert w.finish() == whole
    empty = np.zeros((0, 96), np.uint8)            # an object without points: no row written
    assert codec.RowWriter("bits", np.uint8, empty.shape).finish() == \
        codec.pack({"bits": empty})
    w = codec.RowWriter("bits", np.uint8, bits.shape)
    w.write(bits[:10])
    with pytest.raises(ValueError):
        w.finish()                                 # rows missing
    with pytest.raises(ValueError):
        w.write(np.zeros((5, 95), np.uint8))       # another row length
    with pytest.raises(TypeError):
        codec.RowWriter("x", np.float32, (3,))
