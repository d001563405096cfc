# SPDX-License-Identifier: GPL-3.0-or-later
"""Demo: Suzanne on a ground grid under a bundled HDRI, PRT_RELIGHT F12 vs Cycles.

    python bench/demo.py --out out/demo [--hdri sunset] [--resolution 320x240]
                         [--cycles-samples 256]

Writes prt.exr/.png, cycles.exr/.png (EXR: linear radiance, film transparent;
PNG: through the scene's view transform), compare.png (prt | cycles | error)
and report.txt (precompute time split, F12 and Cycles times, rel-L2 of our
render against Cycles over the pixels Cycles covers).
"""

from __future__ import annotations

import argparse
import pathlib
import sys

import numpy as np

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))
import scenes  # noqa: E402
from prt_relight.core.report.metrics import rel_l2  # noqa: E402  (importing scenes registers prt_relight)


def parse_args(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--out", required=True, type=pathlib.Path, help="output folder")
    p.add_argument("--hdri", default="sunset", help="bundled HDRI name (sunset, forest, ...)")
    p.add_argument("--resolution", default="320x240", help="WIDTHxHEIGHT")
    p.add_argument("--cycles-samples", type=int, default=256)
    p.add_argument("--subdiv", type=int, default=2, help="Suzanne subdivision levels")
    args = p.parse_args(argv)
    try:
        w, h = (int(v) for v in args.resolution.lower().split("x"))
    except ValueError:
        p.error("--resolution must look like 320x240")
    args.size = (w, h)
    return args


def _heat(err: np.ndarray, vmax: float) -> np.ndarray:
    """Black -> red -> yellow -> white for err in [0, vmax]."""
    x = np.clip(err / vmax, 0.0, 1.0)[..., None]
    return np.clip(np.concatenate([3 * x, 3 * x - 1, 3 * x - 2], axis=-1), 0.0, 1.0)


def write_compare(path, prt_png, cycles_png, prt, ref):
    """prt | cycles | relative error heat map (|diff| / mean reference, 0..50 %)."""
    import OpenImageIO as oiio

    def over_grey(p):
        buf = oiio.ImageBuf(str(p))
        img = np.asarray(buf.get_pixels(oiio.FLOAT), dtype=np.float32)
        rgb, a = img[..., :3], (img[..., 3:4] if img.shape[-1] > 3 else 1.0)
        return rgb * a + 0.25 * (1.0 - a)

    mask = ref[..., 3] > 0.5
    diff = np.linalg.norm(prt[..., :3] - ref[..., :3], axis=-1)
    scale = max(float(np.linalg.norm(ref[..., :3], axis=-1)[mask].mean()), 1e-12) if mask.any() else 1
    heat = _heat(diff / scale, 0.5) * mask[..., None]
    strip = np.concatenate([over_grey(prt_png), over_grey(cycles_png), heat], axis=1)
    out = oiio.ImageBuf(oiio.ImageSpec(strip.shape[1], strip.shape[0], 3, oiio.UINT8))
    out.set_pixels(oiio.ROI(), np.ascontiguousarray(strip, dtype=np.float32))
    if not out.write(str(path)):
        raise RuntimeError(out.geterror())


def main(argv=None):
    args = parse_args(argv)
    out = args.out.resolve()
    out.mkdir(parents=True, exist_ok=True)

    scenes.reset()
    scenes.add_world(args.hdri)
    scenes.add_ground()
    scenes.add_suzanne(subdiv=args.subdiv)
    scenes.add_camera(resolution=args.size)

    t = scenes.precompute(resolution=32)
    prt_s = scenes.render_prt(out / "prt.exr", png=out / "prt.png")
    cyc_s = scenes.render_cycles(out / "cycles.exr", samples=args.cycles_samples,
                                 png=out / "cycles.png")
    prt, ref = scenes.read_exr(out / "prt.exr"), scenes.read_exr(out / "cycles.exr")
    err = rel_l2(prt, ref)
    coverage = float(((prt[..., 3] > 0.5) == (ref[..., 3] > 0.5)).mean())
    try:
        write_compare(out / "compare.png", out / "prt.png", out / "cycles.png", prt, ref)
        compare_note = "compare.png: prt | cycles | error (|diff| / mean ref, 0..50 %)"
    except Exception as exc:  # optional output
        compare_note = f"compare.png not written: {exc}"

    w, h = args.size
    accounted = t["export"] + t["build_bvh"] + t["rays"] + t["tessellation_check"] + t["storage"]
    lines = [
        f"prt_relight demo: Suzanne (subsurf {args.subdiv}) on a grid, HDRI '{args.hdri}', "
        f"{w}x{h}",
        f"precompute: REFERENCE, 6x32x32 directions, {t['points']} points, "
        f"{t['ray_count'] / 1e6:.1f} M rays",
        f"  export       {t['export']:8.2f} s",
        f"  BVH build    {t['build_bvh']:8.2f} s",
        f"  rays         {t['rays']:8.2f} s   ({t['rays_per_second'] / 1e6:.2f} M rays/s)",
        f"  tessellation {t['tessellation_check']:8.2f} s   (coarse-receiver check)",
        f"  storage      {t['storage']:8.2f} s",
        f"  other        {t['total'] - accounted:8.2f} s",
        f"  total        {t['total']:8.2f} s",
        f"  last_report  {t['report']}",
        f"F12 PRT_RELIGHT      {prt_s:8.2f} s  (supersampling x{_ss()})",
        f"F12 Cycles           {cyc_s:8.2f} s  ({args.cycles_samples} spp, max_bounces 0, CPU)",
        f"rel-L2 vs Cycles     {err:8.4f}    (RGB, pixels with Cycles alpha > 0.5)",
        f"alpha agreement      {coverage:8.4f}",
    ]
    lines += [f"warning: {x}" for x in t["warnings"]]
    lines.append(compare_note)
    report = "\n".join(lines) + "\n"
    (out / "report.txt").write_text(report)
    print(report, end="")
    return 0


def _ss():
    import bpy
    return bpy.context.scene.prt.supersampling


if __name__ == "__main__":
    sys.exit(main())
