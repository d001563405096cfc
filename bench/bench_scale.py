# SPDX-License-Identifier: GPL-3.0-or-later
"""Production scale (issue 20): a subdivided Suzanne of 25k-500k vertices on a 64^2 ground
under a bundled HDRI, default settings, F12 at 256^2.

    python bench/bench_scale.py [--vertices 25000 100000 250000 500000]
                                [--subsurf 4 5] [--methods REFERENCE SH ...]
                                [--hdri city] [--size 256] [--out-file out/bench/scale.txt]

Each size runs in a process of its own (peak memory is the process's, VmHWM of
/proc/self/status, reset before a step), which prints:

* the precompute (REFERENCE, as the operator runs it): seconds and peak memory, then
  REFERENCE's F12 in the same process (the defaults: the peak over both is the issue's
  "precompute + F12" figure);
* the stored visibility in bytes per shading point and the saved .blend's growth;
* ESC: an F12 of REFERENCE stopped by a stand-in engine whose ``test_break`` turns true
  2 s in: seconds from that to the end of ``render()``, and its progress updates before;
* AUTO's choice (``prt.auto_choose``, nothing measured before): seconds and its ratio to
  the precompute's; then AUTO's first F12 with that choice (the issue's "AUTO's first F12
  <= 1.5x the precompute time": choice + frame);

and each other method's first F12 runs in a process of its own on the saved file
(what a user opening it and switching to that method gets, derived data included):
seconds and peak.  A method whose F12 would pass the memory budget at the next size
(from its peak per point) is skipped there.

then a table over the sizes and the growth per 100k vertices (least-squares slope of
each column over the vertex counts).  Writes ``out/bench/scale.txt`` and ``.json``.

Instances (issue 31, ``--instances``): N collection instances of one Suzanne of
``--instance-vertices`` vertices on a ground (``--instance-bounces``: the Light Paths'
diffuse bounces, 0 by default), each traced in place (addon/blender/surfaces.py),
one process per count: the precompute's seconds and peak, REFERENCE's F12 and its peak, and
per instance the seconds, the stored bytes, the copies it holds (its occluders)
against the source's shared arrays; the same table, and the
growth per instance.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import pathlib
import subprocess
import sys
import tempfile
import time

import numpy as np

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))
import scenes  # noqa: E402

METHODS = ["REFERENCE", "SH", "WAVELET", "RSL", "BLOCKS", "SSDF_SG", "AUTO"]


def parse_args(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--vertices", type=int, nargs="*", default=[25000, 100000, 250000, 500000],
                   help="Suzanne's vertex counts (faces cut k x k, single cuts make up the rest)")
    p.add_argument("--subsurf", type=int, nargs="*", default=[],
                   help="also Suzanne with these Subdivision Surface levels (4: 126k, 5: 504k)")
    p.add_argument("--methods", nargs="*", default=METHODS, help="F12 per method")
    p.add_argument("--hdri", default="city")
    p.add_argument("--size", type=int, default=256, help="F12 width and height")
    p.add_argument("--esc-after", type=float, default=2.0,
                   help="seconds into the ESC check's F12 when ESC is pressed")
    p.add_argument("--memory-budget", type=float, default=None,
                   help="GiB an F12 may take; a method whose F12 would need more (from its "
                        "peak per point at the previous size) is skipped at the next "
                        "(default: 70 %% of the memory available now)")
    p.add_argument("--instances", type=int, nargs="*", default=[16, 64],
                   help="also N collection instances of one mesh (issue 31's target: 1000)")
    p.add_argument("--instance-bounces", type=int, default=0,
                   help="diffuse bounces of the instances' scene (0: direct light)")
    p.add_argument("--instance-vertices", type=int, default=5000,
                   help="vertices of the instanced mesh")
    p.add_argument("--out-file", type=pathlib.Path, default=scenes.ROOT / "out/bench/scale.txt")
    p.add_argument("--child", default=None, help=argparse.SUPPRESS)
    p.add_argument("--blend", default=None, help=argparse.SUPPRESS)
    p.add_argument("--f12", default=None, help=argparse.SUPPRESS)
    return p.parse_args(argv)


# ------------------------------------------------------------------ one size (child)

def _memory():
    got = {}
    with open("/proc/self/status") as f:
        for line in f:
            if line.startswith(("VmHWM", "VmRSS")):
                got[line.split(":")[0]] = int(line.split()[1]) * 1024
    return got


def _reset_peak():
    """Peak RSS from here (Linux: writing 5 to clear_refs resets VmHWM)."""
    try:
        with open("/proc/self/clear_refs", "w") as f:
            f.write("5")
    except OSError:
        pass


def _peak() -> int:
    return _memory().get("VmHWM", 0)


def add_suzanne(vertices=None, subsurf=None, height=1.6):
    """Suzanne cut to ``vertices`` (each face cut k x k, smoothed, then single cuts to make
    up the count) or with a Subdivision Surface modifier of ``subsurf`` levels, standing
    on the ground."""
    import bmesh
    import bpy
    if subsurf is not None:
        return scenes.add_suzanne(subdiv=subsurf, height=height)
    bpy.ops.mesh.primitive_monkey_add()
    ob = bpy.context.active_object
    ob.name = "Suzanne"
    k = max(1, math.floor(math.sqrt(vertices / 485.0)))   # the cuts stay under the count
    bm = bmesh.new()
    bm.from_mesh(ob.data)
    if k > 1:
        bmesh.ops.subdivide_edges(bm, edges=bm.edges[:], cuts=k - 1, smooth=1.0,
                                  use_grid_fill=True)
    # the k x k cuts land near the request; one more cut on evenly spaced edges makes up
    # the rest, so "5k vertices" has at least 5k
    short = vertices - len(bm.verts)
    if 0 < short <= len(bm.edges):
        edges = bm.edges[:]
        step = len(edges) / short
        bmesh.ops.subdivide_edges(bm, edges=[edges[int(i * step)] for i in range(short)],
                                  cuts=1, smooth=1.0)
    bm.to_mesh(ob.data)
    bm.free()
    ob.rotation_euler = (math.radians(-20.0), 0.0, 0.0)
    for poly in ob.data.polygons:
        poly.use_smooth = True
    scenes._stand_on_ground(ob, height)
    return ob


class _EscEngine:
    """What render() uses of a RenderEngine; ESC (``test_break``) after ``after`` s."""

    def __init__(self, after):
        self.start = time.perf_counter()
        self.after = after
        self.pressed = None
        self.progress = []

    def update_progress(self, fraction):
        self.progress.append(fraction)

    def test_break(self):
        if time.perf_counter() - self.start >= self.after:
            if self.pressed is None:
                self.pressed = time.perf_counter()
            return True
        return False

    def report(self, kind, message):
        pass

    def update_stats(self, a, b):
        pass

    def begin_result(self, *args, **kwargs):
        raise RuntimeError("the render was not stopped")

    def end_result(self, result):
        pass


def child(spec: str, args) -> dict:
    """One size: precompute and REFERENCE's F12 (the defaults) in one process, the file
    saved for the other methods' F12s, ESC, AUTO's choice and its first F12."""
    import bpy
    scenes.reset()                                    # registers prt_relight
    from prt_relight.addon.blender import storage
    from prt_relight.addon.frame.engine import PRTRenderEngine
    from prt_relight.addon.methods.auto import shading as auto
    from prt_relight.addon.gpu.drawing import ensure_gpu
    kind, value = spec.split("=")
    scenes.add_world(args.hdri)
    scenes.add_ground(cuts=64)
    ob = add_suzanne(**{kind: int(value)})
    scenes.add_camera(resolution=(args.size, args.size))
    scene = bpy.context.scene
    depsgraph = bpy.context.evaluated_depsgraph_get()
    vertices = len(ob.evaluated_get(depsgraph).data.vertices)
    out = dict(spec=spec, vertices=vertices, cores=os.cpu_count())
    tmp = pathlib.Path(args.blend).parent
    bpy.ops.wm.save_as_mainfile(filepath=str(tmp / "before.blend"), copy=True)
    before = os.path.getsize(tmp / "before.blend")
    out["setup_rss"] = _memory()["VmRSS"]

    # precompute: REFERENCE (the default), gather/run/commit as the operator's execute; the
    # direct light's first (bounces 0: today's figures), the bounces' at the end
    scene.cycles.max_bounces = 0
    _reset_peak()
    t = scenes.precompute(32)
    out.update(points=t["points"], precompute_s=t["total"], rays_s=t["rays"],
               encode_s=t["encode"], precompute_peak=_peak())
    stored = sum(storage.stored_bytes(o, storage.VISIBILITY) for o in bpy.data.objects)
    out["stored_bytes_per_point"] = stored / t["points"]
    bpy.ops.wm.save_as_mainfile(filepath=str(args.blend), copy=True)
    out["blend_growth"] = os.path.getsize(args.blend) - before
    out["blend_bytes_per_point"] = out["blend_growth"] / t["points"]
    print(json.dumps({k: out[k] for k in ("vertices", "points", "precompute_s")}), flush=True)

    # F12 with the default method in the same process: the peak over both
    out["f12_s"] = {"REFERENCE": scenes.render_prt(tmp / "frame.exr")}
    out["f12_peak"] = {"REFERENCE": _peak()}
    out["precompute_f12_peak"] = _peak()

    # ESC: REFERENCE's F12 stopped by a stand-in engine
    ensure_gpu(scene)
    engine = _EscEngine(args.esc_after)
    PRTRenderEngine.render(engine, bpy.context.evaluated_depsgraph_get())
    out["esc_s"] = (time.perf_counter() - engine.pressed) if engine.pressed else float("nan")
    out["esc_progress_updates"] = len(engine.progress)

    # AUTO's choice (nothing measured before), then its first frame with that choice
    scene.prt.method = "AUTO"
    auto.CHOICE_CACHE.clear()
    _reset_peak()
    t0 = time.perf_counter()
    bpy.ops.prt.auto_choose()
    out["auto_choice_s"] = time.perf_counter() - t0
    out["auto_choice_peak"] = _peak()
    record = json.loads(scene.prt.auto_choice)
    out["auto_choice"] = {c["object"]: c["choice"] for c in record["objects"]}
    out["auto_error"] = {c["object"]: [c["error"], c.get("margin")] for c in record["objects"]}
    print(json.dumps({"auto_choice_s": out["auto_choice_s"], "choice": out["auto_choice"]}),
          flush=True)
    if "AUTO" in args.methods:
        _reset_peak()
        out["f12_s"]["AUTO"] = scenes.render_prt(tmp / "frame.exr")
        out["f12_peak"]["AUTO"] = _peak()
        out["auto_first_f12_s"] = out["auto_choice_s"] + out["f12_s"]["AUTO"]
    out.update(_bounces(scene, tmp, before))
    return out


def child_instances(count: int, args) -> dict:
    """``count`` collection instances of one Suzanne of ``args.instance_vertices``
    vertices, turned at random on a grid 1.2 m apart on a ground: the precompute and
    REFERENCE's F12, their times and peaks, and the bytes per instance."""
    import bpy
    scenes.reset(bounces=args.instance_bounces)
    from prt_relight.addon.blender import storage, surfaces
    from prt_relight.core.scene import mesh as core_mesh
    scenes.add_world(args.hdri)
    side = math.ceil(math.sqrt(count))
    scenes.add_ground(size=1.2 * side + 1.0, cuts=64)
    ob = add_suzanne(vertices=args.instance_vertices, height=0.8)
    source = bpy.data.collections.new("Source")
    bpy.context.scene.collection.children.link(source)
    for c in list(ob.users_collection):
        c.objects.unlink(ob)
    source.objects.link(ob)
    bpy.context.view_layer.layer_collection.children["Source"].exclude = True
    rng = np.random.default_rng(1)
    for i in range(count):
        e = bpy.data.objects.new(f"I{i}", None)
        e.instance_type, e.instance_collection = "COLLECTION", source
        e.location = (1.2 * (i % side - (side - 1) / 2), 1.2 * (i // side - (side - 1) / 2), 0)
        e.rotation_euler.z = rng.uniform(0.0, 2.0 * math.pi)
        bpy.context.scene.collection.objects.link(e)
    scenes.add_camera(target=(0.0, 0.0, 0.0), distance=1.6 * side + 3.0, elevation_deg=45.0,
                      resolution=(args.size, args.size))
    scene = bpy.context.scene
    found = surfaces.scene_surfaces(bpy.context.evaluated_depsgraph_get())
    shared = surfaces.SharedArrays()
    one = shared.arrays(next(f for f in found if f.instance))
    occ = core_mesh.occluder_mesh(one)[0]
    # what an instance holds of its own in the precompute: its occluders (its positions and
    # corner normals are placed when read, core.scene.mesh.PlacedArrays)
    copies = occ.vertices.nbytes + occ.triangles.nbytes
    out = dict(instances=count, vertices=len(ob.data.vertices), cores=os.cpu_count(),
               shared_bytes=shared.nbytes(), copy_bytes_per_instance=copies)
    tmp = pathlib.Path(args.blend).parent
    bpy.ops.wm.save_as_mainfile(filepath=str(tmp / "before.blend"), copy=True)
    before = os.path.getsize(tmp / "before.blend")
    _reset_peak()
    t = scenes.precompute(32)
    out.update(points=t["points"], precompute_s=t["total"], precompute_peak=_peak())
    records = [r for e in scene.objects for r in storage.instance_records(e)]
    out["stored_bytes_per_instance"] = sum(storage.stored_bytes(r) for r in records) / count
    bpy.ops.wm.save_as_mainfile(filepath=str(args.blend), copy=True)
    out["blend_bytes_per_instance"] = (os.path.getsize(args.blend) - before) / count
    print(json.dumps({k: out[k] for k in ("instances", "points", "precompute_s")}), flush=True)
    out["f12_s"] = scenes.render_prt(tmp / "frame.exr")
    out["precompute_f12_peak"] = _peak()
    return out


def instance_table(results) -> str:
    rows = [("instances", lambda r: f"{r['instances']}"),
            ("vertices per instance", lambda r: f"{r['vertices']}"),
            ("shading points (all)", lambda r: f"{r['points']}"),
            ("precompute s", lambda r: f"{r['precompute_s']:.1f}"),
            ("  per instance s", lambda r: f"{r['precompute_s'] / r['instances']:.2f}"),
            ("precompute peak MiB", lambda r: _mib(r["precompute_peak"])),
            ("F12 REFERENCE s", lambda r: f"{r['f12_s']:.1f}"),
            ("precompute + F12 peak MiB", lambda r: _mib(r["precompute_f12_peak"])),
            ("stored KiB per instance", lambda r: f"{r['stored_bytes_per_instance'] / 1024:.0f}"),
            (".blend KiB per instance", lambda r: f"{r['blend_bytes_per_instance'] / 1024:.0f}"),
            ("copies KiB per instance (occluders)",
             lambda r: f"{r['copy_bytes_per_instance'] / 1024:.0f}"),
            ("shared source arrays KiB", lambda r: f"{r['shared_bytes'] / 1024:.0f}")]
    width = max(len(n) for n, _ in rows)
    lines = [f"{n:<{width}} " + "".join(f"{fn(r):>10}" for r in results) for n, fn in rows]
    if len(results) >= 2:
        x = np.array([r["instances"] for r in results], float)

        def slope(key, scale=1.0):
            return np.polyfit(x, np.array([r[key] for r in results], float) * scale, 1)

        lines += ["", "growth per instance (least-squares slope over the counts), and at 1000 if it "
                  "went on so (an upper bound for the peak below ~100 instances: the decoded "
                  "visibility's cache fills up to 256 MiB; run --instances 1000 to measure)"]
        for name, key, unit, scale in (("precompute", "precompute_s", "s", 1.0),
                                       ("precompute + F12 peak", "precompute_f12_peak",
                                        "MiB", 2 ** -20)):
            a, b = slope(key, scale)
            lines.append(f"  {name:<22} {a:+.3f} {unit}  (1000: ~{a * 1000 + b:.0f} {unit})")
    return "\n".join(lines) + "\n"


def _turn_world(scene, angle: float):
    """Turn the World's Environment Texture about Z by ``angle`` more (a Mapping node)."""
    nt = scene.world.node_tree
    mapping = next((n for n in nt.nodes if n.type == "MAPPING"), None)
    if mapping is None:
        env = next(n for n in nt.nodes if n.type == "TEX_ENVIRONMENT")
        coord = nt.nodes.new("ShaderNodeTexCoord")
        mapping = nt.nodes.new("ShaderNodeMapping")
        nt.links.new(coord.outputs["Generated"], mapping.inputs["Vector"])
        nt.links.new(mapping.outputs["Vector"], env.inputs["Vector"])
    mapping.inputs["Rotation"].default_value[2] += angle


def _bounces(scene, tmp, before) -> dict:
    """Issue 29's scale figures: REFERENCE's precompute with Cycles' default Light Paths
    (4 diffuse bounces) against the direct one, its stored bytes per point, the peak, and
    a relit F12 (the world turned) with the bounce against the same frame without."""
    import bpy
    from prt_relight.addon.blender import storage
    out = {}
    scene.prt.method = "REFERENCE"
    relit = {}
    for bounces in (0, 4):
        scene.cycles.max_bounces = 12 if bounces else 0
        scene.cycles.diffuse_bounces = max(bounces, 1)
        _reset_peak()
        t = scenes.precompute(32)
        out[f"precompute_b{bounces}_s"] = t["total"]
        out[f"precompute_b{bounces}_peak"] = _peak()
        scenes.render_prt(tmp / "frame.exr")                  # the first frame's caches
        _turn_world(scene, 0.4)
        relit[bounces] = scenes.render_prt(tmp / "frame.exr")
    points = t["points"]
    out["bounce_bytes_per_point"] = sum(
        storage.stored_bytes(o, storage.BOUNCE) for o in bpy.data.objects) / points
    bpy.ops.wm.save_as_mainfile(filepath=str(tmp / "bounce.blend"), copy=True)
    out["bounce_blend_bytes_per_point"] = (os.path.getsize(tmp / "bounce.blend") - before) \
        / points
    out["precompute_bounce_ratio"] = out["precompute_b4_s"] / out["precompute_b0_s"]
    out["relit_f12_b0_s"], out["relit_f12_b4_s"] = relit[0], relit[4]
    out["relit_f12_bounce_ratio"] = relit[4] / relit[0]
    scene.cycles.max_bounces = 0
    return out


def child_f12(blend: str, method: str) -> dict:
    """The first F12 of ``method`` on the saved file, in a process of its own."""
    import bpy
    scenes.load_addon()
    bpy.ops.wm.open_mainfile(filepath=blend)
    bpy.context.scene.prt.method = method
    _reset_peak()
    seconds = scenes.render_prt(pathlib.Path(blend).parent / f"{method}.exr")
    return dict(method=method, s=seconds, peak=_peak())


# ------------------------------------------------------------------ table (parent)

def _available_memory() -> float:
    with open("/proc/meminfo") as f:
        for line in f:
            if line.startswith("MemAvailable"):
                return int(line.split()[1]) * 1024.0
    return float("inf")


def _points_of(spec: str) -> int:
    """About how many shading points a size has (Suzanne's vertices + the 65^2 ground)."""
    kind, value = spec.split("=")
    vertices = int(value) if kind == "vertices" else 500 * 4 ** int(value)
    return vertices + 65 * 65


def _too_big(results, spec, methods, budget) -> dict:
    """Methods whose F12 at ``spec`` would pass ``budget`` bytes: their peak above the
    scene's set-up grows with the points as it did at the largest size done so far."""
    if not results:
        return {}
    prev = max(results, key=lambda r: r["points"])
    out = {}
    for m in methods:
        if m in prev.get("skipped", {}):
            out[m] = prev["skipped"][m] * _points_of(spec) / prev["points"]
            continue
        peak = prev["f12_peak"].get(m)
        if peak:
            need = prev["setup_rss"] + (peak - prev["setup_rss"]) * _points_of(spec) / prev["points"]
            if need > budget:
                out[m] = need
    return out


def _mib(b):
    return f"{b / 2 ** 20:.0f}"


def table(results, methods) -> str:
    rows = []

    def col(name, fn):
        rows.append((name, [fn(r) for r in results]))

    col("vertices (Suzanne)", lambda r: f"{r['vertices']}")
    col("shading points", lambda r: f"{r['points']}")
    col("precompute s", lambda r: f"{r['precompute_s']:.1f}")
    col("  of which rays s", lambda r: f"{r['rays_s']:.1f}")
    col("precompute peak MiB", lambda r: _mib(r["precompute_peak"]))
    col("precompute + F12 peak MiB", lambda r: _mib(r["precompute_f12_peak"]))
    col("stored B/point", lambda r: f"{r['stored_bytes_per_point']:.1f}")
    col(".blend growth MB", lambda r: f"{r['blend_growth'] / 1e6:.2f}")
    col(".blend B/point", lambda r: f"{r['blend_bytes_per_point']:.1f}")
    col("AUTO choice s", lambda r: f"{r['auto_choice_s']:.1f}")
    col("AUTO choice / precompute", lambda r: f"{r['auto_choice_s'] / r['precompute_s']:.2f}")
    col("AUTO first F12 / precompute", lambda r: (
        f"{r['auto_first_f12_s'] / r['precompute_s']:.2f}" if "auto_first_f12_s" in r else "-"))
    col("AUTO choice peak MiB", lambda r: _mib(r["auto_choice_peak"]))
    def skipped(r, m):
        need = r.get("skipped", {}).get(m)
        return None if need is None else f"(~{need / 2 ** 30:.0f} GiB)"

    for m in methods:
        col(f"F12 {m} s", lambda r, m=m: skipped(r, m) or
            f"{r['f12_s'].get(m, float('nan')):.1f}")
    for m in methods:
        col(f"F12 {m} peak MiB", lambda r, m=m: skipped(r, m) or
            _mib(r["f12_peak"].get(m, 0)))
    col("largest peak MiB (any step)", lambda r: _mib(r["peak"]))
    col("ESC to stop s (REFERENCE F12)", lambda r: f"{r['esc_s']:.2f}")
    col("bounces: precompute / direct's", lambda r: f"{r['precompute_bounce_ratio']:.2f}")
    col("bounces: peak MiB", lambda r: _mib(r["precompute_b4_peak"]))
    col("bounces: stored B/point", lambda r: f"{r['bounce_bytes_per_point']:.1f}")
    col("bounces: .blend B/point (all)", lambda r: f"{r['bounce_blend_bytes_per_point']:.1f}")
    col("bounces: relit F12 / direct's", lambda r: f"{r['relit_f12_bounce_ratio']:.2f}")
    col("progress updates before ESC", lambda r: f"{r['esc_progress_updates']}")
    width = max(len(n) for n, _ in rows)
    cw = max(10, max(len(v) for _, vs in rows for v in vs) + 1)
    lines = [f"{name:<{width}} " + "".join(f"{v:>{cw}}" for v in vs) for name, vs in rows]

    # growth per 100k vertices: least-squares slope over the sizes
    if len(results) >= 2:
        x = np.array([r["vertices"] for r in results], float) / 1e5
        lines.append("")
        lines.append("growth per 100k vertices (least-squares slope over the sizes):")

        def slope(values, unit, scale=1.0):
            y = np.array(values, float) * scale
            if not np.isfinite(y).all():
                return "-"
            return f"{np.polyfit(x, y, 1)[0]:+.2f} {unit}"
        growth = [
            ("precompute", slope([r["precompute_s"] for r in results], "s")),
            ("precompute peak", slope([r["precompute_peak"] for r in results], "MiB",
                                      2 ** -20)),
            (".blend", slope([r["blend_growth"] for r in results], "MB", 1e-6)),
            ("AUTO choice", slope([r["auto_choice_s"] for r in results], "s")),
            ("precompute + F12 peak", slope([r["precompute_f12_peak"] for r in results],
                                            "MiB", 2 ** -20)),
        ] + [(f"F12 {m}", slope([r["f12_s"].get(m, float("nan")) for r in results], "s"))
             for m in methods] + [
            (f"F12 {m} peak", slope([r["f12_peak"].get(m, float("nan")) for r in results],
                                    "MiB", 2 ** -20)) for m in methods]
        gw = max(len(n) for n, _ in growth)
        lines += [f"  {n:<{gw}}  {v}" for n, v in growth]
    choices = [f"{r['vertices']}: " + ", ".join(f"{o} -> {c}" for o, c in r["auto_choice"].items())
               for r in results]
    lines += ["", "AUTO's choices:"] + ["  " + c for c in choices]
    if any(r.get("skipped") for r in results):
        lines += ["", "(~N GiB): F12 not run, it would need about that much (its peak per "
                      "point at the previous size)"]
    return "\n".join(lines) + "\n"


def _run(cmd) -> dict:
    proc = subprocess.run(cmd, capture_output=True, text=True)
    lines = proc.stdout.splitlines()
    for line in lines:
        if not line.startswith("RESULT ") and line.strip() and "EGL" not in line:
            print("   " + line, flush=True)
    got = [json.loads(line[7:]) for line in lines if line.startswith("RESULT ")]
    if proc.returncode != 0 or not got:
        print(proc.stderr[-3000:], flush=True)
        return {"failed": proc.returncode}
    return got[0]


def main(argv=None):
    args = parse_args(argv)
    if args.child and args.child.startswith("instances="):
        print("RESULT " + json.dumps(child_instances(int(args.child[10:]), args)), flush=True)
        return 0
    if args.child or args.f12:
        result = child(args.child, args) if args.child else child_f12(args.blend, args.f12)
        print("RESULT " + json.dumps(result), flush=True)
        return 0
    specs = [f"vertices={v}" for v in args.vertices] + [f"subsurf={s}" for s in args.subsurf]
    budget = (args.memory_budget * 2 ** 30 if args.memory_budget
              else 0.7 * _available_memory())
    results = []
    for spec in specs:
        print(f"== {spec}", flush=True)
        skipped = _too_big(results, spec, args.methods, budget)
        for m, need in skipped.items():
            print(f"   F12 {m} skipped: it would need ~{need / 2 ** 30:.1f} GiB "
                  f"(budget {budget / 2 ** 30:.1f} GiB)", flush=True)
        with tempfile.TemporaryDirectory() as tmp:
            blend = str(pathlib.Path(tmp) / "scale.blend")
            methods = [m for m in args.methods if m == "AUTO" and m not in skipped]
            result = _run([sys.executable, __file__, "--child", spec, "--blend", blend,
                           "--hdri", args.hdri, "--size", str(args.size),
                           "--esc-after", str(args.esc_after), "--methods", *methods])
            if "failed" in result:
                raise SystemExit(f"{spec} failed (exit {result['failed']})")
            for m in args.methods:
                if m in ("REFERENCE", "AUTO") or m in skipped:
                    continue
                got = _run([sys.executable, __file__, "--f12", m, "--blend", blend])
                result["f12_s"][m] = got.get("s", float("nan"))
                result["f12_peak"][m] = got.get("peak", float("nan"))
                print(f"   F12 {m}: {result['f12_s'][m]:.1f} s, peak "
                      f"{result['f12_peak'][m] / 2 ** 20:.0f} MiB", flush=True)
        result["skipped"] = skipped
        result["peak"] = max(v for v in [result["precompute_f12_peak"],
                                         result["auto_choice_peak"]]
                             + list(result["f12_peak"].values()) if np.isfinite(v))
        results.append(result)
    placed = []
    for count in args.instances:
        print(f"== instances={count}", flush=True)
        with tempfile.TemporaryDirectory() as tmp:
            got = _run([sys.executable, __file__, "--child", f"instances={count}",
                        "--blend", str(pathlib.Path(tmp) / "instances.blend"),
                        "--hdri", args.hdri, "--size", str(args.size),
                        "--instance-vertices", str(args.instance_vertices),
                        "--instance-bounces", str(args.instance_bounces)])
        if "failed" in got:
            raise SystemExit(f"instances={count} failed (exit {got['failed']})")
        placed.append(got)
    import platform
    header = (f"bench_scale: Suzanne on a 64^2 ground, HDRI {args.hdri}, F12 {args.size}^2, "
              f"default settings; {os.cpu_count()} cores, {platform.processor() or platform.machine()}\n")
    text = header + (table(results, args.methods) if results else "")
    if placed:
        text += (f"\ninstances: collection instances of a {placed[0]['vertices']}-vertex "
                 "Suzanne on a grid, each traced in place:\n" + instance_table(placed))
    args.out_file.parent.mkdir(parents=True, exist_ok=True)
    args.out_file.write_text(text)
    args.out_file.with_suffix(".json").write_text(json.dumps(
        {"sizes": results, "instances": placed}, indent=1))
    print(text, end="")
    print(f"(written to {args.out_file})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
