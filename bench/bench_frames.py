# SPDX-License-Identifier: GPL-3.0-or-later
"""Relit frames against Workbench (issue 32): per scene kind and method, the relit F12 (the
World's Mapping turned by a new angle before every frame) over Workbench's F12 of the same
scene in the same run, the viewport frame after an HDRI turn (one sample per pixel,
``engine.render_pixels`` inside a render, the state's World turned as ``addon.frame.relit``
turns it) over Workbench's F12 without anti-aliasing (the stand-in for its viewport frame:
a headless Blender draws no viewport), the viewport's update after an HDRI turn (a full sync
against the World's part alone, :func:`viewport_update`), and where one relit F12's time
goes.

    python bench/bench_frames.py [--kinds diffuse,sun,glossy,textured,lamps,teapot]
                                 [--methods REFERENCE,SSDF_SG,RSL,BLOCKS,SH,WAVELET,AUTO]
                                 [--size 256] [--rounds 3] [--append docs/measurements.md]

Kinds: ``diffuse`` Suzanne (Diffuse BSDF) on a ground under 'forest'; ``sun`` the same under
a dim sky with a 1-pixel sun; ``glossy`` Beckmann 0.3 Glossy under 'sunrise' (the three of
bench_lights.py); ``textured`` Principled Suzanne and ground with images on Base Color and
Roughness under 'sunrise'; ``lamps`` an area lamp, a spot and a point lamp under 'night';
``teapot`` the glossy teapot (Principled, roughness 0.3) at 1920×1080.  Square frames of
``--size`` (the teapot: 1080p), the scene's Anti-Aliasing (3×3 as shipped).  Times are
medians of ``--rounds`` frames; compare the ratios within one run (a loaded machine reads
higher on both sides).

The profile of one relit F12 (cProfile's cumulative seconds of the engine's steps): sync
(``FrameState.sync``), CPU shading (``FrameState.shade`` / ``draw_objects``: the method's
own work and its uploads), GPU (``drawing.render_offscreen``: every pass drawn, then read
back -- llvmpipe rasterises at the read), filter (the pixel filter), the rest (the render
result, Blender's own work).
"""

from __future__ import annotations

import argparse
import cProfile
import pathlib
import pstats
import statistics
import sys
import time

import numpy as np

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))
import bench_lights  # noqa: E402
import scenes  # noqa: E402  (importing it registers prt_relight)

KINDS = ("diffuse", "sun", "glossy", "textured", "lamps", "teapot")
METHODS = ("REFERENCE", "SSDF_SG", "RSL", "BLOCKS", "SH", "WAVELET", "AUTO")
#: the profile's steps: (label, module path suffix, function names)
STEPS = (("sync", "addon/frame/state.py", ("sync",)),
         ("CPU shading", "addon/frame/state.py", ("shade", "draw_objects")),
         ("GPU", "addon/gpu/drawing.py", ("render_offscreen",)),
         ("filter", "core/shading/pixel_filter.py", ("resolve",)))


def _pattern(name, rgb):
    """A smooth 256² colour image (sRGB-free float data) for the textured scene."""
    y, x = np.mgrid[0:256, 0:256] / 256.0
    c = np.stack([0.5 + 0.4 * np.sin(12 * x) * rgb[0], 0.5 + 0.4 * np.cos(9 * y) * rgb[1],
                  0.5 + 0.3 * np.sin(7 * (x + y)) * rgb[2]], -1)
    return scenes.float_image(name, c, is_data=False)


def _textured(ob, name):
    import bpy
    bpy.context.view_layer.objects.active = ob
    if not ob.data.uv_layers:
        ob.data.uv_layers.new(name="UVMap")
    mat = bpy.data.materials.new(name)
    nt = mat.node_tree
    bsdf = nt.nodes["Principled BSDF"]
    for socket, rgb in (("Base Color", (1.0, 0.7, 0.4)), ("Roughness", (0.5, 0.5, 0.5))):
        tex = nt.nodes.new("ShaderNodeTexImage")
        tex.image = _pattern(f"{name} {socket}", rgb)
        nt.links.new(tex.outputs["Color"], bsdf.inputs[socket])
    ob.data.materials.clear()
    ob.data.materials.append(mat)


