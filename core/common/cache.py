"""The one cache policy of prt_relight: bounded, least-recently-used, thread-safe, and
listed so that the add-on's unregister empties every cache (no bpy).

* :class:`Cache` -- a mapping of at most ``limit`` entries; reading an entry makes it the
  most recent, writing past the bound drops the least recent.  Every read and write holds
  the cache's lock: the viewport shades in a worker thread (``addon.frame.engine``) while the
  main thread syncs, precomputes and draws.  Values are computed outside the lock (a
  computation may take seconds); two threads asking for a missing key at once may both
  compute it, the later write wins.
* :func:`memo` -- ``functools.lru_cache`` (bounded, thread-safe) for pure functions of
  small hashable arguments, listed like a :class:`Cache`.
* :func:`held` -- an entry made from given objects (arrays), made again when asked for
  with other ones: what a cache keyed on an array's ``id`` reads through.
* :data:`CACHES` -- every cache made by either; :func:`clear_all` empties them.

The add-on's helpers on top of it (``per_visibility``, ``image_key``) are in
``addon/frame/keys.py``; docs/README.md lists every cache with its bound.
"""

from __future__ import annotations

import functools
import sys
import threading
from collections import OrderedDict
from collections.abc import MutableMapping

#: every :class:`Cache` and :func:`memo` function made so far (module order)
CACHES: list = []


class Cache(MutableMapping):
    """A bounded LRU mapping with a lock (see the module docstring).

    ``name``: how docs and tests call it (``module.VARIABLE`` by default, found on first
    use of :attr:`name`); ``limit``: the most entries kept; ``gpu``: its values hold GPU
    objects (freed by ``addon.gpu.drawing.free_gpu_resources`` while a GPU context exists);
    ``max_bytes``: the most bytes of arrays its entries may hold together (:func:`nbytes`),
    the newest entry kept whatever its size."""

    def __init__(self, limit: int, name: str = "", gpu: bool = False, module: str = "",
                 max_bytes: int | None = None):
        if int(limit) < 1:
            raise ValueError("a cache keeps at least one entry")
        self.limit = int(limit)
        self.max_bytes = None if max_bytes is None else int(max_bytes)
        self._bytes: dict = {}
        self.gpu = bool(gpu)
        self._name = name
        self._module = module or sys._getframe(1).f_globals.get("__name__", "")
        self._data: OrderedDict = OrderedDict()
        self.lock = threading.RLock()
        CACHES.append(self)

    @property
    def name(self) -> str:
        if not self._name:
            module = sys.modules.get(self._module)
            found = [k for k, v in vars(module).items() if v is self] if module else []
            short = self._module.rsplit(".", 1)[-1]     # the module, whatever package holds it
            self._name = f"{short}.{found[0]}" if found else short
        return self._name

    def __repr__(self):
        return f"<Cache {self.name}: {len(self)}/{self.limit}>"

    # ---------------------------------------------------------------- mapping
    def __getitem__(self, key):
        with self.lock:
            value = self._data[key]
            self._data.move_to_end(key)
            return value

    def __setitem__(self, key, value):
        with self.lock:
            self._data[key] = value
            self._data.move_to_end(key)
            if self.max_bytes is not None:
                self._bytes[key] = nbytes(value)
            while len(self._data) > self.limit:
                self._drop_oldest()
            while (self.max_bytes is not None and len(self._data) > 1
                   and sum(self._bytes.values()) > self.max_bytes):
                self._drop_oldest()

    def _drop_oldest(self):
        key, _ = self._data.popitem(last=False)
        self._bytes.pop(key, None)

    @property
    def held_bytes(self) -> int:
        """Bytes of arrays its entries hold (counted only where ``max_bytes`` bounds them)."""
        with self.lock:
            return sum(self._bytes.values())

    def __delitem__(self, key):
        with self.lock:
            del self._data[key]
            self._bytes.pop(key, None)

    def __contains__(self, key):
        with self.lock:
            return key in self._data

    def __iter__(self):
        with self.lock:
            return iter(list(self._data))

    def __len__(self):
        return len(self._data)

    def get(self, key, default=None):
        with self.lock:
            if key not in self._data:
                return default
            self._data.move_to_end(key)
            return self._data[key]

    def clear(self):
        with self.lock:
            self._data.clear()
            self._bytes.clear()

    def trim(self, limit: int):
        """Drop the least recent entries until at most ``limit`` are left."""
        with self.lock:
            while len(self._data) > max(int(limit), 0):
                self._drop_oldest()


def nbytes(value) -> int:
    """Bytes of the numpy arrays in ``value`` and in the tuples, lists and dicts it holds
    (what a cache's ``max_bytes`` counts; other objects count nothing)."""
    if hasattr(value, "nbytes") and hasattr(value, "dtype"):
        return int(value.nbytes)
    if isinstance(value, (tuple, list)):
        return sum(nbytes(v) for v in value)
    if isinstance(value, dict):
        return sum(nbytes(v) for v in value.values())
    return 0


def held(cache: Cache, key, refs, compute, limit: int | None = None):
    """``cache[key]``, made by ``compute()`` from the objects ``refs`` -- made again when
    missing or when it was made from other objects.  An entry keeps its ``refs`` alive,
    so ids of them in ``key`` cannot be reused meanwhile.  The cache's bound applies
    (least recently used entries go); ``limit``, when given, lowers it for this call.
    ``compute`` runs outside the cache's lock."""
    refs = tuple(refs)
    entry = cache.get(key)
    if entry is not None and len(entry[0]) == len(refs) and \
            all(a is b for a, b in zip(entry[0], refs)):
        return entry[1]
    value = compute()
    with cache.lock:
        cache[key] = (refs, value)
        if limit is not None:
            cache.trim(limit)
    return value


def memo(maxsize: int):
    """``functools.lru_cache(maxsize)`` listed in :data:`CACHES` (cleared by
    :func:`clear_all`; ``len`` of its entry there is ``cache_info().currsize``)."""
    def wrap(fn):
        cached = functools.lru_cache(maxsize=maxsize)(fn)
        CACHES.append(_Memo(cached, f"{fn.__module__.split('.', 1)[-1]}.{fn.__name__}",
                            maxsize))
        return cached
    return wrap


class _Memo:
    """A :func:`memo` function as :data:`CACHES` lists it."""

    gpu = False

    def __init__(self, fn, name, limit):
        self.fn, self.name, self.limit = fn, name, limit

    def __len__(self):
        return self.fn.cache_info().currsize

    def clear(self):
        self.fn.cache_clear()

    def __repr__(self):
        return f"<memo {self.name}: {len(self)}/{self.limit}>"


def clear_all(gpu: bool | None = None):
    """Empty every listed cache (``gpu``: only those that hold GPU objects, or only those
    that do not; None: all)."""
    for c in CACHES:
        if gpu is None or c.gpu == gpu:
            c.clear()
