# SPDX-License-Identifier: GPL-3.0-or-later
"""Frame cost per lamp (issue 31): an interior lit by 0 to 64 spots in rows
(``scenes.spot_rows_scene``), every lamp and its shadow drawn per pixel by the lamp pass
(addon/gpu/lights.py), the frame time against the number of lamps and its least-squares
slope, the cost of one more lamp.

    python bench/bench_lamps.py [--counts 0,1,4,16,64] [--method SH] [--size 128x96]
                                [--spot-deg 50] [--append docs/measurements.md]

Per count: "frame" draws the frame again with the shadow maps cached (the World or the
camera changed), "lamps moved" moves every lamp first (its shadow faces drawn again),
both one sample per pixel (a viewport frame, ``engine.render_pixels`` inside a render) and
with the scene's Anti-Aliasing (F12's samples).  The method's own shading does not depend
on the lamps (SH by default: its per-vertex shading is the cheapest, so the lamps' share
shows).  Times are the best of five frames (the least disturbed on a shared machine).
"""

from __future__ import annotations

import argparse
import pathlib
import sys
import time

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))
import scenes  # noqa: E402

import numpy as np  # noqa: E402


def best_time(fn, repeats=5):
    """The least of ``repeats`` timings (the run least disturbed by other processes)."""
    out = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        out.append(time.perf_counter() - t0)
    return min(out)


def measure(count, method, width, height, spot_deg=50.0):
    """(viewport frame, viewport frame with the lamps moved, F12 frame, F12 frame with the
    lamps moved) in seconds, and the shadow plan's messages, for ``count`` spots."""
    import bpy
    scene = scenes.spot_rows_scene(count, spot_deg=spot_deg)
    scenes.set_resolution(width, height)
    scene.prt.method = method
    scenes.precompute(32, method=method)
    from prt_relight.addon.frame.engine import in_render, render_pixels, render_view
    from prt_relight.addon.frame.state import FrameState
    lamps = [ob for ob in scene.objects if ob.type == "LIGHT"]
    aa = scene.prt.supersampling

    def task(depsgraph):
        state = FrameState()
        state.sync(depsgraph)
        view, proj, w, h, persp = render_view(scene, depsgraph)
        out = []
        for s in (1, aa):
            def frame():
                render_pixels(state, view, proj, w, h, True, persp, s)
            frame()                                               # caches
            out.append(best_time(frame))
            step = [0.0]

            def moved():
                # a new placement of every lamp: its shadow faces are drawn again
                step[0] += 1e-3
                for lamp in state.drawn_lamps:
                    lamp.position = np.asarray(lamp.position) + (0.0, 0.0, step[0])
                frame()
            out.append(best_time(moved) if lamps else out[-1])
        return out, list(state.warnings)
    (view1, moved1, f12, moved_f12), messages = in_render(scene, task)
    return (view1, moved1, f12, moved_f12), [m for m in messages if "Shadow maps" in m], aa


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--counts", default="0,1,4,16,64")
    ap.add_argument("--method", default="SH")
    ap.add_argument("--size", default="128x96")
    ap.add_argument("--spot-deg", type=float, default=50.0,
                    help="the spots' cone (50°: 64 spots light each floor point ~6 times)")
    ap.add_argument("--append", default=None, help="append the table to this markdown file")
    args = ap.parse_args(sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else None)
    width, height = map(int, args.size.split("x"))
    counts = [int(c) for c in args.counts.split(",")]
    rows, times = [], []
    aa = 1
    for n in counts:
        got, messages, aa = measure(n, args.method, width, height, args.spot_deg)
        times.append(got)
        row = (f"| {n} | " + " | ".join(f"{1e3 * t:.0f} ms" for t in got) + " | "
               + ("; ".join(messages) or "full-size shadow maps") + " |")
        print(row, flush=True)
        rows.append(row)
    # the slope over the counts with lamps (the first lamp also brings the pass itself)
    lit = [k for k, n in enumerate(counts) if n > 0]
    T = np.asarray(times)[lit]
    A = np.stack([np.ones(len(lit)), np.asarray(counts, float)[lit]], 1)
    slope = np.linalg.lstsq(A, T, rcond=None)[0][1] if len(lit) > 1 else np.zeros(4)
    lines = [f"Frame cost per lamp ({args.method}, {width}×{height}, {args.spot_deg:g}° spots in "
             f"rows over a "
             f"floor with three Suzannes, `make bench-lamps`):", "",
             f"| lamps | viewport frame | lamps moved | F12 ({aa}² samples) | F12, lamps moved "
             "| shadow maps |", "|---|---|---|---|---|---|", *rows,
             "| per lamp (least squares over 1+ lamps) | " + " | ".join(f"{1e3 * s:.1f} ms" for s in slope)
             + " | |", ""]
    print("\n".join(lines))
    if args.append:
        with open(args.append, "a", encoding="utf-8") as f:
            f.write("\n" + "\n".join(lines))


if __name__ == "__main__":
    main()
