"""Textured scenes the texture tests share (add-on, GLSL and Cycles): float images, an
Image Texture material, a plane seen from above under a white world, a Principled material
whose Roughness is an image."""

from __future__ import annotations

import bpy
import numpy as np

from prt_relight.bench import scenes


def texture_image(name, rgba, colorspace="Non-Color"):
    h, w = rgba.shape[:2]
    img = bpy.data.images.new(name, w, h, alpha=True, float_buffer=True)
    img.colorspace_settings.name = colorspace         # first: it regenerates the buffer
    img.pixels.foreach_set(np.ascontiguousarray(rgba, np.float32).reshape(-1))
    img.pack()
    return img


def textured_material(name, img, interpolation="Linear", extension="REPEAT", uv_map=None,
              mapping=None, node="ShaderNodeBsdfDiffuse"):
    mat = bpy.data.materials.new(name)
    nt = mat.node_tree
    for n in list(nt.nodes):
        if n.type == "BSDF_PRINCIPLED":
            nt.nodes.remove(n)
    bsdf = nt.nodes.new(node)
    nt.links.new(bsdf.outputs[0], next(n for n in nt.nodes
                                      if n.type == "OUTPUT_MATERIAL").inputs["Surface"])
    tex = nt.nodes.new("ShaderNodeTexImage")
    tex.image, tex.interpolation, tex.extension = img, interpolation, extension
    colour = "Color" if node == "ShaderNodeBsdfDiffuse" else "Base Color"
    nt.links.new(tex.outputs["Color"], bsdf.inputs[colour])
    vec = tex.inputs["Vector"]
    if mapping is not None:
        m = nt.nodes.new("ShaderNodeMapping")
        m.inputs["Location"].default_value = mapping
        nt.links.new(m.outputs["Vector"], vec)
        vec = m.inputs["Vector"]
    if uv_map is not None:
        uvn = nt.nodes.new("ShaderNodeUVMap")
        uvn.uv_map = uv_map
        nt.links.new(uvn.outputs["UV"], vec)
    return mat


def white_world():
    scenes.add_world(image=scenes.float_image("white", np.ones((8, 16, 3), np.float32)))


def plane_from_above(size=2.0, pixels=16):
    bpy.ops.mesh.primitive_plane_add(size=size)
    plane = bpy.context.object
    cam = scenes.add_camera(location=(0.0, 0.0, 5.0), rotation=(0.0, 0.0, 0.0), resolution=None)
    cam.data.type = "ORTHO"
    cam.data.ortho_scale = size
    scenes.set_resolution(pixels, pixels)
    scene = bpy.context.scene
    scene.prt.supersampling = 1
    scene.render.filter_size = 0.0
    return plane


def rough_principled(name, cells, **inputs):
    """(material, its Principled node) whose Roughness is the Non-Color image ``cells``
    read with Closest interpolation."""
    mat = scenes.bsdf_material(name, "ShaderNodeBsdfPrincipled", **inputs)
    tex = mat.node_tree.nodes.new("ShaderNodeTexImage")
    tex.image, tex.interpolation = texture_image("cells", cells), "Closest"
    bsdf = next(nd for nd in mat.node_tree.nodes if nd.type == "BSDF_PRINCIPLED")
    mat.node_tree.links.new(tex.outputs["Color"], bsdf.inputs["Roughness"])
    return mat, bsdf
