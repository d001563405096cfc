"""Versioned, compressed container for the typed arrays the add-on stores.

One blob (``bytes``) holds named numpy arrays and a small JSON ``meta`` dict::

    b"PRTB"      magic
    uint16       FORMAT, the layout version (little-endian, as every number here)
    uint32       header length H
    H bytes      UTF-8 JSON {"arrays": [[name, dtype, shape, codec, stored bytes], ...],
                             "meta": {...}}
    payload      each array's stored bytes, in header order

Codecs, lossless: ``zlib`` (the array's bytes, zlib level 6) and ``zlib-shuffle``
(byte ``k`` of every element first, then byte ``k+1``...: the exponent bytes of floats
line up, ~10 % smaller than ``zlib``).  Bit-packed visibility goes through plain zlib:
rows of neighbouring shading points (points are ordered by vertex) repeat within
zlib's 32 KB window (docs/measurements.md: 6x32^2 visibility in 30-50 bytes per
point instead of 768).

A blob of a newer layout or with an unknown codec raises :class:`NewerFormatError`,
anything malformed :class:`FormatError`: never a silently wrong array.
"""

from __future__ import annotations

import json
import struct
import zlib

import numpy as np

MAGIC = b"PRTB"
FORMAT = 1
_FIXED = struct.Struct("<4sHI")
#: element types a blob may hold (explicit byte order)
DTYPES = ("|u1", "|i1", "<u2", "<i2", "<u4", "<i4", "<i8", "<f2", "<f4", "<f8", "|b1")
CODECS = ("zlib", "zlib-shuffle")
LEVEL = 6


class FormatError(ValueError):
    """A blob that cannot be read (damaged, or not a blob at all)."""


class NewerFormatError(FormatError):
    """A blob written by a newer version (higher layout version or unknown codec)."""


def _dtype_name(dtype) -> str:
    dt = np.dtype(dtype)
    name = dt.newbyteorder("<").str if dt.itemsize > 1 else dt.str
    if name not in DTYPES:
        raise TypeError(f"cannot store arrays of {dt} (supported: {', '.join(DTYPES)})")
    return name


def _encode(a: np.ndarray, codec: str) -> bytes:
    size = a.dtype.itemsize
    raw = np.ascontiguousarray(a, dtype=a.dtype.newbyteorder("<")).reshape(-1).view(np.uint8)
    if codec == "zlib-shuffle" and size > 1:
        raw = np.ascontiguousarray(raw.reshape(-1, size).T)
    return zlib.compress(raw, LEVEL)


def _decode(data: bytes, dtype: np.dtype, shape: tuple, codec: str) -> np.ndarray:
    size = int(np.prod(shape, dtype=np.int64)) * dtype.itemsize
    try:
        raw = zlib.decompress(data)
    except zlib.error as exc:
        raise FormatError(f"damaged data ({exc})") from None
    if len(raw) != size:
        raise FormatError(f"damaged data ({len(raw)} bytes where {size} were stored)")
    flat = np.frombuffer(raw, dtype=np.uint8)
    if codec == "zlib-shuffle" and dtype.itemsize > 1:
        flat = np.ascontiguousarray(flat.reshape(dtype.itemsize, -1).T)
    out = flat.view(dtype).reshape(shape)
    out.flags.writeable = False         # decoded data is shared by caches, never edited
    return out


def pack(arrays: dict, meta: dict | None = None) -> bytes:
    """One blob of ``arrays`` (name -> array) and ``meta`` (JSON-able: str, int, float,
    bool, lists and dicts of them).  Arrays of more than one byte per element are
    byte-shuffled before zlib."""
    entries, payload = [], []
    for name, a in arrays.items():
        a = np.asarray(a)
        dt = _dtype_name(a.dtype)
        codec = "zlib-shuffle" if a.dtype.itemsize > 1 else "zlib"
        data = _encode(a, codec)
        entries.append([str(name), dt, [int(s) for s in a.shape], codec, len(data)])
        payload.append(data)
    try:
        header = json.dumps({"arrays": entries, "meta": dict(meta or {})},
                            allow_nan=True, separators=(",", ":")).encode("utf-8")
    except TypeError as exc:
        raise TypeError(f"meta must hold str, int, float, bool, lists and dicts: {exc}") from None
    return b"".join([_FIXED.pack(MAGIC, FORMAT, len(header)), header] + payload)


