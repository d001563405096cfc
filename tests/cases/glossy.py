"""Glossy objects the SSDF_SG, sharp-lobe and Cycles tests share: a mirror ball, and a
Principled object whose Roughness and Normal Map read images."""

from __future__ import annotations

import bpy
import numpy as np

from prt_relight.bench import scenes


def mirror_ball(kind="glossy", roughness=0.0, hdri="courtyard", size=(64, 48), ground=True):
    scenes.reset()
    scenes.add_world(hdri)
    if ground:
        scenes.add_ground(size=6.0, cuts=24)
    bpy.ops.mesh.primitive_uv_sphere_add(location=(0.0, 0.0, 1.0), radius=0.8, segments=48,
                                         ring_count=24)
    bpy.ops.object.shade_smooth()
    ball = bpy.context.object
    if kind == "glossy":
        mat = scenes.bsdf_material("Mirror", "ShaderNodeBsdfGlossy", Roughness=roughness)
    else:
        mat = scenes.bsdf_material("Metal", "ShaderNodeBsdfPrincipled", Roughness=roughness,
                               Metallic=1.0)
    ball.data.materials.append(mat)
    scenes.add_camera(location=(0.0, -5.0, 2.2), rotation=(1.3, 0.0, 0.0), resolution=None)
    scenes.set_resolution(*size)
    return ball


def glossy_object(metallic, shape="SUZANNE"):
    if shape == "SUZANNE":
        bpy.ops.mesh.primitive_monkey_add(size=2.0)
        mod = bpy.context.object.modifiers.new("subdivide", "SUBSURF")
        mod.levels = 2
        bpy.ops.object.modifier_apply(modifier=mod.name)
    else:
        bpy.ops.mesh.primitive_uv_sphere_add(segments=96, ring_count=48, radius=1.0)
    ob = bpy.context.object
    bpy.ops.object.shade_smooth()
    mat = bpy.data.materials.new("textured glossy")
    nt = mat.node_tree
    bsdf = nt.nodes["Principled BSDF"]
    bsdf.inputs["Base Color"].default_value = (0.8, 0.5, 0.3, 1.0)
    bsdf.inputs["Metallic"].default_value = metallic
    rough, normal = roughness_and_normal_images()
    tex = nt.nodes.new("ShaderNodeTexImage")
    tex.image = scenes.float_image("roughness", rough)
    nt.links.new(tex.outputs["Color"], bsdf.inputs["Roughness"])
    tex = nt.nodes.new("ShaderNodeTexImage")
    tex.image = scenes.float_image("normal", normal)
    node = nt.nodes.new("ShaderNodeNormalMap")
    nt.links.new(tex.outputs["Color"], node.inputs["Color"])
    nt.links.new(node.outputs["Normal"], bsdf.inputs["Normal"])
    ob.data.materials.append(mat)
    return bsdf


def roughness_and_normal_images(res=256):
    """(roughness, tangent-space normal) images, top row first: roughness in smooth blobs
    between 0.2 and 0.7, normals of an egg-crate relief (slopes up to 0.35, 19 degrees)."""
    u = (np.arange(res) + 0.5) / res
    U, V = np.meshgrid(u, u[::-1])
    r = 0.45 + 0.25 * np.sin(2 * np.pi * (2 * U + 0.3)) * np.cos(3 * np.pi * V)
    su = 0.35 * np.cos(16 * np.pi * U) * np.sin(8 * np.pi * V)
    sv = 0.35 * np.sin(16 * np.pi * U) * np.cos(8 * np.pi * V)
    n = np.stack([-su, -sv, np.ones_like(U)], -1)
    n /= np.linalg.norm(n, axis=-1, keepdims=True)
    return np.repeat(r[..., None], 3, axis=2).astype(np.float32), (0.5 * (n + 1)).astype(np.float32)


#: the SSDF_SG Suzanne's frame size
SSDF_SG_SIZE = (48, 36)


def ssdf_sg_suzanne(principled=False):
    """Suzanne (Beckmann Glossy 0.3, or a GGX Principled metal) on a coarse ground under a
    turned 'sunset', SSDF_SG at 32^2, a 48 x 36 camera: the SSDF_SG add-on and GPU tests'
    scene."""
    scenes.reset()
    scenes.add_world("sunset", rotation_z=0.4)
    scenes.add_ground(size=6.0, cuts=12)
    suz = scenes.add_suzanne(subdiv=1, location=(0.0, 0.0, 1.0))
    if principled:              # GGX: the fitted view-slice lobes (ggx_specular)
        suz.data.materials.append(scenes.bsdf_material(
            "Metal", "ShaderNodeBsdfPrincipled", Metallic=1.0, Roughness=0.45,
            **{"Base Color": (0.9, 0.7, 0.5, 1.0)}))
    else:
        suz.data.materials.append(scenes.bsdf_material("Glossy", "ShaderNodeBsdfGlossy",
                                                       distribution="BECKMANN", Roughness=0.3))
    scenes.add_camera(location=(0.0, -6.0, 3.0), rotation=(1.15, 0.0, 0.0), resolution=None)
    scenes.set_resolution(*SSDF_SG_SIZE)
    scene = bpy.context.scene
    scene.prt.method = "SSDF_SG"
    scene.prt.resolution = "32"
    return scene

