"""addon.frame.keys: the one helper every add-on cache goes through (held: made once per
object it was made from, bounded)."""


import numpy as np


def test_held_makes_once_per_refs():
    from prt_relight.addon.frame import keys
    c = keys.cache(2, name="test.held")
    a, b = np.zeros(3), np.zeros(3)
    calls = []

    def make(x):
        calls.append(x)
        return x
    assert keys.held(c, "k", (a,), lambda: make(1)) == 1
    assert keys.held(c, "k", (a,), lambda: make(2)) == 1          # same object: kept
    assert keys.held(c, "k", (b,), lambda: make(3)) == 3          # other object: made again
    keys.held(c, "x", (), lambda: make(4))
    keys.held(c, "y", (), lambda: make(5))                          # bound 2: "k" goes
    assert "k" not in c and calls == [1, 3, 4, 5]
    keys.held(c, "z", (), lambda: 6, limit=1)                       # a lower bound for a call
    assert list(c) == ["z"]