class RowWriter:
    """The blob of :func:`pack` of one array of one-byte elements (plain ``zlib``),
    written row block by row block as they come (in order): no copy of the whole array
    is held, only its compressed bytes (the precompute streams each traced chunk of
    visibility into it).  ``finish()`` returns the blob, byte for byte what :func:`pack`
    makes of the same rows."""

    def __init__(self, name: str, dtype, shape, meta: dict | None = None):
        self.name, self.dtype = str(name), np.dtype(dtype)
        if self.dtype.itemsize != 1:
            raise TypeError("RowWriter stores one-byte elements (plain zlib)")
        self.shape = tuple(int(s) for s in shape)
        self.meta = dict(meta or {})
        self.rows = 0
        # the deflate state (about 256 KiB) lives from the first row to the last only: a
        # precompute opens a writer per object (a thousand instances) and fills them in turn
        self._z = None
        self._flushed = False
        self._parts: list = []

    def write(self, rows: np.ndarray):
        rows = np.ascontiguousarray(rows, dtype=self.dtype)
        if rows.shape[1:] != self.shape[1:] or self.rows + len(rows) > self.shape[0]:
            raise ValueError(f"rows {rows.shape} do not continue an array of {self.shape}")
        if self._z is None:
            self._z = zlib.compressobj(LEVEL)
        self._parts.append(self._z.compress(rows.reshape(-1).view(np.uint8)))
        self.rows += len(rows)
        if self.rows == self.shape[0]:
            self._flush()

    def _flush(self):
        if not self._flushed:
            self._parts.append((self._z or zlib.compressobj(LEVEL)).flush())
            self._z, self._flushed = None, True

    def finish(self) -> bytes:
        if self.rows != self.shape[0]:
            raise ValueError(f"{self.rows} of {self.shape[0]} rows written")
        self._flush()
        data = b"".join(self._parts)
        self._parts = []
        header = json.dumps({"arrays": [[self.name, _dtype_name(self.dtype), list(self.shape),
                                         "zlib", len(data)]], "meta": self.meta},
                            allow_nan=True, separators=(",", ":")).encode("utf-8")
        return b"".join([_FIXED.pack(MAGIC, FORMAT, len(header)), header, data])


def _header(blob) -> tuple[dict, int]:
    if len(blob) < _FIXED.size:
        raise FormatError("not prt_relight data (too short)")
    magic, version, length = _FIXED.unpack_from(blob)
    if magic != MAGIC:
        raise FormatError("not prt_relight data")
    if version > FORMAT:
        raise NewerFormatError(f"stored with a newer prt_relight (layout {version}; this "
                               f"version reads layout {FORMAT})")
    if version < 1 or _FIXED.size + length > len(blob):
        raise FormatError("damaged data (bad header)")
    try:
        header = json.loads(bytes(blob[_FIXED.size:_FIXED.size + length]).decode("utf-8"))
        arrays, meta = header["arrays"], header["meta"]
    except (ValueError, KeyError, TypeError):
        raise FormatError("damaged data (bad header)") from None
    if not isinstance(arrays, list) or not isinstance(meta, dict):
        raise FormatError("damaged data (bad header)")
    return header, _FIXED.size + length


def read_meta(blob) -> dict:
    """``meta`` of a blob without decompressing its arrays."""
    return _header(blob)[0]["meta"]


def unpack(blob) -> tuple[dict, dict]:
    """``(arrays, meta)`` of a blob made by :func:`pack`; the arrays are read-only."""
    header, at = _header(blob)
    view = memoryview(blob)
    out = {}
    for entry in header["arrays"]:
        try:
            name, dt, shape, codec, n = entry
            shape = tuple(int(s) for s in shape)
            n = int(n)
        except (TypeError, ValueError):
            raise FormatError("damaged data (bad array entry)") from None
        if codec not in CODECS:
            raise NewerFormatError(f"stored with a newer prt_relight (unknown codec '{codec}')")
        if dt not in DTYPES or min(shape, default=0) < 0 or n < 0 or at + n > len(blob):
            raise FormatError(f"damaged data (array '{name}')")
        out[name] = _decode(view[at:at + n], np.dtype(dt), shape, codec)
        at += n
    if at != len(blob):
        raise FormatError("damaged data (trailing bytes)")
    return out, header["meta"]
