# SPDX-License-Identifier: GPL-3.0-or-later
"""Compact sources and lamps per pixel (addon/gpu/lights.py): error against Cycles and relit
F12 time per method, with and without the split, against Workbench's F12 of the same scene
in the same run; with ``--lamps``, the frame cost per lamp.

    python bench/bench_lights.py [--out out/bench_lights] [--methods REFERENCE,SH,...]
    python bench/bench_lights.py --lamps [--counts 0,1,4,16,64] [--method SH]
                                 [--size 128x96] [--spot-deg 50] [--append docs/measurements.md]
    python bench/bench_lights.py --sun-seeds [--seeds 12] [--spp 1024] [--size 128 96]
                                 [--methods REFERENCE,SH,...] [--out out/bench_sun_seeds]

Scenes: Suzanne on a 96² ground under a dim sky with one 1-pixel sun (2·10⁴), the same
Suzanne diffuse under 'forest' (a soft HDRI), and Beckmann 0.3 glossy under 'sunrise'.
"Relit F12" turns the world's Mapping rotation by a new angle before every frame (the
lighting changes; the shadow maps are drawn again); "viewport" draws one sample per pixel
(`engine.render_pixels` inside a render, no supersampling).  Timings are medians of three
frames on this machine; compare the ratios.

``--lamps`` (issue 31): an interior lit by 0 to 64 spots in rows (``scenes.spot_rows_scene``),
every lamp and its shadow drawn per pixel, the frame time against the number of lamps and
its least-squares slope, the cost of one more lamp.  Per count: "frame" draws the frame
again with the shadow maps cached (the World or the camera changed), "lamps moved" moves
every lamp first (its shadow faces drawn again), both one sample per pixel (a viewport
frame, ``engine.render_pixels`` inside a render) and with the scene's Anti-Aliasing (F12's
samples).  The method's own shading does not depend on the lamps (SH by default: its
per-vertex shading is the cheapest, so the lamps' share shows).  Times are the best of five
frames (the least disturbed on a shared machine).

``--sun-seeds``: the error against converged Cycles where Cycles itself is noisy, the *sun*
scene (Cycles' 1024 spp frames differ from each other by 3-16 % rel-L2 there, fireflies)
rendered by Cycles with N seeds: ``core.report.metrics.rel_l2_converged`` (the per-seed
variance subtracted), printed with the raw figure and the mean's own noise; Cycles frames
are kept and reused (per seed, size and spp).
"""

from __future__ import annotations

import argparse
import math
import pathlib
import statistics
import sys
import time

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))
import scenes  # noqa: E402
from prt_relight.core.report.metrics import rel_l2, rel_l2_converged  # noqa: E402  (importing scenes registers prt_relight)

import numpy as np  # noqa: E402

METHODS = ["REFERENCE", "SSDF_SG", "RSL", "SH", "WAVELET"]


def dim_sky_with_sun(h=512, w=1024, direction=(0.5, -0.6, 0.6), sun=2e4):
    theta = (np.arange(h) + 0.5) / h * math.pi
    sky = (0.03 + 0.05 * np.clip(np.cos(theta), 0.0, 1.0))[:, None, None] \
        * np.array([0.6, 0.8, 1.0])
    img = np.repeat(sky, w, axis=1).astype(np.float32)
    d = np.asarray(direction, float) / np.linalg.norm(direction)
    u = (0.5 - math.atan2(d[1], d[0]) / (2 * math.pi)) % 1.0
    img[min(int(math.acos(d[2]) / math.pi * h), h - 1), min(int(u * w), w - 1)] = sun
    return img


def image_world(pixels, name):
    """A world whose Environment Texture is ``pixels`` (top row first), with a Mapping."""
    import bpy
    h, w, _ = pixels.shape
    img = bpy.data.images.new(name, w, h, alpha=True, float_buffer=True, is_data=True)
    rgba = np.ones((h, w, 4), np.float32)
    rgba[..., :3] = pixels
    img.pixels.foreach_set(rgba[::-1].reshape(-1))
    img.pack()
    world = scenes.add_world("forest", rotation_z=0.01)
    env = next(n for n in world.node_tree.nodes if n.type == "TEX_ENVIRONMENT")
    env.image = img


def build(kind):
    import bpy
    scenes.reset()
    if kind == "sun":
        image_world(dim_sky_with_sun(), "sun sky")
    else:
        scenes.add_world("forest" if kind == "diffuse" else "sunrise", rotation_z=0.01)
    ground = scenes.add_ground(cuts=96)
    scenes.add_bsdf_material(ground, "Ground", "ShaderNodeBsdfDiffuse", Color=(0.8, 0.8, 0.8, 1))
    ob = scenes.add_suzanne(subdiv=2)
    if kind == "glossy":
        scenes.add_bsdf_material(ob, "Glossy", "ShaderNodeBsdfGlossy", distribution="BECKMANN",
                                 Roughness=0.3, Color=(1.0, 1.0, 1.0, 1.0))
    else:
        scenes.add_bsdf_material(ob, "Diffuse", "ShaderNodeBsdfDiffuse",
                                 Color=(0.8, 0.8, 0.8, 1))
    scenes.add_camera(resolution=(256, 192))
    bpy.context.scene.prt.supersampling = 3


def median_time(fn, repeats=3):
    out = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        out.append(time.perf_counter() - t0)
    return statistics.median(out)


