"""The Normal Map and Bump scenes the export and Cycles tests share: a ridged normal image
and its height, and a grid whose Principled Normal is a Normal Map or Bump node."""

from __future__ import annotations

import bpy
import numpy as np

from prt_relight.bench import scenes


def ridges(res=128, amp=0.08, k=4):
    """A tangent-space normal image of ridges along v (h = amp sin(2 pi k u) on a unit
    UV square), top row first, and the height itself."""
    u = (np.arange(res) + 0.5) / res
    hu = amp * 2 * np.pi * k * np.cos(2 * np.pi * k * u)
    n = np.stack([-hu, np.zeros(res), np.ones(res)], axis=1)
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    img = np.ones((res, res, 3), np.float32)
    img[:] = 0.5 * (n[None, :, :] + 1.0)
    h = np.repeat((amp * np.sin(2 * np.pi * k * u))[None, :, None], 3, axis=2)
    return img, np.ascontiguousarray(np.broadcast_to(h, (res, res, 3)), np.float32)


def mapped_plane(kind, size=2.0, **node_inputs):
    """A grid with a Principled material whose Normal is a Normal Map or Bump node on a
    generated Non-Color image (None: no link, drawn flat)."""
    plane = scenes.add_ground(size=size, cuts=8)
    mat = bpy.data.materials.new("mapped")
    nt = mat.node_tree
    bsdf = nt.nodes["Principled BSDF"]
    normal_img, height = ridges()
    if kind is not None:
        tex = nt.nodes.new("ShaderNodeTexImage")
        tex.image = scenes.float_image(kind, normal_img if kind == "NORMAL_MAP" else height)
        node = nt.nodes.new("ShaderNodeNormalMap" if kind == "NORMAL_MAP" else "ShaderNodeBump")
        for key, value in node_inputs.items():
            node.inputs[key].default_value = value
        nt.links.new(tex.outputs["Color"], node.inputs["Color" if kind == "NORMAL_MAP"
                                                       else "Height"])
        nt.links.new(node.outputs["Normal"], bsdf.inputs["Normal"])
    plane.data.materials.append(mat)
    return plane
