"""Draw docs/images/data_flow.svg, the data-flow picture of docs/architecture.md.

    .venv/bin/python tools/draw_data_flow.py [--out docs/images/data_flow.svg]

Plain SVG written by hand (no plotting library): boxes, wrapped text and arrows.  Edit the
BOXES and ARROWS below and run it again when the pipeline changes.
"""

from __future__ import annotations

import argparse
import pathlib
import textwrap
from xml.sax.saxutils import escape

ROOT = pathlib.Path(__file__).resolve().parents[1]

FONT = 12.0
CHAR_W = 6.6          # mean advance of the sans-serif font at FONT px, for wrapping
LINE_H = 15.0
PAD = 8.0

MAIN_X, MAIN_W = 20.0, 540.0
SIDE_X, SIDE_W = 710.0, 300.0

# (key, column x, width, title, body, fill): the main pipeline top to bottom, then the side
# column (the world's compact sources and the per-pixel passes every method gets)
BOXES = [
    ("scene", MAIN_X, MAIN_W, "Blender scene (bpy)",
     "evaluated meshes, curves, text · materials (node trees) · World: Environment Texture "
     "through a Mapping node · sun / point / spot lamps · camera", "#e8eef8"),
    ("arrays", MAIN_X, MAIN_W, "core arrays (numpy) — addon/blender/scene_export.py, texture_export.py",
     "core.scene.mesh: shading points, normals, triangles, closed sides · core.shading.brdf materials "
     "(Cycles' microfacet lobes), textured colour inputs · the world image read in its colour "
     "space, resampled exactly to the cubemap (core.sphere.envmap, core.sphere.resample: 6N² texels with "
     "solid angles and mean light directions)", "#eef6ea"),
    ("precompute", MAIN_X, MAIN_W, "precompute — addon/blender/precompute.py",
     "gather (main thread, reads bpy) → run (worker thread, ESC cancels): core.scene.visibility "
     "traces Embree rays, one bit per cubemap texel and shading point; the active method's "
     "derive (BLOCKS run-length varints, RSL distance tables + clustered PCA, SSDF_SG signed "
     "distances + PCA) → commit (main thread, the only step that writes)", "#fdf3e3"),
    ("blobs", MAIN_X, MAIN_W, "stored blobs — addon/blender/storage.py, core/common/codec.py",
     "ob['prt_store'][name] = versioned PRTB blob (JSON header + zlib arrays): visibility, "
     "blocks, rsl, ssdf_sg; the object's record ob.prt (run, point count, fingerprint); "
     "saved with the .blend, carried through rename / duplicate / undo / append", "#fdf3e3"),
    ("state", MAIN_X, MAIN_W, "frame state — addon/frame/state.py",
     "FrameState.sync: blobs decoded once (cached by uid), stale and newer-layout checks, the "
     "world's lighting per image and rotation, each method's sync", "#f3ecf8"),
    ("method", MAIN_X, MAIN_W, "method — addon/methods/ (numerics in core/)",
     "shade → per-corner radiance: REFERENCE, SH, WAVELET, RSL, BLOCKS, AUTO (per object the "
     "cheapest within the error target) · draw_objects → per-pixel GPU draws: SSDF_SG",
     "#f3ecf8"),
    ("gpu", MAIN_X, MAIN_W, "GPU textures and batches — addon/gpu/drawing.py",
     "per-corner radiance as vertex attributes (white / black split for textured colour) · "
     "float textures: PCA SSDFs, visibility bits, shadow maps, environment mips, albedo "
     "images", "#e8f4f6"),
    ("shaders", MAIN_X, MAIN_W, "shaders — shaders/{lib,passes,methods}, addon/gpu/shaders.py",
     "passes/surface(_tex): Gouraud radiance × per-pixel colour · methods/ssdf_sg_*: eq. 39 / 41 "
     "per pixel · passes/lights_*: compact sources and lamps · passes/sharp_lobe_*: mirror-like "
     "lobes · passes/background_*: the world as Cycles shows it", "#e8f4f6"),
    ("pixels", MAIN_X, MAIN_W, "pixels — addon/frame/engine.py",
     "Rendered viewport, or F12 drawn at s× resolution and resolved with Cycles' "
     "Blackman-Harris filter (core.shading.pixel_filter) → linear RGBA render result", "#e8eef8"),
    ("sources", SIDE_X, SIDE_W, "compact sources — core/sphere/sources.py",
     "the World's few small bright regions (a sun, softboxes) split off the cubemap; the "
     "methods shade the smooth rest (scene.prt.light_sources = 0: the whole World)",
     "#eef6ea"),
    ("passes", SIDE_X, SIDE_W, "per-pixel passes, every method",
     "addon/gpu/lights.py: compact sources and lamps, shadow maps with PCSS · addon/gpu/sharp.py: "
     "lobes narrower than a texel (NDF samples, filtered environment, stored visibility) · "
     "textured colour: texture × (white − black) radiance", "#e8f4f6"),
]

