# SPDX-License-Identifier: GPL-3.0-or-later
"""Error against converged Cycles where Cycles itself is noisy: bench_lights' *sun* scene (a
1-pixel sun of 2·10⁴ over a dim sky; Cycles' 1024 spp frames differ from each other by
3-16 % rel-L2 there, fireflies) rendered by Cycles with N seeds.

    python bench/bench_sun_seeds.py [--seeds 12] [--spp 1024] [--size 128 96]
                                    [--methods REFERENCE,SH,...] [--out out/bench_sun_seeds]

For a method's frame ``o``, the Cycles frames ``c_i`` and their mean ``m``:
``E|o - m|² = |o - t|² + σ²/N`` (``t`` the converged frame, ``σ²`` the per-seed variance,
estimated without bias by ``Σ|c_i - m|² / (N - 1)``), so the error against converged Cycles
is estimated as ``sqrt(|o - m|² - σ²/N) / |m|``; printed with the raw figure and the mean's
own noise.  Cycles frames are kept and reused (per seed, size and spp).
"""

from __future__ import annotations

import argparse
import pathlib
import sys

import numpy as np

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))
import bench_lights  # noqa: E402
import scenes  # noqa: E402


def converged_error(ours, frames):
    """(rel-L2 against the mean, the mean's noise, estimated rel-L2 against converged)."""
    C = np.stack(frames)[..., :3].astype(np.float64)
    n = len(frames)
    mean = C.mean(0)
    mask = np.stack(frames)[..., 3].mean(0) > 0.5
    norm = float((mean ** 2).sum(-1)[mask].sum())
    var = float(sum(((c - mean) ** 2).sum(-1)[mask].sum() for c in C)) / (n - 1)
    e2 = float(((ours[..., :3] - mean) ** 2).sum(-1)[mask].sum())
    return (np.sqrt(e2 / norm), np.sqrt(var / n / norm),
            np.sqrt(max(e2 - var / n, 0.0) / norm))


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
        raw, noise, est = converged_error(scenes.read_exr(out / f"{m}.exr"), frames)
        print(f"| {m} | {100 * raw:.2f} % | {100 * noise:.2f} % | {100 * est:.2f} % |",
              flush=True)


if __name__ == "__main__":
    main()
