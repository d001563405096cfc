# SPDX-License-Identifier: GPL-3.0-or-later
"""GPU frames (issue 32, item 4): ms per frame of every method beside Workbench and EEVEE.

    python bench/gpu_frames.py [--kinds diffuse,sun,glossy,textured,lamps,teapot]
                               [--methods REFERENCE,SSDF_SG,RSL,BLOCKS,SH,WAVELET,AUTO]
                               [--size 1920 1080] [--rounds 3] [--eevee-samples 16]
                               [--append docs/measurements.md]

The scenes of bench/bench_frames.py (its ``build``), every one at ``--size`` (1920×1080 by
default), precomputed once (6×32²); per method the relit F12 (the World turned before every
frame) and the viewport frame after an HDRI turn, both measured as bench_frames measures them
(its ``relit_f12`` and ``viewport_frame``: medians of ``--rounds``), beside Workbench's F12
(the scene's Anti-Aliasing; its viewport column is its F12 without AA) and EEVEE's F12 at
``--eevee-samples`` render samples (16), of the same scene in the same run.  The header names
the GPU (``gpu.platform``) and the date.

The GPU is Blender's, reached headless through EGL: the bpy module opens EGL's default
display, and GLVND loads the vendor libraries listed in ``/usr/share/glvnd/egl_vendor.d``
(``10_nvidia.json`` before Mesa's ``50_mesa.json``).  On an NVIDIA machine:

* ``__EGL_VENDOR_LIBRARY_FILENAMES=/usr/share/glvnd/egl_vendor.d/10_nvidia.json`` makes
  NVIDIA's EGL the only one tried (in containers that mount the driver it may lie under
  ``/usr/local/nvidia/share/glvnd/egl_vendor.d/``); without a working NVIDIA EGL, GLVND falls
  back to Mesa and the frames are llvmpipe's;
* ``EGL_PLATFORM`` (``surfaceless`` or ``device``) is read by Mesa's EGL for the default
  display; NVIDIA's EGL takes a display-less default display as its GPU device;
* ``DISPLAY`` unset (no X server): the bpy module draws off screen either way.

Nothing else is needed: the repository's ``.venv`` (``make setup``) and the GPU's driver
(``libEGL_nvidia``).  The header line says which renderer ran; on a software rasterizer
(llvmpipe) the script warns that the times are that of the CPU: compare the ratios only.
"""

from __future__ import annotations

import argparse
import pathlib
import statistics
import sys
import time

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))
import bench_frames  # noqa: E402
import scenes  # noqa: E402  (importing it registers prt_relight)

SOFTWARE_WARNING = "software rasterizer: ratios only, not a GPU figure"
#: renderer names of Mesa's CPU rasterizers (device_type_get() says SOFTWARE for them too)
SOFTWARE_RENDERERS = ("llvmpipe", "softpipe", "swrast", "lavapipe")


def gpu_platform() -> dict:
    """Blender's GPU as ``gpu.platform`` names it (asked after a render: the gpu module has
    no context in a headless Blender before one)."""
    import gpu
    p = gpu.platform
    info = {"renderer": p.renderer_get(), "vendor": p.vendor_get(),
            "device": p.device_type_get(), "version": p.version_get(),
            "backend": p.backend_type_get()}
    info["software"] = (info["device"] == "SOFTWARE"
                        or any(s in info["renderer"].lower() for s in SOFTWARE_RENDERERS))
    return info


def header(info, size, rounds, samples) -> str:
    """The table's header line: the GPU, the date, what was measured."""
    line = (f"GPU frames ({time.strftime('%Y-%m-%d')}, one run, `make bench-gpu`): "
            f"{info['renderer']}, {info['vendor']}, device type {info['device']}, "
            f"{info['backend']} {info['version']}; {size[0]}×{size[1]}, the median of {rounds} "
            f"frame{'s' if rounds > 1 else ''}; relit F12 = the HDRI turned before the frame, viewport = one sample per "
            f"pixel after a turn (Workbench's: its F12 without AA), EEVEE at {samples} render "
            "samples; ÷ = relit F12 over the engine's F12")
    return line + (f". **{SOFTWARE_WARNING}**" if info["software"] else "")


def run(kind, methods, size, rounds, samples, out_dir, announce=None):
    """The rows of one scene kind: Workbench, EEVEE, then each method's relit F12 and
    viewport seconds.  ``announce(info)`` is called once the GPU has a context."""
    import bpy
    bench_frames.build(kind, size[0], resolution=size)
    scene = bpy.context.scene
    scenes.precompute(32)
    t_wb = bench_frames.workbench_f12(scene, rounds)
    if announce:
        announce(gpu_platform())
    t_wb1 = bench_frames.workbench_f12(scene, rounds, "OFF")
    scenes.render_eevee(samples=samples)                           # warm: shaders compile
    t_ee = statistics.median(scenes.render_eevee(samples=samples) for _ in range(rounds))
    rows = [(kind, "Workbench", t_wb, t_wb1, t_wb, t_ee),
            (kind, f"EEVEE ({samples} samples)", t_ee, None, t_wb, t_ee)]
    for r in rows:
        print(row(r), flush=True)
    for method in methods:
        scene.prt.method = method
        t_f12 = bench_frames.relit_f12(scene, out_dir / f"{kind}.{method}.exr", rounds)
        t_view = bench_frames.viewport_frame(scene, rounds)
        rows.append((kind, method, t_f12, t_view, t_wb, t_ee))
        print(row(rows[-1]), flush=True)
    return rows


def row(r) -> str:
    kind, method, t_f12, t_view, t_wb, t_ee = r
    view = "—" if t_view is None else f"{1e3 * t_view:.0f}"
    return (f"| {kind} | {method} | {1e3 * t_f12:.0f} | {view} | {t_f12 / t_wb:.3g}× "
            f"| {t_f12 / t_ee:.3g}× |")


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--kinds", default=",".join(bench_frames.KINDS))
    ap.add_argument("--methods", default=",".join(bench_frames.METHODS))
    ap.add_argument("--size", type=int, nargs=2, default=(1920, 1080), metavar=("W", "H"))
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--eevee-samples", type=int, default=16,
                    help="EEVEE's render samples (scene.eevee.taa_render_samples)")
    ap.add_argument("--out", default="out/gpu_frames")
    ap.add_argument("--append", default=None, help="append the table to this markdown file")
    args = ap.parse_args()
    out_dir = scenes.ROOT / args.out
    out_dir.mkdir(parents=True, exist_ok=True)
    device = {}

    def announce(info):
        # once, as soon as the first render has made the GPU context
        if not device:
            device.update(info)
            print(f"GPU: {info['renderer']} | {info['vendor']} | {info['device']} | "
                  f"{info['backend']} {info['version']}", flush=True)
            if info["software"]:
                print(f"WARNING: {SOFTWARE_WARNING}", flush=True)

    rows = []
    for kind in args.kinds.split(","):
        rows += run(kind, args.methods.split(","), args.size, args.rounds, args.eevee_samples,
                    out_dir, announce)
    lines = [header(device, args.size, args.rounds, args.eevee_samples) + ":", "",
             "| scene | method | relit F12 ms | viewport ms | ÷ Workbench | ÷ EEVEE |",
             "|---|---|---|---|---|---|", *map(row, rows), ""]
    bench_frames.report(lines, args.append)


if __name__ == "__main__":
    main()
