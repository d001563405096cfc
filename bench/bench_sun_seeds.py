# SPDX-License-Identifier: GPL-3.0-or-later
"""Error against converged Cycles where Cycles itself is noisy: bench_lights' *sun* scene (a
1-pixel sun of 2·10⁴ over a dim sky; Cycles' 1024 spp frames differ from each other by
3-16 % rel-L2 there, fireflies) rendered by Cycles with N seeds.

    python bench/bench_sun_seeds.py [--seeds 12] [--spp 1024] [--size 128 96]
                                    [--methods REFERENCE,SH,...] [--out out/bench_sun_seeds]

The error against converged Cycles is ``core.report.metrics.rel_l2_converged`` (the per-seed
variance subtracted), printed with the raw figure and the mean's own noise.  Cycles frames are kept and reused (per seed, size and spp).
"""

from __future__ import annotations

import argparse
import pathlib
import sys

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))
import bench_lights  # noqa: E402
import scenes  # noqa: E402
from prt_relight.core.report.metrics import rel_l2_converged  # noqa: E402  (scenes registers it)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--seeds", type=int, default=12)
    ap.add_argument("--spp", type=int, default=1024)
    ap.add_argument("--size", type=int, nargs=2, default=[128, 96])
    ap.add_argument("--methods", default=",".join(bench_lights.METHODS + ["BLOCKS"]))
    ap.add_argument("--out", default="out/bench_sun_seeds")
    args = ap.parse_args()
    import bpy
    out = scenes.ROOT / args.out
    out.mkdir(parents=True, exist_ok=True)
    bench_lights.build("sun")
    sc = bpy.context.scene
    sc.render.resolution_x, sc.render.resolution_y = args.size
    scenes.precompute(32)
    w, h = args.size
    frames = []
    for s in range(args.seeds):
        p = out / f"cycles_{w}x{h}_{args.spp}_{s}.exr"
        if not p.exists():
            scenes.render_cycles(p, samples=args.spp, seed=s)
        frames.append(scenes.read_exr(p))
    print(f"sun scene {w}×{h}, Cycles {args.seeds} seeds × {args.spp} spp")
    print("| method | vs the mean | the mean's noise | est. vs converged |")
    print("|---|---|---|---|")
    for m in args.methods.split(","):
        sc.prt.method = m
        scenes.render_prt(out / f"{m}.exr")
        raw, noise, est = rel_l2_converged(scenes.read_exr(out / f"{m}.exr"), frames)
        print(f"| {m} | {100 * raw:.2f} % | {100 * noise:.2f} % | {100 * est:.2f} % |",
              flush=True)


if __name__ == "__main__":
    main()
