# SPDX-License-Identifier: GPL-3.0-or-later
"""Precompute benchmark: the Stanford bunny on a ground grid under a bundled HDRI.

    python bench/bench_precompute.py [--mesh PATH] [--hdri sunset]
                                     [--resolution 640x480] [--subset 3000]

Prints (and writes to out/bench/precompute.txt):

1. the add-on's precompute time split (export, BVH build, rays, encode, storage) and
   its rays/s on the whole scene;
2. ray throughput of ``core.scene.visibility.trace_visibility`` (default threads)
   against ONE bare single-threaded embreex ``scene.run(..., query='OCCLUDED')``
   over exactly the same rays, on a fixed random subset of shading points
   (the full ray set does not fit in memory as one call); target ours/bare >= 1.6
   with 2 threads;
3. F12 time of PRT_RELIGHT against Workbench on the same scene and resolution.
"""

from __future__ import annotations

import argparse
import os
import pathlib
import sys
import time

import numpy as np

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))
import scenes  # noqa: E402

DEFAULT_MESH = scenes.ROOT.parent / "shared/data/meshes/stanford-bunny.obj"


def parse_args(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--mesh", type=pathlib.Path, default=DEFAULT_MESH)
    p.add_argument("--hdri", default="sunset")
    p.add_argument("--resolution", default="640x480", help="F12 size, WIDTHxHEIGHT")
    p.add_argument("--subset", type=int, default=3000,
                   help="shading points (fixed random subset) for the bare-Embree comparison")
    p.add_argument("--repeat", type=int, default=3, help="best of N for the ray timings")
    p.add_argument("--out-file", type=pathlib.Path,
                   default=scenes.ROOT / "out/bench/precompute.txt")
    args = p.parse_args(argv)
    if not args.mesh.is_file():
        p.error(f"mesh not found: {args.mesh}\n  (expected the Stanford bunny OBJ at "
                f"{DEFAULT_MESH}; pass --mesh PATH)")
    try:
        args.size = tuple(int(v) for v in args.resolution.lower().split("x"))
    except ValueError:
        p.error("--resolution must look like 640x480")
    return args


def best_of(n, fn):
    best, result = float("inf"), None
    for _ in range(max(1, n)):
        t0 = time.perf_counter()
        result = fn()
        best = min(best, time.perf_counter() - t0)
    return best, result


def main(argv=None):
    args = parse_args(argv)
    import bpy
    scenes.reset()                                   # also registers prt_relight
    from prt_relight.addon.blender import precompute as pc
    from prt_relight.core.sphere import directions
    from prt_relight.core.scene import visibility
    from prt_relight.core.common import parallel

    scenes.add_world(args.hdri)
    scenes.add_ground()
    bunny = scenes.add_obj(args.mesh)
    scenes.add_camera(target=(0.0, 0.0, 0.7), resolution=args.size)
    tri = sum(len(o.evaluated_get(bpy.context.evaluated_depsgraph_get()).data.polygons)
              for o in bpy.context.scene.objects if o.type == "MESH")
    threads = parallel.default_threads()

    # 1. the add-on's precompute on the whole scene
    t = scenes.precompute(resolution=32)
    accounted = (t["export"] + t["build_bvh"] + t["rays"] + t["tessellation_check"]
                 + t["encode"] + t["storage"])

    # 2. the same rays, ours vs one bare single-threaded Embree call (fixed subset)
    job = pc.gather(bpy.context.evaluated_depsgraph_get(), bpy.context.scene.prt)
    pts = np.concatenate([o.points.positions for o in job.objects])
    nrm = np.concatenate([o.points.normals for o in job.objects])
    rng = np.random.default_rng(0)
    idx = np.sort(rng.choice(len(pts), size=min(args.subset, len(pts)), replace=False))
    pts, nrm = pts[idx], nrm[idx]
    cube = directions.cubemap(job.resolution)
    escene = visibility.build_occluder_scene(job.occluders)
    # The exact rays trace_visibility casts (its lower-hemisphere slots are skipped).
    origins, rays, mask = visibility.hemisphere_rays(pts, nrm, cube, job.offset)
    nrays = len(rays)

    def bare():
        return escene.run(origins, rays, query="OCCLUDED")

    def ours():
        return visibility.trace_visibility(escene, pts, nrm, cube, job.offset)

    def ours_1t():
        return visibility.trace_visibility(escene, pts, nrm, cube, job.offset, threads=1)

    bare(); ours()                                   # warm up (BVH commit, page faults)
    bare_s, hit = best_of(args.repeat, bare)
    ours_s, bits = best_of(args.repeat, ours)
    ours1_s, _ = best_of(1, ours_1t)
    mask[mask] = np.asarray(hit) == -1
    agree = bool(np.array_equal(np.packbits(mask, axis=1), bits))
    del origins, rays, hit, mask

    # 3. F12: ours vs Workbench, same scene and resolution (cold = first render)
    prt_cold = scenes.render_prt(args.out_file.parent / "bench_prt.exr")
    wb_cold = scenes.render_workbench()
    prt_warm = scenes.render_prt(args.out_file.parent / "bench_prt.exr")
    wb_warm = scenes.render_workbench()
    ss = bpy.context.scene.prt.supersampling

    w, h = args.size
    rows = [
        ("scene", f"{args.mesh.name} + 96x96 grid, {tri} faces, HDRI {args.hdri}, "
                  f"{os.cpu_count()} cores"),
        ("shading points", f"{t['points']}"),
        ("rays (6x32x32, hemisphere)", f"{t['ray_count'] / 1e6:.1f} M"),
        ("precompute: export", f"{t['export']:.2f} s"),
        ("precompute: BVH build", f"{t['build_bvh']:.2f} s"),
        ("precompute: rays", f"{t['rays']:.2f} s"),
        ("precompute: tessellation check", f"{t['tessellation_check']:.2f} s"),
        ("precompute: visibility encode (zlib, worker)", f"{t['encode']:.2f} s"),
        ("precompute: storage", f"{t['storage']:.2f} s"),
        ("precompute: other", f"{t['total'] - accounted:.2f} s"),
        ("precompute: total", f"{t['total']:.2f} s"),
        ("ours, whole scene", f"{t['rays_per_second'] / 1e6:.2f} M rays/s ({threads} threads)"),
        ("subset", f"{len(idx)} points, {nrays / 1e6:.2f} M rays, best of {args.repeat}"),
        ("bare embreex, 1 call 1 thread", f"{bare_s:.3f} s = {nrays / bare_s / 1e6:.2f} M rays/s"),
        (f"trace_visibility, {threads} threads", f"{ours_s:.3f} s = "
                                                 f"{nrays / ours_s / 1e6:.2f} M rays/s"),
        ("trace_visibility, 1 thread", f"{ours1_s:.3f} s = {nrays / ours1_s / 1e6:.2f} M rays/s"),
        ("RATIO ours/bare (target >= 1.6)", f"{bare_s / ours_s:.2f}"
                                            f"{'' if bare_s / ours_s >= 1.6 else '  BELOW TARGET'}"),
        ("ours == bare bits", "yes" if agree else "NO (mismatch!)"),
        (f"F12 {w}x{h} PRT_RELIGHT cold/warm", f"{prt_cold:.2f} / {prt_warm:.2f} s "
                                             f"(supersampling x{ss})"),
        (f"F12 {w}x{h} Workbench cold/warm", f"{wb_cold:.2f} / {wb_warm:.2f} s"),
        ("RATIO F12 PRT/Workbench cold/warm", f"{prt_cold / wb_cold:.2f} / {prt_warm / wb_warm:.2f}"),
    ]
    width = max(len(k) for k, _ in rows)
    table = "\n".join(f"{k:<{width}}  {v}" for k, v in rows) + "\n"
    args.out_file.parent.mkdir(parents=True, exist_ok=True)
    args.out_file.write_text(table)
    print(table, end="")
    print(f"(written to {args.out_file})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
