"""REFERENCE against Cycles on held-out-style scenes: a diffuse object on a tessellated
ground under several of Blender's HDRIs (one of very high dynamic range).

    .venv/bin/python bench/eval_cycles.py [--samples 2048] [--resolution 200x150]
                                          [--hdris forest,sunset,city,courtyard]

Both objects get an explicit Diffuse BSDF (albedo 0.8); Cycles renders direct light
only (max_bounces 0), film transparent; rel-L2 over RGB of pixels with Cycles alpha
> 0.5.  Prints a table and writes out/eval/cycles.txt (+ the EXRs).
"""

from __future__ import annotations

import argparse
import pathlib
import sys

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))
import scenes  # noqa: E402
from prt_relight.core.report.metrics import rel_l2  # noqa: E402  (importing scenes registers prt_relight)


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--samples", type=int, default=2048)
    p.add_argument("--resolution", default="200x150")
    p.add_argument("--hdris", default="forest,sunset,city,courtyard")
    p.add_argument("--mesh", type=pathlib.Path,
                   default=scenes.ROOT.parent / "shared/data/meshes/stanford-bunny.obj")
    p.add_argument("--directions", type=int, default=32, choices=(32, 64, 128))
    p.add_argument("--out", type=pathlib.Path, default=scenes.ROOT / "out/eval")
    args = p.parse_args(argv)
    w, h = (int(v) for v in args.resolution.lower().split("x"))
    args.out.mkdir(parents=True, exist_ok=True)
    import bpy

    rows = []
    for hdri in args.hdris.split(","):
        scenes.reset()
        scenes.add_world(hdri, rotation_z=0.6)
        ground = scenes.add_ground(cuts=96)
        obj = scenes.add_obj(args.mesh) if args.mesh.is_file() else scenes.add_suzanne()
        for ob in (ground, obj):
            scenes.add_bsdf_material(ob, "diffuse", "ShaderNodeBsdfDiffuse",
                                     Color=(0.8, 0.8, 0.8, 1.0))
        scenes.add_camera()
        r = bpy.context.scene.render
        r.resolution_x, r.resolution_y, r.resolution_percentage = w, h, 100
        t = scenes.precompute(resolution=args.directions)
        prt_s = scenes.render_prt(args.out / f"{hdri}_prt.exr")
        cyc_s = scenes.render_cycles(args.out / f"{hdri}_cycles.exr", samples=args.samples)
        err = rel_l2(scenes.read_exr(args.out / f"{hdri}_prt.exr"),
                            scenes.read_exr(args.out / f"{hdri}_cycles.exr"))
        rows.append((hdri, err, t["total"], prt_s, cyc_s))
        print(f"{hdri:10s} rel-L2 {err:.4f}  precompute {t['total']:.1f} s  "
              f"F12 {prt_s:.2f} s  Cycles {cyc_s:.1f} s", flush=True)
    lines = [f"REFERENCE (6x{args.directions}^2) vs Cycles {args.samples} spp, {w}x{h}, "
             f"{args.mesh.name if args.mesh.is_file() else 'Suzanne'} on a 96^2 grid, "
             "Diffuse BSDF 0.8, world rotated 0.6 rad",
             f"{'hdri':10s} {'rel-L2':>8s} {'precompute':>11s} {'F12':>7s} {'Cycles':>8s}"]
    lines += [f"{n:10s} {e:8.4f} {pc:10.1f}s {f:6.2f}s {c:7.1f}s" for n, e, pc, f, c in rows]
    text = "\n".join(lines)
    print(text)
    (args.out / "cycles.txt").write_text(text + "\n")


if __name__ == "__main__":
    main()
