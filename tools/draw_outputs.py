# SPDX-License-Identifier: GPL-3.0-or-later
"""Draw docs/images/outputs/, the pictures and figures of the results Blender users reach
for (issue 33): light group passes rebalanced, a baked lightmap in EEVEE, the mesh
attributes and what they cost in the .blend.

    .venv/bin/python tools/draw_outputs.py --out /tmp/outputs [--resolution 320x240]

(then copy its PNGs into docs/images/outputs/)

Writes groups.png (Combined | World | its sun | the lamp | the groups rebalanced | a new
F12 with the lights changed so), lightmap.png (F12 | EEVEE with the baked radiance
lightmap on Emission materials | |difference| × 10), ao_cycles.png (the PRT AO attribute
through Cycles' Attribute node) and report.txt (errors, the attributes as the Spreadsheet
lists them, .blend bytes with and without them).
"""

from __future__ import annotations

import argparse
import pathlib
import sys

import numpy as np

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parents[1] / "bench"))
import scenes  # noqa: E402
from prt_relight.core.report.metrics import rel_l2  # noqa: E402  (importing scenes registers prt_relight)

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parents[1]))
from tests.addon.frame import test_baking, test_passes  # noqa: E402  (the cases' scenes)


def _png(path, rows):
    """Panels side by side, linear → x / (1 + x) (Reinhard), gamma 2.2, 8-bit PNG."""
    import OpenImageIO as oiio
    strip = np.concatenate([np.asarray(p, np.float32)[..., :3] for p in rows], axis=1)
    px = np.clip(strip / (1.0 + np.maximum(strip, 0.0)), 0.0, 1.0) ** (1.0 / 2.2)
    out = oiio.ImageBuf(oiio.ImageSpec(px.shape[1], px.shape[0], 3, oiio.UINT8))
    out.set_pixels(oiio.ROI(), (px * 255 + 0.5).astype(np.uint8))
    out.write(str(path))


def light_groups(out: pathlib.Path, size, lines: list):
    import bpy
    scene = test_passes._scene(0)
    scenes.set_resolution(*size)
    scene.prt.light_group_passes = True
    got = test_passes.render_layers(out / "groups.exr")
    world, lamp = 0.5, 4.0                   # the rebalance: World and its sun ×0.5, lamp ×4
    sun = next(k for k in got if k.startswith("Combined_World_Source"))
    mixed = (world * (got["Combined_World"] + got[sun]) + lamp * got["Combined_Key_Lamp"]
             + got["Combined_Rim"])
    scene.world.node_tree.nodes["Background"].inputs["Strength"].default_value *= world
    bpy.data.objects["Key Lamp"].data.energy *= lamp
    again = test_passes.render_layers(out / "again.exr")["Combined"]
    _png(out / "groups.png", [got["Combined"], got["Combined_World"], got[sun],
                              got["Combined_Key_Lamp"], mixed, again])
    lines.append(f"light groups: {', '.join(k for k in got if k.startswith('Combined_'))}")
    lines.append(f"rebalanced passes (World ×{world}, Key Lamp ×{lamp}) against a new F12 with "
                 f"those lights: rel-L2 {rel_l2(mixed, again[..., :3], np.ones(size[::-1], bool)):.1e}")


def lightmap(out: pathlib.Path, size, lines: list):
    import bpy
    scene = test_baking._scene()
    scenes.set_resolution(*size)
    ours = scenes.render_exr(out / "ours.exr")
    test_baking._select("Ground", "Suzanne")
    bpy.ops.prt.bake(quantity="RADIANCE", target="IMAGE", size=1024, margin=8)
    for name in ("Ground", "Suzanne"):
        test_baking._emission_from(bpy.data.objects[name],
                                   bpy.data.images[f"PRT Radiance {name}"])
    scene.world.node_tree.nodes["Background"].inputs["Strength"].default_value = 0.0
    scene.eevee.taa_render_samples = 64
    eevee = scenes.render_exr(out / "eevee.exr", "BLENDER_EEVEE")
    mask = test_passes.interior(ours[..., 3] > 0.999)
    _png(out / "lightmap.png", [ours, eevee, 10 * np.abs(eevee - ours)])
    lines.append(f"baked radiance lightmap (EEVEE, 1024² maps) against F12: rel-L2 "
                 f"{rel_l2(eevee, ours, mask):.4f}")


def attributes(out: pathlib.Path, size, lines: list):
    import bpy
    sizes = {}
    for write in (False, True):
        scenes.reset()
        scenes.add_world("sunset")
        scenes.add_ground(size=6.0, cuts=96)
        scenes.add_suzanne(subdiv=0, location=(0.0, 0.0, 1.0))
        scenes.add_camera(location=(0.0, -6.0, 3.0), rotation=(1.15, 0.0, 0.0), resolution=None)
        scenes.set_resolution(*size)
        bpy.context.scene.prt.write_attributes = write
        bpy.ops.prt.precompute()
        path = out / f"attributes_{int(write)}.blend"
        bpy.ops.wm.save_as_mainfile(filepath=str(path), compress=False)
        sizes[write] = path.stat().st_size
    mesh = bpy.data.objects["Ground"].data
    corners = len(mesh.loops)
    lines.append("Spreadsheet, Ground, Face Corner domain: " + ", ".join(
        f"{a.name} ({a.data_type})" for a in mesh.attributes if a.name.startswith("PRT ")))
    stored = sum(len(bytes(e["blob"])) for ob in bpy.data.objects if "prt_store" in ob
                 for e in ob["prt_store"].values())
    lines.append(f".blend (uncompressed): {sizes[False]} bytes without the attributes, "
                 f"{sizes[True]} with them (+{sizes[True] - sizes[False]} for "
                 f"{sum(len(o.data.loops) for o in bpy.data.objects if o.type == 'MESH')} "
                 f"corners); the compressed store: {stored} bytes; Ground {corners} corners")
    mat = bpy.data.materials.new("AO")
    nt = mat.node_tree
    nt.nodes.clear()
    attr = nt.nodes.new("ShaderNodeAttribute")
    attr.attribute_name = "PRT AO"
    emit = nt.nodes.new("ShaderNodeEmission")
    nt.links.new(attr.outputs["Fac"], emit.inputs["Color"])
    nt.links.new(emit.outputs["Emission"], nt.nodes.new("ShaderNodeOutputMaterial").inputs[0])
    for ob in bpy.data.objects:
        if ob.type == "MESH":
            ob.data.materials.clear()
            ob.data.materials.append(mat)
    bpy.context.scene.world.node_tree.nodes["Background"].inputs["Strength"].default_value = 0
    _png(out / "ao_cycles.png", [scenes.render_exr(out / "ao.exr", "CYCLES", samples=32,
                                                   seed=1)])


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--out", required=True, type=pathlib.Path)
    p.add_argument("--resolution", default="320x240")
    args = p.parse_args(argv)
    size = tuple(int(v) for v in args.resolution.lower().split("x"))
    args.out.mkdir(parents=True, exist_ok=True)
    scenes.load_addon()
    lines = []
    light_groups(args.out, size, lines)
    lightmap(args.out, size, lines)
    attributes(args.out, size, lines)
    (args.out / "report.txt").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
