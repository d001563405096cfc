"""Speed against error of every method against REFERENCE, same scene, same run.

    .venv/bin/python bench/bench_methods.py [--mesh PATH] [--hdri sunset] [--resolution 320x240]

For each method and budget: the per-frame shading time (``FrameState.shade``, the
part that depends on the method; median of repeats), the F12 time, and the error of
the F12 image against REFERENCE's (rel-L2 and PSNR over pixels with alpha > 0.5;
PSNR uses the REFERENCE image's peak).  Writes out/bench/methods.txt.
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

def sweeps():
    """(method, setting name, values) for every registered method (its ``budget``),
    REFERENCE first."""
    from prt_relight.addon import methods
    out = []
    for m in methods.REGISTRY.values():
        setting, values = m.bench.budget if m.bench.budget else (None, [None])
        out.append((m.id, setting, list(values)))
    out.sort(key=lambda row: row[0] != "REFERENCE")
    return out


def psnr(a: np.ndarray, ref: np.ndarray) -> float:
    m = ref[..., 3] > 0.5
    mse = float(np.mean((a[m][:, :3] - ref[m][:, :3]) ** 2))
    peak = float(ref[m][:, :3].max())
    return float("inf") if mse == 0 else 10.0 * np.log10(peak * peak / mse)


def shade_time(repeats: int) -> float:
    import bpy
    from prt_relight.addon.frame.state import FrameState
    state = FrameState()
    state.sync(bpy.context.evaluated_depsgraph_get())
    cam = bpy.context.scene.camera
    eye = np.array(cam.matrix_world.translation)
    state.shade(eye)                                   # warm caches (transfer, lighting)
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        state.shade(eye)
        times.append(time.perf_counter() - t0)
    return statistics.median(times)


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--mesh", type=pathlib.Path,
                   default=scenes.ROOT.parent / "shared/data/meshes/stanford-bunny.obj")
    p.add_argument("--hdri", default="sunset")
    p.add_argument("--resolution", default="320x240")
    p.add_argument("--repeats", type=int, default=3)
    p.add_argument("--out", type=pathlib.Path, default=scenes.ROOT / "out/bench/methods.txt")
    args = p.parse_args(argv)
    w, h = (int(v) for v in args.resolution.lower().split("x"))
    import bpy

    scenes.reset()
    scenes.add_world(args.hdri, rotation_z=0.6)
    scenes.add_ground(cuts=96)
    if args.mesh.is_file():
        scenes.add_obj(args.mesh)
    else:
        print(f"{args.mesh} not found: using Suzanne")
        scenes.add_suzanne()
    scenes.add_camera()
    r = bpy.context.scene.render
    r.resolution_x, r.resolution_y, r.resolution_percentage = w, h, 100
    pre = scenes.precompute(resolution=32)
    prt = bpy.context.scene.prt
    out_dir = args.out.parent
    out_dir.mkdir(parents=True, exist_ok=True)

    rows, ref_img, ref_shade = [], None, None
    for method, setting, values in sweeps():
        for value in values:
            prt.method = method
            if setting:
                setattr(prt, setting, value)
            label = method if setting is None else f"{method} {setting}={value}"
            path = out_dir / f"methods_{method}_{value}.exr"
            f12 = scenes.render_prt(path)
            img = scenes.read_exr(path)
            t = shade_time(args.repeats)
            if method == "REFERENCE":
                ref_img, ref_shade = img, t
            err = rel_l2(img, ref_img)
            rows.append((label, t, f12, err, psnr(img, ref_img), ref_shade / max(t, 1e-9)))
            print(f"{label:22s} shade {t:8.4f} s  F12 {f12:6.2f} s  rel-L2 {err:.4f}  "
                  f"PSNR {rows[-1][4]:6.2f} dB  speed-up {rows[-1][5]:8.1f}x", flush=True)
    lines = [f"methods vs REFERENCE: {args.mesh.name if args.mesh.is_file() else 'Suzanne'} on "
             f"a 96^2 grid, HDRI {args.hdri}, {w}x{h}, {pre['points']} shading points, "
             "no materials (Cycles' default Principled)",
             f"{'method':22s} {'shade/frame':>12s} {'F12':>7s} {'rel-L2':>8s} {'PSNR':>9s} "
             f"{'speed-up':>9s}"]
    lines += [f"{lbl:22s} {t:11.4f}s {f:6.2f}s {e:8.4f} {ps:7.2f}dB {su:8.1f}x"
              for lbl, t, f, e, ps, su in rows]
    text = "\n".join(lines)
    print(text)
    args.out.write_text(text + "\n")


if __name__ == "__main__":
    main()
