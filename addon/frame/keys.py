"""Cache keys and the one cache helper shared by the frame state, the methods and the
per-pixel passes (bpy-free; imports no module of the add-on, so any may use it).

Every cache of the add-on is a :class:`core.common.cache.Cache` made with :func:`cache` (or
``drawing.gpu_cache`` for GPU objects): an LRU bounded by its ``limit``, locked for each
read and write (the viewport shades in a worker thread), emptied by :func:`free` when the
add-on is unregistered.  :func:`held` is how entries are made.  docs/README.md lists every
cache with its bound.
"""

from __future__ import annotations

import hashlib
import sys

import numpy as np

from ...core.sphere import envmap
from ...core.common.cache import CACHES, Cache, clear_all, held

__all__ = ["CACHES", "Cache", "cache", "held", "per_visibility", "image_key", "env_key",
           "environment_cubemap", "free"]


def cache(limit: int, name: str = "", max_bytes: int | None = None) -> Cache:
    """A new cache of at most ``limit`` entries (and ``max_bytes`` of arrays when given),
    listed for :func:`free` (named after the calling module's variable unless ``name`` is
    given)."""
    return Cache(limit, name, module=sys._getframe(1).f_globals.get("__name__", ""),
                 max_bytes=max_bytes)


def per_visibility(cache: Cache, key, bits, compute, limit: int | None = None):
    """``cache[key]`` derived from ``bits`` (:func:`held` with ``bits`` as the one
    object it is made from)."""
    return held(cache, key, (bits,), compute, limit)


# Content hashes of the newest environment images, per array (held with it).  Every sync
# and every turned copy of a world shares the exported pixel array, so it is hashed
# once (an array is not modified in place; new pixels are a new array).
_CONTENT_KEYS = cache(4)


def image_key(img: np.ndarray):
    return held(_CONTENT_KEYS, id(img), (img,), lambda: (
        img.shape, hashlib.sha1(np.ascontiguousarray(img).view(np.uint8)).hexdigest()))


def env_key(world: envmap.WorldLighting, resolution: int):
    """Key of the lighting: its content (the image's pixels hashed once per array),
    strength, rotation and the cubemap resolution."""
    img = world.image
    ident = (("color",) + tuple(float(c) for c in world.color) if img is None
             else image_key(img))
    return (ident, float(world.strength), world.rotation.round(9).tobytes(), resolution)


# Area-resampled environment of the newest lighting (a turned world is a new one).
_ENV_CACHE = cache(1)


def environment_cubemap(world: envmap.WorldLighting, resolution: int) -> envmap.CubeLighting:
    """The world resampled to the cubemap of ``resolution`` (kept for the newest lighting)."""
    return held(_ENV_CACHE, env_key(world, resolution), (),
                lambda: world.to_cubemap(resolution))


def free():
    """Empty every cache (the add-on's unregister; GPU ones too)."""
    clear_all()
