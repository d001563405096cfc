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

The storage benchmark: stored bytes per shading point, decode time and .blend growth.

    python bench/bench_precompute.py storage [--mesh PATH ...] [--suzanne SUBDIV ...]
                                             [--resolution 32]

Each case is one object on the ground grid (``scenes.add_ground``) under a bundled
HDRI, precomputed with REFERENCE.  Per object it prints the points, the stored
visibility blob (``addon.blender.storage``) in bytes per point against the 6N^2/8 bit-packed
bytes, and the best-of-N time to read the blob back from the object and decode it; per
case the trace and encode (zlib, all objects) times and the growth of the saved .blend.
Writes out/bench/storage.txt as well.
"""

from __future__ import annotations

import argparse
import os
import pathlib
import sys
import tempfile
import time

import numpy as np

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))
import scenes  # noqa: E402

MESHES = scenes.ROOT.parent / "shared/data/meshes"
DEFAULT_MESH = MESHES / "stanford-bunny.obj"
STORAGE_MESHES = ["stanford-bunny.obj", "spot.obj", "teapot.obj", "suzanne.obj"]


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


def storage_args(argv=None):
    p = argparse.ArgumentParser(description="Storage benchmark: stored bytes per shading point, "
                                            "decode time and .blend growth")
    p.add_argument("--mesh", type=pathlib.Path, nargs="*",
                   default=[MESHES / m for m in STORAGE_MESHES])
    p.add_argument("--suzanne", type=int, nargs="*", default=[3],
                   help="Blender's Suzanne with these Subdivision Surface levels")
    p.add_argument("--resolution", type=int, default=32, choices=(32, 64, 128))
    p.add_argument("--repeat", type=int, default=5, help="best of N for the decode time")
    p.add_argument("--out-file", type=pathlib.Path,
                   default=scenes.ROOT / "out/bench/storage.txt")
    args = p.parse_args(argv)
    missing = [str(m) for m in args.mesh if not m.is_file()]
    if missing:
        p.error("mesh not found: " + ", ".join(missing))
    return args


def saved_size(path) -> int:
    import bpy
    bpy.ops.wm.save_as_mainfile(filepath=str(path), copy=True)
    return os.path.getsize(path)


def storage_main(argv=None):
    args = storage_args(argv)
    scenes.reset()
    import bpy
    from prt_relight.addon.blender import storage

    cases = [(m.stem, lambda m=m: scenes.add_obj(m)) for m in args.mesh]
    cases += [(f"Suzanne subdiv {lv}", lambda lv=lv: scenes.add_suzanne(subdiv=lv))
              for lv in args.suzanne]
    lines = []

    def say(text=""):
        print(text, flush=True)
        lines.append(text)

    raw = 6 * args.resolution ** 2 // 8
    say(f"visibility at 6x{args.resolution}^2: {raw} bytes per point bit-packed")
    say(f"{'case':22s} {'object':16s} {'points':>8s} {'stored MB':>9s} {'B/point':>8s} "
        f"{'ratio':>6s} {'decode ms':>9s} {'trace s':>8s} {'encode s':>8s} {'.blend +MB':>10s}")
    with tempfile.TemporaryDirectory() as tmp:
        for name, add in cases:
            scenes.reset()
            scenes.add_world("sunset")
            scenes.add_ground()
            add()
            before = saved_size(pathlib.Path(tmp) / "before.blend")
            t = scenes.precompute(args.resolution)
            grown = saved_size(pathlib.Path(tmp) / "after.blend") - before
            for ob in (o for o in bpy.data.objects if storage.has(o, storage.VISIBILITY)):
                size = storage.stored_bytes(ob, storage.VISIBILITY)
                best = float("inf")
                for _ in range(max(1, args.repeat)):
                    t0 = time.perf_counter()
                    bits = storage.get(ob, storage.VISIBILITY)[0]["bits"]
                    best = min(best, time.perf_counter() - t0)
                points = len(bits)
                say(f"{name:22s} {ob.name:16s} {points:8d} {size / 1e6:9.2f} "
                    f"{size / points:8.1f} {raw * points / size:5.1f}x {best * 1e3:9.1f} "
                    f"{t['rays']:8.1f} {t['encode']:8.2f} {grown / 1e6:10.2f}")
    args.out_file.parent.mkdir(parents=True, exist_ok=True)
    args.out_file.write_text("\n".join(lines) + "\n", encoding="utf-8")
    print(f"written {args.out_file}")


if __name__ == "__main__":
    if sys.argv[1:2] == ["storage"]:
        sys.exit(storage_main(sys.argv[2:]))
    sys.exit(main())