def _lamp(kind, power, location, rotation=(0.0, 0.0, 0.0)):
    import bpy
    data = bpy.data.lights.new(kind.title(), kind)
    data.energy = power
    ob = bpy.data.objects.new(kind.title(), data)
    ob.location, ob.rotation_euler = location, rotation
    bpy.context.scene.collection.objects.link(ob)


def build(kind, size, resolution=None):
    """The scene of ``kind`` (the module's docstring), ``size``² pixels (the teapot 1080p);
    ``resolution`` (width, height) replaces both (bench/gpu_frames.py's frame size)."""
    import bpy
    if kind in ("diffuse", "sun", "glossy"):
        bench_lights.build(kind)
    else:
        scenes.reset()
        scenes.add_world({"textured": "sunrise", "lamps": "night"}.get(kind, "sunrise"),
                         rotation_z=0.01)
        ground = scenes.add_ground(cuts=96)
        if kind == "teapot":
            ob = scenes.add_obj(scenes.ROOT.parent / "shared/data/meshes/teapot.obj", height=1.2)
        else:
            ob = scenes.add_suzanne(subdiv=2)
        if kind == "textured":
            _textured(ob, "statue")
            _textured(ground, "ground")
        elif kind == "teapot":
            scenes.add_bsdf_material(ob, "Teapot", "ShaderNodeBsdfPrincipled", Roughness=0.3,
                                     **{"Base Color": (0.8, 0.3, 0.2, 1.0)})
        else:
            _lamp("AREA", 150.0, (1.5, -1.5, 2.5), (0.6, 0.0, 0.8))
            _lamp("SPOT", 500.0, (-2.0, -1.5, 3.0), (0.5, 0.0, -0.9))
            _lamp("POINT", 200.0, (0.5, 1.5, 2.2))
        scenes.add_camera(resolution=(256, 192))
        bpy.context.scene.prt.supersampling = 3
    if resolution is None:
        resolution = (1920, 1080) if kind == "teapot" else (size, size)
    scenes.set_resolution(*resolution)


def turn_world(scene):
    """Turn the World's Mapping by a new angle (a relit frame)."""
    mapping = next(n for n in scene.world.node_tree.nodes if n.type == "MAPPING")
    mapping.inputs["Rotation"].default_value[2] += 0.37


def profile(path):
    """Seconds per step of one relit F12 (:data:`STEPS`, then the rest)."""
    import bpy
    turn_world(bpy.context.scene)
    prof = cProfile.Profile()
    prof.enable()
    t0 = time.perf_counter()
    scenes.render_prt(path)
    total = time.perf_counter() - t0
    prof.disable()
    stats = pstats.Stats(prof).stats
    steps = {}
    for label, suffix, names in STEPS:
        steps[label] = sum(v[3] for (file, _, fn), v in stats.items()
                           if file.endswith(suffix) and fn in names)
    steps["rest"] = max(total - sum(steps.values()), 0.0)
    return steps


def workbench_f12(scene, rounds, aa=None):
    """Median seconds of Workbench's F12 over ``rounds`` frames after a warm one, with the
    scene's Anti-Aliasing or ``aa`` ("OFF": the stand-in for its viewport frame)."""
    saved = scene.display.render_aa
    scene.display.render_aa = aa or saved
    try:
        scenes.render_workbench()                                  # warm
        return statistics.median(scenes.render_workbench() for _ in range(rounds))
    finally:
        scene.display.render_aa = saved


def relit_f12(scene, path, rounds):
    """Median seconds of the relit F12 (saved to ``path``): a first frame fills the caches,
    then the World is turned before each of ``rounds`` frames."""
    scenes.render_prt(path)

    def one():
        turn_world(scene)
        return scenes.render_prt(path)
    return statistics.median(one() for _ in range(rounds))


def viewport_frame(scene, rounds):
    """Median seconds of the viewport frame after an HDRI turn: one sample per pixel,
    ``engine.render_pixels`` inside a render, the state's World turned as
    ``addon.frame.relit`` turns it."""
    from prt_relight.addon.frame import relit
    from prt_relight.addon.frame.engine import in_render, render_pixels, render_view
    from prt_relight.addon.frame.state import FrameState

    def viewport(depsgraph):
        state = FrameState()
        state.sync(depsgraph)
        view, proj, vw, vh, persp = render_view(scene, depsgraph)
        times = relit.relit_times(
            [state], lambda st: render_pixels(st, view, proj, vw, vh, True, persp), rounds)
        return statistics.median(times[0])
    return in_render(scene, viewport)


