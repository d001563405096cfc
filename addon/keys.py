"""Cache keys and the one cache helper shared by the frame state, the methods and the
per-pixel passes (bpy-free; no module of the add-on imported, so any may use it)."""

from __future__ import annotations

import hashlib

import numpy as np


def held(cache: dict, key, refs: tuple, compute, limit: int = 64):
    """``cache[key]``, made by ``compute()`` from the objects ``refs`` -- made again when
    missing or when it was made from other objects.  An entry keeps its ``refs`` alive,
    so ids of them in ``key`` cannot be reused meanwhile; the oldest entry goes when a
    new key would pass ``limit``."""
    refs = tuple(refs)
    entry = cache.get(key)
    if entry is None or len(entry[0]) != len(refs) or \
            not all(a is b for a, b in zip(entry[0], refs)):
        if entry is None and len(cache) >= limit:
            cache.pop(next(iter(cache)))
        entry = cache[key] = (refs, compute())
    return entry[1]


def per_visibility(cache: dict, key, bits, compute, limit: int = 64):
    """``cache[key]`` derived from ``bits`` (:func:`held` with ``bits`` as the one
    object it is made from)."""
    return held(cache, key, (bits,), compute, limit)


# Content hashes of the newest environment images, per array (held with it).  Every sync
# and every turned copy of a world shares the exported pixel array, so it is hashed
# once (an array is not modified in place; new pixels are a new array).
_CONTENT_KEYS: dict = {}


def image_key(img: np.ndarray):
    return held(_CONTENT_KEYS, id(img), (img,), lambda: (
        img.shape, hashlib.sha1(np.ascontiguousarray(img).view(np.uint8)).hexdigest()), limit=4)