# (from, to, label): main-column arrows go bottom → top edge; side arrows as noted
ARROWS = [
    ("scene", "arrays", ""), ("arrays", "precompute", ""), ("precompute", "blobs", ""),
    ("blobs", "state", ".blend reopened: no recompute"), ("state", "method", ""),
    ("method", "gpu", ""), ("gpu", "shaders", ""), ("shaders", "pixels", ""),
    ("arrays", "sources", "world split"), ("sources", "passes", ""),
    ("state", "passes", "visibility, materials"), ("passes", "shaders", "added draws"),
]

GAP = 26.0          # vertical space between main boxes (arrows)


def _lines(box):
    _, _, w, title, body, _ = box
    return [title], textwrap.wrap(body, int((w - 2 * PAD) / CHAR_W))


def _height(box) -> float:
    title, body = _lines(box)
    return 2 * PAD + LINE_H * (len(title) + len(body)) + 4.0


def layout():
    """Box geometry {key: (x, y, w, h)}: the main column stacked, the side boxes beside
    the main boxes they are drawn from / into."""
    geo, y = {}, 20.0
    for box in BOXES:
        if box[1] == MAIN_X:
            h = _height(box)
            geo[box[0]] = (box[1], y, box[2], h)
            y += h + GAP
    by_key = {b[0]: b for b in BOXES}
    _, ya, _, ha = geo["arrays"]
    geo["sources"] = (SIDE_X, ya + 10.0, SIDE_W, _height(by_key["sources"]))
    _, ys, _, _ = geo["state"]
    geo["passes"] = (SIDE_X, ys, SIDE_W, _height(by_key["passes"]))
    return geo, y


def _arrow(x1, y1, x2, y2, label=""):
    out = [f'<line x1="{x1:.1f}" y1="{y1:.1f}" x2="{x2:.1f}" y2="{y2:.1f}" '
           'stroke="#333" stroke-width="1.4" marker-end="url(#head)"/>']
    if label:
        mx, my = (x1 + x2) / 2, (y1 + y2) / 2
        lx, ly = (mx + 6, my + 4) if x1 == x2 else (min(x1, x2) + 8, my - 6)  # beside / above
        out.append(f'<text x="{lx:.1f}" y="{ly:.1f}" font-size="{FONT - 1:.0f}" '
                   f'fill="#555" font-style="italic">{escape(label)}</text>')
    return out


def svg() -> str:
    geo, height = layout()
    width = SIDE_X + SIDE_W + 20.0
    out = [f'<svg xmlns="http://www.w3.org/2000/svg" width="{width:.0f}" '
           f'height="{height:.0f}" viewBox="0 0 {width:.0f} {height:.0f}" '
           f'font-family="DejaVu Sans, Helvetica, Arial, sans-serif" font-size="{FONT:.0f}">',
           '<defs><marker id="head" viewBox="0 0 10 10" refX="10" refY="5" markerWidth="7" '
           'markerHeight="7" orient="auto-start-reverse"><path d="M0,0 L10,5 L0,10 z" '
           'fill="#333"/></marker></defs>',
           f'<rect width="{width:.0f}" height="{height:.0f}" fill="white"/>']
    for box in BOXES:
        key, _, _, _, _, fill = box
        x, y, w, h = geo[key]
        out.append(f'<rect x="{x:.1f}" y="{y:.1f}" width="{w:.1f}" height="{h:.1f}" rx="6" '
                   f'fill="{fill}" stroke="#444" stroke-width="1"/>')
        title, body = _lines(box)
        ty = y + PAD + FONT
        for line in title:
            out.append(f'<text x="{x + PAD:.1f}" y="{ty:.1f}" font-weight="bold">'
                       f'{escape(line)}</text>')
            ty += LINE_H + 2.0
        for line in body:
            out.append(f'<text x="{x + PAD:.1f}" y="{ty:.1f}">{escape(line)}</text>')
            ty += LINE_H
    for a, b, label in ARROWS:
        xa, ya, wa, ha = geo[a]
        xb, yb, wb, hb = geo[b]
        if xa == xb:                              # same column: bottom edge to top edge
            x = xa + min(wa, wb) / 2 if xa == MAIN_X else xa + wa / 2
            out += _arrow(x, ya + ha, x, yb, label)
        elif xa < xb:                             # main → side: right edge to left edge
            y = max(ya, yb) + 18.0
            out += _arrow(xa + wa, y, xb, y, "")
            if label:
                out.append(f'<text x="{xa + wa + 8:.1f}" y="{y - 6:.1f}" '
                           f'font-size="{FONT - 1:.0f}" fill="#555" font-style="italic">'
                           f'{escape(label)}</text>')
        else:                                     # side → main: left edge to right edge
            y = yb + hb / 2
            out.append(f'<polyline points="{xa + wa / 2:.1f},{ya + ha:.1f} {xa + wa / 2:.1f},'
                       f'{y:.1f}" fill="none" stroke="#333" stroke-width="1.4"/>')
            out += _arrow(xa + wa / 2, y, xb + wb, y, label)
    out.append("</svg>")
    return "\n".join(out) + "\n"


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--out", default=str(ROOT / "docs" / "images" / "data_flow.svg"))
    args = p.parse_args(argv)
    path = pathlib.Path(args.out)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(svg(), encoding="utf-8")
    print(path)


if __name__ == "__main__":
    main()
