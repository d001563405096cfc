"""The parallel runner every core computation shares: blocks of points on all cores
(numpy's large array passes and Embree release the GIL), progress ticks, cancellation."""

from __future__ import annotations

import os
from concurrent.futures import ThreadPoolExecutor

#: points per vectorised block at 6x32^2 with two threads; (block, 6*N*N) float32
#: temporaries.  With more threads blocks shrink (:func:`block_points`), so the points in
#: flight -- and the temporaries' memory -- stay the same on any number of cores.
BLOCK_POINTS = 256


def block_points(resolution: int, per_block: int = BLOCK_POINTS) -> int:
    """Points per block at a cubemap ``resolution``: ``per_block`` at 6x32^2 with two
    threads, fewer at finer cubemaps and with more threads (at least 16)."""
    threads = max(2, os.cpu_count() or 1)
    return max(16, per_block * 32 * 32 * 2 // (resolution ** 2 * threads))


def block_spans(count, block):
    for start in range(0, count, block):
        yield start, min(count, start + block)


def for_blocks(count, block, fn, tick=None):
    """Call ``fn(a, b)`` for every block of points; blocks run on all cores (numpy's
    large ufuncs and matrix products release the GIL) and write disjoint rows.

    ``tick(fraction)`` is called in the calling thread as blocks finish (in order); it
    may raise (e.g. ``visibility.Cancelled`` on ESC): blocks not started are dropped."""
    spans = list(block_spans(count, block))
    threads = min(len(spans), os.cpu_count() or 1)
    if threads <= 1:
        for k, (a, b) in enumerate(spans):
            fn(a, b)
            if tick is not None:
                tick((k + 1) / len(spans))
        return
    with ThreadPoolExecutor(max_workers=threads) as pool:
        futures = [pool.submit(fn, a, b) for a, b in spans]
        try:
            for k, f in enumerate(futures):
                f.result()
                if tick is not None:
                    tick((k + 1) / len(futures))
        except BaseException:
            for f in futures:
                f.cancel()
            raise


def part(tick, lo: float, hi: float):
    """``tick`` for a part ``[lo, hi]`` of the work (None stays None)."""
    if tick is None:
        return None
    return lambda fraction: tick(lo + (hi - lo) * fraction)


class Cancelled(Exception):
    """Raised when a cancel callback asks the trace to stop."""


def default_threads() -> int:
    """Two threads per core: Embree releases the GIL, numpy's ray set-up does not,
    and oversubscribing lets one thread's set-up overlap the others' tracing."""
    return max(2, 2 * (os.cpu_count() or 1))


def in_threads(tasks, fn, threads):
    """``fn(task_list)`` for ``threads`` interleaved shares of ``tasks`` (in this thread
    when there is one share); numpy releases the GIL inside the large array passes."""
    threads = max(1, min(int(threads or os.cpu_count() or 1), len(tasks)))
    if threads <= 1:
        fn(tasks)
        return
    with ThreadPoolExecutor(max_workers=threads) as pool:
        for f in [pool.submit(fn, tasks[i::threads]) for i in range(threads)]:
            f.result()


def for_chunks(count: int, chunk: int, fn, threads: int | None = None):
    """``fn(a, b)`` over chunks of ``range(count)`` on all cores; returns the results in order."""
    spans = list(enumerate((a, min(count, a + chunk)) for a in range(0, count, chunk)))
    out = [None] * len(spans)

    def run(share):
        for i, (a, b) in share:
            out[i] = fn(a, b)

    in_threads(spans, run, threads)
    return out
