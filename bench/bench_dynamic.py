# SPDX-License-Identifier: GPL-3.0-or-later
"""Dynamic objects (shadow fields, addon/frame/dynamic.py): field precompute and storage per
detail, and frame time with 1 / 4 / 16 dynamic objects against the same scene static.

    python bench/bench_dynamic.py [--big] [--methods REFERENCE,SH] [--counts 1,4,16]
                                  [--frame-detail LOW] [--repeat 3]
                                  [--out-file out/bench/dynamic.md]
                                  [--append docs/measurements.md]

Everything runs in one process (compare the ratios: the machine is shared).

1. *Fields*: Suzanne (one subdivision level, 1.6 tall) on a 6 x 6 ground of 40^2 quads
   under 'city', marked dynamic, precomputed at each ``scene.prt.field_detail``: the
   precompute's seconds (``timings["shadow_fields"]``: the occluder field + the static
   scene's field where it goes), against the precompute of the same scene with Suzanne
   static; the stored blob ``storage.SHADOW_FIELD`` (compressed bytes) and the raw sizes of its
   occluder field (OVDF: independent of the vertex count) and static field; Suzanne's own
   stored visibility (grows with its vertices); then a frame after Suzanne moved
   (``--field-method``, SH: little besides the product) against the static scene's relit
   frame.  ``--big`` adds a ~60k-vertex Suzanne (the issue: its field <= 20 MB
   compressed).  Every surface is a Diffuse BSDF of 0.8.
2. *Frames*: 1 / 4 / 16 small Suzannes (no subdivision, 0.5 tall) on a lattice over the
   same ground, precomputed once with them static and once dynamic (at
   ``--frame-detail``; fields of 16 objects at HIGH take minutes).  A frame is what F12
   and the viewport do before rasterising: a new ``runtime.FrameState``, ``sync`` and
   ``shade(eye)`` (per-corner radiance); medians of ``--repeat`` frames after a warm one.
   *relit*: the world's Mapping turned to a new angle (same poses: the products of the
   fields are cached per pose); *moved*: every dynamic object at a new pose (the products
   are made again: ``addon.frame.dynamic.posed_bits``, its seconds summed as "product"); *one
   moved*: only the first of them at a new pose (an animation where one object moves).
"""

from __future__ import annotations

import argparse
import datetime
import math
import pathlib
import statistics
import sys
import textwrap
import time

import numpy as np

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))
import scenes  # noqa: E402

EYE = np.array([0.0, -7.0, 4.0])
DETAILS = ["LOW", "MEDIUM", "HIGH"]


def parse_args(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--big", action="store_true",
                   help="also the fields of a ~60k-vertex Suzanne (minutes)")
    p.add_argument("--big-vertices", type=int, default=60000)
    p.add_argument("--details", default=",".join(DETAILS), help="field details of part 1")
    p.add_argument("--field-method", default="SH",
                   help="method of the fields table's frames (the product is the same for all)")
    p.add_argument("--methods", default="REFERENCE,SH", help="methods of the frame table")
    p.add_argument("--counts", default="1,4,16", help="dynamic objects per frame scene")
    p.add_argument("--frame-detail", default="LOW", choices=DETAILS,
                   help="field detail of the frame scenes")
    p.add_argument("--hdri", default="city")
    p.add_argument("--resolution", type=int, default=32, help="precompute directions")
    p.add_argument("--repeat", type=int, default=3, help="frames per median")
    p.add_argument("--out-file", type=pathlib.Path,
                   default=scenes.ROOT / "out/bench/dynamic.md")
    p.add_argument("--append", type=pathlib.Path, default=None,
                   help="append the tables as a section to this markdown file")
    return p.parse_args(argv)


# ------------------------------------------------------------------ helpers

class ProductClock:
    """Seconds spent in ``addon.frame.dynamic.posed_bits`` (the per-pose visibility products)."""

    def __init__(self):
        from prt_relight.addon.frame import dynamic
        self.dynamic = dynamic
        self.inner = dynamic.posed_bits
        self.seconds = 0.0
        self.calls = 0

        def timed(*args, **kwargs):
            t0 = time.perf_counter()
            try:
                return self.inner(*args, **kwargs)
            finally:
                self.seconds += time.perf_counter() - t0
                self.calls += 1
        dynamic.posed_bits = timed

    def reset(self):
        self.seconds, self.calls = 0.0, 0