def viewport_update(scene, rounds):
    """Median seconds of the viewport's update after an HDRI turn (the view layer's
    depsgraph): a full ``FrameState.sync`` (every mesh read again: what ``view_update`` did
    for any edit) and ``FrameState.relit`` (the World alone: what it does now when the
    update names only the World, core.pipeline.frame_status.world_only)."""
    import bpy
    from prt_relight.addon.frame.state import FrameState
    full, world = [], []
    state = None
    for _ in range(rounds + 1):            # the first round warms the caches
        turn_world(scene)
        bpy.context.view_layer.update()
        depsgraph = bpy.context.evaluated_depsgraph_get()
        t0 = time.perf_counter()
        fresh = FrameState()
        fresh.sync(depsgraph)
        t1 = time.perf_counter()
        if state is not None:
            state.relit(depsgraph)
            world.append(time.perf_counter() - t1)
            full.append(t1 - t0)
        state = fresh
    return statistics.median(full), statistics.median(world)


def run(kind, methods, size, rounds, out_dir):
    """The rows of one scene kind: ratios and the profile per method."""
    import bpy
    build(kind, size)
    scene = bpy.context.scene
    scenes.precompute(32)
    t_wb = workbench_f12(scene, rounds)
    t_wb1 = workbench_f12(scene, rounds, "OFF")
    w, h = scene.render.resolution_x, scene.render.resolution_y
    rows = []
    for method in methods:
        scene.prt.method = method
        path = out_dir / f"{kind}.{method}.exr"
        t_f12 = relit_f12(scene, path, rounds)
        t_view = viewport_frame(scene, rounds)
        updates = viewport_update(scene, rounds)
        steps = profile(path)
        rows.append((kind, f"{w}×{h}", method, t_f12 / t_wb, t_view / t_wb1, t_f12, steps,
                     updates))
        print(_row(rows[-1]), f"(Workbench F12 {1e3 * t_wb:.0f} ms, no AA {1e3 * t_wb1:.0f} ms)",
              flush=True)
    return rows


def _row(r):
    kind, size, method, ratio, view_ratio, t, steps, (full, world) = r
    return (f"| {kind} | {size} | {method} | {ratio:.1f}× | {view_ratio:.1f}× | "
            f"{1e3 * full:.0f} → {1e3 * world:.0f} | {1e3 * t:.0f} ms | "
            + " | ".join(f"{1e3 * steps[k]:.0f}" for k in ("sync", "CPU shading", "GPU",
                                                             "filter", "rest")) + " |")


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--kinds", default=",".join(KINDS))
    ap.add_argument("--methods", default=",".join(METHODS))
    ap.add_argument("--size", type=int, default=256)
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--out", default="out/bench_frames")
    ap.add_argument("--append", default=None, help="append the table to this markdown file")
    args = ap.parse_args()
    out_dir = scenes.ROOT / args.out
    out_dir.mkdir(parents=True, exist_ok=True)
    rows = []
    for kind in args.kinds.split(","):
        rows += run(kind, args.methods.split(","), args.size, args.rounds, out_dir)
    lines = [f"Relit frames against Workbench ({time.strftime('%Y-%m-%d')}, one run, "
             "`make bench-frames`; relit F12 = the HDRI turned before the frame, viewport = one "
             "sample per pixel after a turn against Workbench's F12 without AA; view update = "
             "the viewport's sync after a turn, every object read again → the World alone; the "
             "profile of one relit F12 in ms):", "",
             "| scene | size | method | relit F12 ÷ Workbench | viewport ÷ Workbench | view "
             "update (ms) | relit F12 | sync | CPU shading | GPU | filter | rest |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|", *map(_row, rows), ""]
    report(lines, args.append)


def report(lines, append=None):
    """Print a table's ``lines``, and append them to the markdown file ``append`` if given."""
    print("\n".join(lines))
    if append:
        with open(append, "a", encoding="utf-8") as f:
            f.write("\n" + "\n".join(lines))


if __name__ == "__main__":
    main()
