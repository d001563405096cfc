"""RSL (rotatable square lights, Xu et al. 2006) against REFERENCE: the K table of Fig. 9/10.

    .venv/bin/python bench/bench_rsl.py [--mesh spot.obj] [--hdri forest city]
                                        [--resolution 160x120]

Held-out scenes (the decomposition cost was tuned on sunset and courtyard): a mesh with Cycles'
default Principled surface on a diffuse 96² ground grid, each listed HDRI rotated 0.6 rad.
For K = 10, 30, 60, 100 it prints the rel-L2 of the F12 image against REFERENCE's (pixels
with alpha > 0.5) and of the per-vertex radiance, the per-frame shading time, the F12 time
against REFERENCE's F12 (first render, which includes the decomposition, and a
second one with the lights cached) and the decomposition time of the 6x32² cubemap.  Writes
out/bench/rsl.txt.
"""

from __future__ import annotations

import argparse
import pathlib
import statistics
import sys
import time

import numpy as np

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))
import scenes  # noqa: E402
from prt_relight.core.report.metrics import rel_l2  # noqa: E402  (importing scenes registers prt_relight)

COUNTS = (10, 30, 60, 100)


def _state():
    import bpy
    from prt_relight.addon.frame.state import FrameState
    state = FrameState()
    state.sync(bpy.context.evaluated_depsgraph_get())
    return state


def _shade(state, repeats=3):
    import bpy
    eye = np.array(bpy.context.scene.camera.matrix_world.translation)
    out = state.shade(eye)                               # warm caches
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        out = state.shade(eye)
        times.append(time.perf_counter() - t0)
    return np.concatenate(out), statistics.median(times)


def run_scene(mesh, hdri, w, h, out_dir, lines):
    import bpy
    scenes.reset()
    from prt_relight.core.sphere import directions
    from prt_relight.core.methods.rsl import square_lights
    from prt_relight.addon.methods.rsl import shading as rsl_method
    scenes.add_world(hdri, rotation_z=0.6)
    ground = scenes.add_ground(cuts=96)
    scenes.add_bsdf_material(ground, "Ground", "ShaderNodeBsdfDiffuse",
                             Color=(0.8, 0.8, 0.8, 1.0))
    if mesh.is_file():
        scenes.add_obj(mesh)
    else:
        scenes.add_suzanne()
    scenes.add_camera()
    r = bpy.context.scene.render
    r.resolution_x, r.resolution_y, r.resolution_percentage = w, h, 100
    prt = bpy.context.scene.prt
    prt.method = "RSL"
    pre = scenes.precompute(resolution=32, method="RSL")

    prt.method = "REFERENCE"
    ref_f12 = scenes.render_prt(out_dir / f"rsl_{hdri}_REFERENCE.exr")
    ref_warm = scenes.render_prt(out_dir / f"rsl_{hdri}_REFERENCE.exr")
    ref_img = scenes.read_exr(out_dir / f"rsl_{hdri}_REFERENCE.exr")
    ref_vert, ref_t = _shade(_state())

    prt.method = "RSL"
    state = _state()
    _, lighting = rsl_method.unrotated_lighting(state.world, 32)
    cube = directions.cubemap(32)
    head = (f"{mesh.stem if mesh.is_file() else 'suzanne'} + 96² grid, HDRI {hdri} (rot 0.6), "
            f"{w}x{h}, {pre['points']} points (RSL precompute: rays {pre.get('rays', 0):.1f} s, "
            f"VDT + CPCA {pre.get('derive', 0):.1f} s, {pre.get('rsl_cpca', '')}); "
            f"REFERENCE F12 {ref_f12:.2f} s (again: {ref_warm:.2f} s), shade {ref_t:.3f} s")
    lines += [head, f"{'K':>4s} {'rel-L2 F12':>10s} {'rel-L2 vtx':>10s} {'shade':>8s} "
                    f"{'F12':>7s} {'F12/REF':>8s} {'F12 again':>9s} {'/REF':>6s} {'decomp':>7s}"]
    print(lines[-2] + "\n" + lines[-1], flush=True)
    for K in COUNTS:
        t0 = time.perf_counter()
        square_lights.decompose(lighting, cube, K)
        decomp = time.perf_counter() - t0
        prt.rsl_lights = K
        path = out_dir / f"rsl_{hdri}_{K}.exr"
        f12 = scenes.render_prt(path)                 # includes the decomposition
        warm = scenes.render_prt(path)                # lights and tables cached
        img = scenes.read_exr(path)
        vert, t = _shade(_state())
        err_vtx = float(np.linalg.norm(vert - ref_vert) / np.linalg.norm(ref_vert))
        err = rel_l2(img, ref_img)
        lines.append(f"{K:4d} {err:10.4f} {err_vtx:10.4f} {t:7.3f}s {f12:6.2f}s "
                     f"{f12 / ref_f12:8.3f} {warm:8.2f}s {warm / ref_warm:6.3f} {decomp:6.2f}s")
        print(lines[-1], flush=True)


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--mesh", type=pathlib.Path,
                   default=scenes.ROOT.parent / "shared/data/meshes/spot.obj")
    p.add_argument("--hdri", nargs="+", default=["forest", "city"])
    p.add_argument("--resolution", default="160x120")
    p.add_argument("--out", type=pathlib.Path, default=scenes.ROOT / "out/bench/rsl.txt")
    args = p.parse_args(argv)
    w, h = (int(v) for v in args.resolution.lower().split("x"))
    out_dir = args.out.parent
    out_dir.mkdir(parents=True, exist_ok=True)
    lines = ["RSL vs REFERENCE (rel-L2 of F12 pixels and of per-vertex radiance; times on this "
             "machine, one run)"]
    for hdri in args.hdri:
        run_scene(args.mesh, hdri, w, h, out_dir, lines)
    from prt_relight.core.shading import materials
    from prt_relight.core.methods.rsl import shading as rsl
    for mat in (materials.principled_material(roughness=0.5), materials.principled_material(roughness=0.3)):
        rsl.brdf_tables(mat)                          # warm (Cycles' albedo tables load once)
        t0 = time.perf_counter()
        rsl.brdf_tables(mat, 32, 32, 3)
        lines.append(f"BRDF SAT rebuild (32 views x 32², Principled r={mat.roughness}): "
                     f"{(time.perf_counter() - t0) * 1000:.0f} ms")
        print(lines[-1], flush=True)
    text = "\n".join(lines)
    print(text)
    args.out.write_text(text + "\n")


if __name__ == "__main__":
    main()