def frame(method):
    """One frame as F12 / the viewport make it before rasterising: sync + shade."""
    import bpy
    from prt_relight.addon.frame import state as runtime
    bpy.context.scene.prt.method = method
    state = runtime.FrameState()
    state.sync(bpy.context.evaluated_depsgraph_get())
    out = state.shade(EYE)
    assert out is not None and all(np.isfinite(np.asarray(r)).all() for r in out), method
    return state


def median_of(repeat, before, fn):
    """Median seconds of ``fn()`` over ``repeat`` runs, ``before()`` untimed each time."""
    times = []
    for i in range(repeat):
        before(i)
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return statistics.median(times)


def mapping_node():
    import bpy
    return next(n for n in bpy.context.scene.world.node_tree.nodes if n.type == "MAPPING")


class Turner:
    """Turns the world's Mapping to a new angle on every call."""

    def __init__(self):
        self.angle = 0.01

    def __call__(self, _i=0):
        import bpy
        self.angle += 0.37
        mapping_node().inputs["Rotation"].default_value[2] = self.angle
        bpy.context.view_layer.update()


def vertex_count(ob) -> int:
    import bpy
    return len(ob.evaluated_get(bpy.context.evaluated_depsgraph_get()).data.vertices)


def diffuse(ob):
    scenes.add_bsdf_material(ob, "Diffuse", "ShaderNodeBsdfDiffuse", Color=(0.8, 0.8, 0.8, 1))
    return ob


def base_scene(hdri):
    import bpy
    scene = scenes.reset()
    scenes.add_world(hdri, rotation_z=0.01)
    diffuse(scenes.add_ground(size=6.0, cuts=40))
    scene.prt.light_sources = 0        # time the methods, not the per-pixel sources
    bpy.context.view_layer.update()
    return scene


def move(ob, rng, home):
    """``ob`` to a new pose near ``home`` (moved, lifted, turned about z and tilted)."""
    import bpy
    ob.location = (home[0] + rng.uniform(-0.3, 0.3), home[1] + rng.uniform(-0.3, 0.3),
                   home[2] + rng.uniform(0.0, 0.2))
    ob.rotation_euler = (rng.uniform(-0.3, 0.3), rng.uniform(-0.3, 0.3),
                         rng.uniform(-math.pi, math.pi))
    bpy.context.view_layer.update()


# ------------------------------------------------------------------ 1. fields

def field_rows(args, clock):
    from prt_relight.addon.frame import dynamic
    from prt_relight.addon.blender import storage
    from bench_scale import add_suzanne as cut_suzanne
    objects = [("Suzanne subdiv 1", lambda: diffuse(scenes.add_suzanne(subdiv=1)))]
    if args.big:
        objects.append((f"Suzanne ~{args.big_vertices // 1000}k",
                        lambda: diffuse(cut_suzanne(vertices=args.big_vertices))))
    m = args.field_method
    rows = []
    for label, add in objects:
        # the same scene static: the precompute and the frame the dynamic ones compare to
        scene = base_scene(args.hdri)
        ob = add()
        t_static = scenes.precompute(args.resolution, method=m)["total"]
        frame(m)
        f_static = median_of(args.repeat, Turner(), lambda: frame(m))
        for detail in args.details.split(","):
            scene = base_scene(args.hdri)
            ob = add()
            ob.prt.dynamic = True
            scene.prt.field_detail = detail
            home = tuple(ob.location)
            t = scenes.precompute(args.resolution, method=m)
            data = dynamic.stored_field(ob)
            frame(m)
            rng = np.random.default_rng(1)
            clock.reset()
            f_moved = median_of(args.repeat, lambda i: move(ob, rng, home),
                                lambda: frame(m))
            product = clock.seconds / max(args.repeat, 1)
            row = dict(
                object=label, vertices=vertex_count(ob), detail=detail,
                precompute=t["total"], fields=t.get("shadow_fields", 0.0),
                static_precompute=t_static,
                stored=storage.stored_bytes(ob, storage.SHADOW_FIELD),
                ovdf_raw=data.field.nbytes,
                static_raw=data.static.nbytes if data.static is not None else 0,
                pca_error=data.field.error,
                own=storage.stored_bytes(ob, storage.VISIBILITY),
                moved=f_moved, product=product, static_frame=f_static)
            rows.append(row)
            print(f"[fields] {label} {detail}: precompute {row['precompute']:.2f} s "
                  f"(fields {row['fields']:.2f} s; static scene {t_static:.2f} s), "
                  f"FIELD {row['stored'] / 2**20:.2f} MiB, own visibility "
                  f"{row['own'] / 2**20:.2f} MiB, moved frame {f_moved:.3f} s "
                  f"(static {f_static:.3f} s)", flush=True)
    return rows


