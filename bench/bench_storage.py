# SPDX-License-Identifier: GPL-3.0-or-later
"""Storage benchmark: stored bytes per shading point, decode time and .blend growth.

    python bench/bench_storage.py [--mesh PATH ...] [--suzanne SUBDIV ...] [--resolution 32]

Each case is one object on the ground grid (``scenes.add_ground``) under a bundled
HDRI, precomputed with REFERENCE.  Per object it prints the points, the stored
visibility blob (``addon.blender.storage``) in bytes per point against the 6N^2/8 bit-packed
bytes, and the best-of-N time to read the blob back from the object and decode it; per
case the trace and encode (zlib, all objects) times and the growth of the saved .blend.  Writes out/bench/storage.txt as well.
"""

from __future__ import annotations

import argparse
import os
import pathlib
import sys
import tempfile
import time

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))
import scenes  # noqa: E402

MESHES = scenes.ROOT.parent / "shared/data/meshes"
DEFAULT_MESHES = ["stanford-bunny.obj", "spot.obj", "teapot.obj", "suzanne.obj"]


def parse_args(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--mesh", type=pathlib.Path, nargs="*",
                   default=[MESHES / m for m in DEFAULT_MESHES])
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


def main(argv=None):
    args = parse_args(argv)
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
    main()
