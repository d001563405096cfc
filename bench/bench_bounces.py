"""Light that bounces, per method: error against Cycles with its bounces and against
Cycles' direct light, F12 time with and without bounces, on the bounce scenes.

    .venv/bin/python bench/bench_bounces.py [--scale 1] [--spp 512] [--methods ...]
        [--pictures docs/images]

Scenes (bench/scenes.py): the Cornell box (an area lamp, coloured walls), the window-lit
room (sunrise's sun and sky through one window, two-sided walls), Suzanne on an orange
ground under courtyard.  Per scene, Cycles renders two seeds with 4 diffuse bounces and two
with none (variance subtracted: core.report.metrics.rel_l2_converged); per method, the
precompute with bounces, then F12 with the Light Paths at 4 and at 0 (the same stored
data; the median of three warm renders).  Writes out/bench/bounces.txt and, with
``--pictures``, ours | Cycles | error pictures of the room and the box (REFERENCE).
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
from prt_relight.core.report.metrics import rel_l2_converged  # noqa: E402

OUT = scenes.ROOT / "out" / "bench"
SCENES = {"box": scenes.cornell_box, "room": scenes.window_room, "ground": scenes.coloured_ground}
#: pixel sizes at --scale 1
SIZES = {"box": (96, 96), "room": (96, 72), "ground": (96, 72)}


def _f12(path, transparent: bool, repeats: int = 3):
    """(pixels, median seconds of ``repeats`` warm F12 renders)."""
    scenes.render_exr(path, transparent=transparent)      # warm: sync, caches, shaders
    times = []
    for _ in range(repeats):
        times.append(scenes.render([path], transparent=transparent))
    return scenes.read_exr(path), statistics.median(times)


def _cycles(tmp: pathlib.Path, name: str, spp: int, transparent: bool):
    return [scenes.render_exr(tmp / f"{name}{k}.exr", "CYCLES", spp, transparent, seed=k)
            for k in range(2)]


def picture(path, ours, truth):
    """ours | Cycles | |error| (the error's scale: a quarter of Cycles' 99th percentile)
    as an 8-bit PNG, each tone-mapped by Cycles' 99th percentile (gamma 2.2)."""
    import OpenImageIO as oiio
    o, c = ours[..., :3], truth[..., :3]
    peak = max(float(np.percentile(c, 99)), 1e-6)
    tone = [np.clip((x / peak) ** (1 / 2.2), 0, 1) for x in (o, c)]
    err = np.clip(np.abs(o - c).sum(-1) / (0.25 * peak), 0, 1)
    heat = np.stack([err, 0.3 * err, 1.0 - err], -1)
    img = np.concatenate(tone + [heat], axis=1)
    img = np.repeat(np.repeat(img, 3, 0), 3, 1)
    buf = oiio.ImageBuf(oiio.ImageSpec(img.shape[1], img.shape[0], 3, oiio.UINT8))
    buf.set_pixels(oiio.ROI(), (img * 255 + 0.5).astype(np.uint8))
    pathlib.Path(path).parent.mkdir(parents=True, exist_ok=True)
    buf.write(str(path))


def run_scene(name: str, methods, spp: int, scale: float, pictures):
    import bpy
    w, h = SIZES[name]
    size = (int(w * scale), int(h * scale))
    tmp = OUT / "bounces" / name
    tmp.mkdir(parents=True, exist_ok=True)
    SCENES[name](size=size)
    transparent = name == "ground"
    scene = bpy.context.scene
    scenes.light_paths(4)
    cyc_b = _cycles(tmp, "cb", spp, transparent)
    scenes.light_paths(0)
    cyc_d = _cycles(tmp, "cd", spp, transparent)
    rows = []
    for method in methods:
        scene.prt.method = method
        scenes.light_paths(4)
        t0 = time.perf_counter()
        bpy.ops.prt.precompute()
        pre_b = time.perf_counter() - t0
        ours_b, f12_b = _f12(tmp / f"{method}_b.exr", transparent)
        scenes.light_paths(0)
        ours_d, f12_d = _f12(tmp / f"{method}_d.exr", transparent)
        t0 = time.perf_counter()
        bpy.ops.prt.precompute()
        pre_d = time.perf_counter() - t0
        rows.append(dict(
            scene=name, method=method, size=f"{size[0]}x{size[1]}",
            err_b=rel_l2_converged(ours_b, cyc_b)[2], err_d=rel_l2_converged(ours_d, cyc_d)[2],
            direct_vs_b=rel_l2_converged(ours_d, cyc_b)[2], f12_b=f12_b, f12_d=f12_d,
            pre_b=pre_b, pre_d=pre_d))
        if pictures and method == "REFERENCE" and name in ("room", "box"):
            picture(pathlib.Path(pictures) / f"bounce_{name}.png", ours_b, np.mean(cyc_b, 0))
    return rows


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--scale", type=float, default=1.0, help="pixel size factor")
    ap.add_argument("--spp", type=int, default=512, help="Cycles samples per seed")
    ap.add_argument("--scenes", nargs="+", default=list(SCENES), choices=list(SCENES))
    ap.add_argument("--methods", nargs="+",
                    default=["REFERENCE", "SSDF_SG", "RSL", "BLOCKS", "SH", "WAVELET"])
    ap.add_argument("--pictures", default=None, help="folder for the pictures")
    args = ap.parse_args(argv)
    rows = []
    for name in args.scenes:
        rows += run_scene(name, args.methods, args.spp, args.scale, args.pictures)
    lines = ["| scene | method | vs Cycles with bounces | direct vs Cycles direct | our direct "
             "vs Cycles with bounces | F12 bounces / direct (s) | ratio | precompute "
             "bounces / direct (s) |", "|---|---|---|---|---|---|---|---|"]
    for r in rows:
        lines.append(
            f"| {r['scene']} {r['size']} | {r['method']} | {100 * r['err_b']:.1f} % | "
            f"{100 * r['err_d']:.1f} % | {100 * r['direct_vs_b']:.1f} % | "
            f"{r['f12_b']:.3f} / {r['f12_d']:.3f} | {r['f12_b'] / max(r['f12_d'], 1e-9):.2f} | "
            f"{r['pre_b']:.1f} / {r['pre_d']:.1f} |")
    text = "\n".join(lines)
    OUT.mkdir(parents=True, exist_ok=True)
    (OUT / "bounces.txt").write_text(text + "\n")
    print(text)


if __name__ == "__main__":
    main()