def run(kind, methods, out_dir, lines):
    import bpy
    build(kind)                            # registers the add-on as prt_relight
    from prt_relight.addon.frame.engine import in_render, render_pixels, render_view
    from prt_relight.addon.frame.state import FrameState
    scene = bpy.context.scene
    scenes.precompute(32)
    d = out_dir / kind
    samples = 1024 if kind != "diffuse" else 512
    scenes.render_cycles(d.with_suffix(".cycles.exr"), samples=samples)
    truth = scenes.read_exr(d.with_suffix(".cycles.exr"))
    t_wb = median_time(lambda: scenes.render_workbench())
    mapping = next(n for n in scene.world.node_tree.nodes if n.type == "MAPPING")
    lines.append(f"### {kind} (256×192, Cycles {samples} spp; Workbench F12 {t_wb:.2f} s)")
    lines.append("")
    lines.append("| method | split | sources | vs Cycles | relit F12 | ÷ Workbench | viewport frame |")
    lines.append("|---|---|---|---|---|---|---|")
    for method in methods:
        for split in (0, 8):
            scene.prt.method = method
            scene.prt.light_sources = split
            path = d.with_suffix(f".{method}.{split}.exr")
            scenes.render_prt(path)                             # first frame: caches
            err = rel_l2(scenes.read_exr(path), truth)
            angle = [mapping.inputs["Rotation"].default_value[2]]

            def relit():
                angle[0] += 0.013
                mapping.inputs["Rotation"].default_value[2] = angle[0]
                scenes.render_prt(path.with_suffix(".turned.exr"))
            t_relit = median_time(relit)

            def viewport(depsgraph):
                state = FrameState()
                state.sync(depsgraph)
                view, proj, w, h, persp = render_view(scene, depsgraph)
                render_pixels(state, view, proj, w, h, True, persp)    # caches
                t = median_time(lambda: render_pixels(state, view, proj, w, h, True, persp))
                return t, len(state.sources)
            t_view, count = in_render(scene, viewport)
            mapping.inputs["Rotation"].default_value[2] = 0.01
            row = (f"| {method} | {'on' if split else 'off'} | {count} | {100 * err:.2f} % | "
                   f"{t_relit:.2f} s | {t_relit / t_wb:.1f}× | {t_view:.3f} s |")
            print(row, flush=True)
            lines.append(row)
    lines.append("")


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


def lamp_cost(argv):
    """``--lamps``: the frame cost per lamp (the module's docstring)."""
    ap = argparse.ArgumentParser(description="frame cost per lamp")
    ap.add_argument("--counts", default="0,1,4,16,64")
    ap.add_argument("--method", default="SH")
    ap.add_argument("--size", default="128x96")
    ap.add_argument("--spot-deg", type=float, default=50.0,
                    help="the spots' cone (50°: 64 spots light each floor point ~6 times)")
    ap.add_argument("--append", default=None, help="append the table to this markdown file")
    args = ap.parse_args(argv)
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
    slope = np.linalg.lstsq(A, T, rcond=None)[0][1] if len(lit) > 1 else [None] * 4
    lines = [f"Frame cost per lamp ({args.method}, {width}×{height}, {args.spot_deg:g}° spots in "
             f"rows over a "
             f"floor with three Suzannes, `make bench-lamps`, bench/bench_lights.py --lamps):", "",
             f"| lamps | viewport frame | lamps moved | F12 ({aa}² samples) | F12, lamps moved "
             "| shadow maps |", "|---|---|---|---|---|---|", *rows,
             "| per lamp (least squares over 1+ lamps) | " + " | ".join("-" if s is None else f"{1e3 * s:.1f} ms" for s in slope)
             + " | |", ""]
    print("\n".join(lines))
    if args.append:
        with open(args.append, "a", encoding="utf-8") as f:
            f.write("\n" + "\n".join(lines))


def sun_seeds(argv):
    """``--sun-seeds``: the sun scene against converged Cycles (the module's docstring)."""
    ap = argparse.ArgumentParser(description="the sun scene against converged Cycles")
    ap.add_argument("--seeds", type=int, default=12)
    ap.add_argument("--spp", type=int, default=1024)
    ap.add_argument("--size", type=int, nargs=2, default=[128, 96])
    ap.add_argument("--methods", default=",".join(METHODS + ["BLOCKS"]))
    ap.add_argument("--out", default="out/bench_sun_seeds")
    args = ap.parse_args(argv)
    import bpy
    out = scenes.ROOT / args.out
    out.mkdir(parents=True, exist_ok=True)
    build("sun")
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



def main():
    if "--sun-seeds" in sys.argv:
        sun_seeds([a for a in sys.argv[1:] if a != "--sun-seeds"])
        return
    if "--lamps" in sys.argv:
        lamp_cost([a for a in sys.argv[1:] if a != "--lamps"])
        return
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--out", default="out/bench_lights")
    ap.add_argument("--methods", default=",".join(METHODS))
    ap.add_argument("--scenes", default="sun,diffuse,glossy")
    args = ap.parse_args()
    out_dir = pathlib.Path(args.out)
    out_dir.mkdir(parents=True, exist_ok=True)
    lines = []
    for kind in args.scenes.split(","):
        run(kind, args.methods.split(","), out_dir, lines)
    (out_dir / "table.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
