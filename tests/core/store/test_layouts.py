"""core.store.layouts: the stored visibility's blob (bit-packed rows over the 6N^2 texels,
compressed as traced) round-trips bit for bit, the streaming writer makes the very blob of
the whole array, and a blob of the wrong shape or type is refused.  No bpy."""

from __future__ import annotations

import numpy as np
import pytest

from prt_relight.core.common import codec
from prt_relight.core.store import layouts


def _bits(points, resolution, seed=0):
    """Random visibility with runs (what a trace gives: long stretches of 0 and 1)."""
    rng = np.random.default_rng(seed)
    texels = 6 * resolution * resolution
    runs = np.cumsum(rng.integers(1, 40, size=(points, texels)), axis=1) // 97 % 2
    return np.packbits(runs.astype(bool), axis=1)


@pytest.mark.parametrize("resolution", [4, 16, 32])
def test_blob_round_trips_the_bits_and_names_the_resolution(resolution):
    bits = _bits(50, resolution)
    blob = layouts.visibility_blob(bits, resolution)
    back = layouts.visibility_of_blob(blob)
    assert back.dtype == np.uint8 and back.shape == (50, 6 * resolution ** 2 // 8)
    np.testing.assert_array_equal(back, bits)
    assert not back.flags.writeable                      # a view of the stored data
    arrays, meta = codec.unpack(blob)
    assert set(arrays) == {"bits"} and meta == {"resolution": resolution}
    assert len(blob) < bits.nbytes                       # compressed


def test_writer_fed_rows_in_any_block_size_makes_the_same_blob():
    """The trace streams rows in chunks of any size; the blob is the one of the whole array,
    so a stored precompute does not depend on the threads or chunks that made it."""
    bits = _bits(203, 16, seed=3)
    whole = layouts.visibility_blob(bits, 16)
    for step in (1, 7, 64, 203):
        w = layouts.visibility_writer(len(bits), 16)
        for a in range(0, len(bits), step):
            w.write(bits[a:a + step])
        assert w.finish() == whole, step


def test_zero_points_make_a_valid_empty_blob():
    empty = np.zeros((0, 6 * 8 * 8 // 8), np.uint8)
    blob = layouts.visibility_blob(empty, 8)
    assert layouts.visibility_of_blob(blob).shape == (0, 48)
    w = layouts.visibility_writer(0, 8)
    assert w.finish() == blob


@pytest.mark.parametrize("bits, resolution", [
    (np.zeros((4, 48), np.uint8), 16),            # rows of another resolution
    (np.zeros((4, 48), np.int32), 8),             # not bytes
    (np.zeros(48, np.uint8), 8),                  # not one row per point
    (np.zeros((4, 47), np.uint8), 8),             # a partial row
])
def test_bits_of_the_wrong_shape_or_type_are_refused(bits, resolution):
    with pytest.raises(ValueError, match="visibility must be"):
        layouts.visibility_blob(bits, resolution)


def test_the_blob_names_are_the_stored_keys():
    """The names every method's stored data is keyed by (addon.blender.storage) are
    distinct, non-empty strings."""
    names = [layouts.VISIBILITY, layouts.SHADOW_FIELD]
    assert all(isinstance(n, str) and n for n in names) and len(set(names)) == len(names)
