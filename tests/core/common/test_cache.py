"""core.common.cache: the one cache policy (bounded LRU, thread-safe, listed) -- no Blender."""

import threading

import numpy as np
import pytest

from prt_relight.core.common import cache as core_cache
from prt_relight.core.common.cache import Cache, memo


def test_bound_and_least_recently_used_goes():
    c = Cache(3, name="test.lru")
    for k in "abc":
        c[k] = k.upper()
    assert c["a"] == "A"                  # read: "a" is now the most recent
    c["d"] = "D"                          # past the bound: "b" (least recent) goes
    assert list(c) == ["c", "a", "d"] and len(c) == 3
    assert c.get("b") is None and "b" not in c
    c.trim(1)
    assert list(c) == ["d"]
    with pytest.raises(ValueError):
        Cache(0)


def test_listed_and_cleared():
    c = Cache(2, name="test.listed")
    c[1] = 1

    @memo(4)
    def square(x):
        return x * x

    square(3)
    names = {getattr(x, "name", "") for x in core_cache.CACHES}
    assert {"test.listed"} <= names and any(n.endswith(".square") for n in names)
    core_cache.clear_all()
    assert len(c) == 0 and square.cache_info().currsize == 0


def test_default_name_is_the_module_variable():
    assert _MODULE_CACHE.name == "test_cache._MODULE_CACHE"


_MODULE_CACHE = Cache(1)


def test_threads_never_see_a_broken_cache():
    """Readers and writers in several threads at once (the viewport worker and the main
    thread): no error, the bound holds, every value read is the one written for its key."""
    c = Cache(16, name="test.threads")
    errors = []

    def work(seed):
        rng = np.random.default_rng(seed)
        try:
            for _ in range(3000):
                k = int(rng.integers(64))
                if rng.random() < 0.5:
                    c[k] = ("value", k)
                else:
                    got = c.get(k)
                    assert got is None or got == ("value", k)
                if rng.random() < 0.01:
                    list(c)
                    c.trim(8)
        except Exception as exc:           # pragma: no cover - what the test looks for
            errors.append(exc)

    threads = [threading.Thread(target=work, args=(s,)) for s in range(8)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert not errors and len(c) <= 16


def test_a_bound_in_bytes_drops_the_least_recent_arrays_and_keeps_the_newest():
    c = Cache(100, name="test.bytes", max_bytes=3000)
    kb = lambda: (np.zeros(125), {"meta": 1})              # noqa: E731  1000 bytes an entry
    for k in "abc":
        c[k] = kb()
    assert c.held_bytes == 3000 and len(c) == 3
    c.get("a")
    c["d"] = kb()                          # past 3000 bytes: "b", the least recent, goes
    assert list(c) == ["c", "a", "d"] and c.held_bytes == 3000
    c["big"] = {"bits": np.zeros(1000)}    # bigger than the bound alone: kept, alone
    assert list(c) == ["big"] and c.held_bytes == 8000
    del c["big"]
    assert c.held_bytes == 0
    assert core_cache.nbytes(((np.zeros(2), [np.zeros(3, np.float32)]), "x")) == 28
