"""core.common.parallel: the block sizes (their definition on any core count), every point in
exactly one block, ticks in order in the calling thread, cancellation that drops the blocks
not started, the interleaved shares and ordered chunk results against serial runs.  No bpy."""

from __future__ import annotations

import threading
import time

import numpy as np
import pytest

from prt_relight.core.common import parallel


@pytest.mark.parametrize("cores", [1, 2, 4, 16, 64])
def test_block_points_keep_the_points_in_flight_on_any_core_count(cores, monkeypatch):
    """BLOCK_POINTS at 6x32^2 with two threads; fewer with finer cubemaps and more threads
    (the temporaries of all threads stay the same), at least 16."""
    monkeypatch.setattr(parallel.os, "cpu_count", lambda: cores)
    threads = max(2, cores)
    for resolution in (8, 16, 32, 64, 128):
        got = parallel.block_points(resolution)
        want = max(16, parallel.BLOCK_POINTS * 32 * 32 * 2 // (resolution ** 2 * threads))
        assert got == want
        if got > 16:                        # above the floor: the same points x texels x threads
            in_flight = got * resolution ** 2 * threads
            assert abs(in_flight - parallel.BLOCK_POINTS * 32 ** 2 * 2) <= resolution ** 2 * threads
    monkeypatch.setattr(parallel.os, "cpu_count", lambda: None)    # unknown: two threads
    assert parallel.block_points(32) == parallel.BLOCK_POINTS
    assert parallel.block_points(32, per_block=64) == 64


@pytest.mark.parametrize("count, block", [(0, 5), (1, 5), (10, 5), (11, 5), (7, 100), (100, 1)])
def test_block_spans_cover_the_range_once_in_order(count, block):
    spans = list(parallel.block_spans(count, block))
    covered = [i for a, b in spans for i in range(a, b)]
    assert covered == list(range(count))
    assert all(0 < b - a <= block for a, b in spans)
    assert len(spans) == -(-count // block)


@pytest.mark.parametrize("cores", [1, 2, 4])
def test_for_blocks_writes_every_row_once_and_ticks_in_order(cores, monkeypatch):
    monkeypatch.setattr(parallel.os, "cpu_count", lambda: cores)
    out = np.zeros(103, int)
    calls, ticks, tick_threads = [], [], set()

    def fn(a, b):
        calls.append((a, b))
        out[a:b] += 1

    def tick(fraction):
        ticks.append(fraction)
        tick_threads.add(threading.get_ident())

    parallel.for_blocks(103, 10, fn, tick)
    assert (out == 1).all() and sorted(calls) == list(parallel.block_spans(103, 10))
    assert ticks == [(k + 1) / 11 for k in range(11)]                 # in order, to 1
    assert tick_threads == {threading.get_ident()}                    # the caller's thread
    parallel.for_blocks(0, 10, fn)                                    # nothing to do


def test_a_tick_that_raises_stops_and_drops_the_blocks_not_started(monkeypatch):
    """ESC: the tick raises Cancelled after the first block; it reaches the caller and
    the blocks still queued are never run."""
    monkeypatch.setattr(parallel.os, "cpu_count", lambda: 2)
    started = []

    def fn(a, b):
        started.append(a)
        time.sleep(0.01)

    def tick(fraction):
        raise parallel.Cancelled()

    with pytest.raises(parallel.Cancelled):
        parallel.for_blocks(400, 1, fn, tick)
    time.sleep(0.05)                        # let blocks already running finish
    assert 1 <= len(started) < 400


def test_an_error_in_a_block_reaches_the_caller(monkeypatch):
    monkeypatch.setattr(parallel.os, "cpu_count", lambda: 2)

    def fn(a, b):
        if a == 30:
            raise ZeroDivisionError("block 30")

    with pytest.raises(ZeroDivisionError, match="block 30"):
        parallel.for_blocks(100, 10, fn)


def test_part_maps_a_fraction_into_its_share_of_the_work():
    seen = []
    first, second = parallel.part(seen.append, 0.0, 0.25), parallel.part(seen.append, 0.25, 1.0)
    for f in (0.0, 0.5, 1.0):
        first(f)
    for f in (0.0, 0.5, 1.0):
        second(f)
    assert seen == pytest.approx([0.0, 0.125, 0.25, 0.25, 0.625, 1.0])
    assert parallel.part(None, 0.2, 0.4) is None


def test_default_threads_are_two_per_core(monkeypatch):
    for cores, want in ((None, 2), (1, 2), (2, 4), (8, 16)):
        monkeypatch.setattr(parallel.os, "cpu_count", lambda c=cores: c)
        assert parallel.default_threads() == want


@pytest.mark.parametrize("threads", [None, 1, 2, 3, 50])
def test_in_threads_hands_every_task_to_exactly_one_share(threads):
    tasks = list(range(17))
    shares, lock = [], threading.Lock()

    def fn(share):
        with lock:
            shares.append((threading.get_ident(), list(share)))

    parallel.in_threads(tasks, fn, threads)
    assert sorted(t for _, share in shares for t in share) == tasks
    expected = max(1, min(int(threads or parallel.os.cpu_count() or 1), len(tasks)))
    assert len(shares) == expected
    if expected == 1:                                     # one share: in this thread
        assert shares[0][0] == threading.get_ident()
    else:                                                 # interleaved: task i in share i % k
        for _, share in shares:
            assert len({t % expected for t in share}) == 1


@pytest.mark.parametrize("count, chunk, threads", [(0, 4, 2), (10, 3, 1), (10, 3, 4), (57, 8, 3)])
def test_for_chunks_returns_the_results_in_order(count, chunk, threads):
    def fn(a, b):
        return np.arange(a, b) ** 2

    got = parallel.for_chunks(count, chunk, fn, threads)
    assert len(got) == -(-count // chunk)
    joined = np.concatenate(got) if got else np.zeros(0, int)
    np.testing.assert_array_equal(joined, np.arange(count) ** 2)