# ------------------------------------------------------------------ 2. frames

LATTICE = 1.3


def spots(count):
    """``count`` (a square) places on a lattice centred on the ground."""
    side = int(round(math.sqrt(count)))
    if side * side != count:
        raise SystemExit(f"--counts: {count} is not a square")
    at = (np.arange(side) - (side - 1) / 2) * LATTICE
    return [(float(x), float(y)) for y in at for x in at]


def frame_scene(args, count, dynamic_flag):
    import bpy
    scene = base_scene(args.hdri)
    scene.prt.field_detail = args.frame_detail
    obs = []
    for i, (x, y) in enumerate(spots(count)):
        ob = scenes.add_suzanne(subdiv=0, height=0.5)
        ob.name = f"Suzanne.{i:02d}"
        ob.location.x += x
        ob.location.y += y
        ob.prt.dynamic = dynamic_flag
        obs.append(ob)
    bpy.context.view_layer.update()
    return scene, obs


def frame_rows(args, clock):
    methods = args.methods.split(",")
    store_method = next((m for m in reversed(methods) if m != "REFERENCE"), "REFERENCE")
    rows = []
    for count in [int(c) for c in args.counts.split(",")]:
        got = {m: {} for m in methods}
        # static: the same objects, not dynamic
        scene, obs = frame_scene(args, count, False)
        t_static = scenes.precompute(args.resolution, method=store_method)
        turn = Turner()
        for m in methods:
            frame(m)                                         # caches (derived data)
            got[m]["static_relit"] = median_of(args.repeat, turn, lambda m=m: frame(m))
        points = sum(st.points.count for st in frame(methods[0]).objects)
        # dynamic
        scene, obs = frame_scene(args, count, True)
        t_dyn = scenes.precompute(args.resolution, method=store_method)
        homes = [tuple(ob.location) for ob in obs]
        rng = np.random.default_rng(count)
        turn = Turner()

        def move_all(_i):
            for ob, home in zip(obs, homes):
                move(ob, rng, home)

        for m in methods:
            move_all(0)
            frame(m)                                         # caches at this pose
            got[m]["dyn_relit"] = median_of(args.repeat, turn, lambda m=m: frame(m))
            clock.reset()
            got[m]["moved"] = median_of(args.repeat, move_all, lambda m=m: frame(m))
            got[m]["product"] = clock.seconds / max(args.repeat, 1)
            clock.reset()
            got[m]["one"] = median_of(args.repeat, lambda i: move(obs[0], rng, homes[0]),
                                      lambda m=m: frame(m))
            got[m]["one_product"] = clock.seconds / max(args.repeat, 1)
        for m in methods:
            g = got[m]
            row = dict(method=m, count=count, points=points, detail=args.frame_detail,
                       precompute_static=t_static["total"], precompute_dynamic=t_dyn["total"],
                       fields=t_dyn.get("shadow_fields", 0.0), **g)
            rows.append(row)
            print(f"[frames] {m} x{count}: static relit {g['static_relit']:.3f} s | dynamic "
                  f"relit {g['dyn_relit']:.3f} s, moved {g['moved']:.3f} s (product "
                  f"{g['product']:.3f} s), one moved {g['one']:.3f} s (product "
                  f"{g['one_product']:.3f} s) | precompute {t_static['total']:.1f} s static, "
                  f"{t_dyn['total']:.1f} s dynamic", flush=True)
    return rows


# ------------------------------------------------------------------ report

def mib(n):
    return f"{n / 2**20:.2f} MiB"


def tables(args, field, frames, seconds):
    lines = []
    if field:
        lines += [
            "Fields: one dynamic Suzanne on the 6×6 ground of 40² quads under "
            f"'{args.hdri}', {args.resolution}² directions per face.  *FIELD* is the stored "
            "blob (compressed): the occluder field (OVDF, independent of the vertex count) "
            "and the static scene's field where it goes; *own visibility* is the object's "
            "stored self-visibility (grows with its vertices).  *Moved frame*: "
            f"{args.field_method} sync + shade after Suzanne moved (median), against the "
            "static scene's relit frame.",
            "",
            "| object | vertices | detail | precompute | of which fields | ÷ static precompute "
            "| FIELD stored | OVDF raw | static field raw | PCA error | own visibility "
            "| moved frame | of which product | ÷ static relit |",
            "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
        for r in field:
            lines.append(
                f"| {r['object']} | {r['vertices']:,} | {r['detail']} | {r['precompute']:.2f} s "
                f"| {r['fields']:.2f} s | {r['precompute'] / r['static_precompute']:.1f}× "
                f"| {mib(r['stored'])} | {mib(r['ovdf_raw'])} | {mib(r['static_raw'])} "
                f"| {100 * r['pca_error']:.1f} % | {mib(r['own'])} | {r['moved']:.3f} s "
                f"| {r['product']:.3f} s | {r['moved'] / r['static_frame']:.2f}× |")
        lines.append("")
    if frames:
        r0 = frames[0]
        lines += [
            f"Frames: {' / '.join(args.counts.split(','))} Suzannes (0.5 tall, no "
            "subdivision) on the same ground, "
            f"fields at {r0['detail']}; a frame = new FrameState, sync, shade (per-corner "
            f"radiance, no rasterising), median of {args.repeat}.  *relit*: the world's "
            "Mapping turned (same poses); *moved*: every dynamic object at a new pose "
            "(*product*: seconds in `dynamic.posed_bits` per frame); *one moved*: only the "
            "first at a new pose.  Ratios are dynamic ÷ the static scene's relit frame "
            "(the same objects, not dynamic).",
            "",
            "| method | objects | points | static relit | dynamic relit | ÷ static "
            "| moved | product | ÷ static | one moved | product | ÷ static |",
            "|---|---|---|---|---|---|---|---|---|---|---|---|"]
        for r in frames:
            lines.append(
                f"| {r['method']} | {r['count']} | {r['points']:,} "
                f"| {r['static_relit']:.3f} s | {r['dyn_relit']:.3f} s "
                f"| {r['dyn_relit'] / r['static_relit']:.2f}× | {r['moved']:.3f} s "
                f"| {r['product']:.3f} s | {r['moved'] / r['static_relit']:.2f}× "
                f"| {r['one']:.3f} s | {r['one_product']:.3f} s "
                f"| {r['one'] / r['static_relit']:.2f}× |")
        lines += ["", "Precompute of the frame scenes (all objects, static vs dynamic): "
                  + ", ".join(f"{r['count']}: {r['precompute_static']:.1f} s vs "
                              f"{r['precompute_dynamic']:.1f} s (fields {r['fields']:.1f} s)"
                              for r in frames if r['method'] == r0['method']) + ".", ""]
    lines.append(f"(bench run {seconds:.0f} s)")
    return [textwrap.fill(line, 92, break_on_hyphens=False)
            if line and not line.startswith("|") else line for line in lines]


def main(argv=None):
    args = parse_args(argv)
    t0 = time.perf_counter()
    scenes.reset()                                   # registers prt_relight
    clock = ProductClock()
    field = field_rows(args, clock) if args.details else []
    frames = frame_rows(args, clock) if args.counts and args.methods else []
    lines = tables(args, field, frames, time.perf_counter() - t0)
    text = "\n".join(lines) + "\n"
    args.out_file.parent.mkdir(parents=True, exist_ok=True)
    args.out_file.write_text(text)
    print()
    print(text)
    if args.append:
        day = datetime.date.today().isoformat()
        with open(args.append, "a") as f:
            f.write(f"\n## Dynamic objects (shadow fields) ({day}; `bench/bench_dynamic.py`)\n\n"
                    + text)
        print(f"appended to {args.append}")


if __name__ == "__main__":
    main()
