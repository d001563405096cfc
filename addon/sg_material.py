"""SG reflectance settings per material (paper 003 §4) and the exports the SSDF_SG method needs.

Blender side only; the numerics are in ``core/sg_brdf.py`` / ``core/sg_lighting.py``.

* ``material.prt_sg`` (:class:`PRTSGMaterialSettings`): "Use Blender Material"
  (default on: the node tree is mapped by ``core.sg_brdf.sg_material_from_brdf``),
  otherwise the SG model, roughness (Blender roughness r, slope a = r^2),
  anisotropic parameters, Fresnel mode/IOR and colour overrides.  Every slider
  only redraws the viewports (no recompute: the BRDF is evaluated per pixel).
* Panel "PRT Reflectance" in Material properties for the PRT_RELIGHT engine.

Functions for the method module (``addon/methods/ssdf_sg.py``):

* :func:`export_sg_material(blender_material, warnings=None) -> core.sg_brdf.SGMaterial`
* :func:`export_material_textures(blender_material) -> dict` -- image textures wired
  straight into the Principled "Base Color" / "Roughness" inputs and the image of a
  Normal Map node wired into "Normal": ``{"base_color": (pixels (H, W, 4) linear,
  uv_map name), "roughness": ..., "normal": (pixels, uv_map, strength)}`` (only the
  keys present).  Pixels are Blender's order (row 0 at v = 0); sample them per
  shading point with ``core.sg_brdf.sample_texture(pixels, uv)``, make the per-point
  material with ``core.sg_brdf.with_textures(material, base_color=..., roughness=...)``
  (roughness r -> slope ``a = max(r^2, ALPHA_MIN)``) and turn normal-map texels into
  normals with ``core.sg_brdf.tangent_space_normals``.
* :func:`mesh_uv_tangents(ob_eval, uv_map=None) -> (uv (C, 2), tangents (C, 3) world,
  bitangent_sign (C,))` per face corner (``mesh.calc_tangents``), or None without UVs.
* :func:`export_lamps(depsgraph) -> list[core.sg_lighting.Lamp]` (point, spot, sun; area
  lights are reported in ``warnings`` and skipped).
"""

from __future__ import annotations

import numpy as np

import bpy
from bpy.props import (BoolProperty, EnumProperty, FloatProperty, FloatVectorProperty,
                       PointerProperty)

from ..core import sg_brdf, sg_lighting
from . import scene_export
from .runtime import redraw_viewports

MODEL_ITEMS = [
    ("COOK_TORRANCE", "Cook-Torrance", "Beckmann NDF, Smith shadowing (eq. 10-12): one SG lobe"),
    ("BLINN_PHONG", "Blinn-Phong", "Exponent 2/a^2 - 2: one SG lobe"),
    ("WARD", "Ward", "Isotropic Ward: one SG lobe"),
    ("WARD_ANISO", "Ward Anisotropic", "Anisotropic Ward (alpha x, alpha y): several SG lobes"),
    ("ASHIKHMIN_SHIRLEY", "Ashikhmin-Shirley", "Anisotropic Phong exponents nu, nv: several SG lobes"),
]
FRESNEL_ITEMS = [
    ("NONE", "None", "F = 1: the specular colour is the reflectance (Cycles Glossy BSDF)"),
    ("SCHLICK", "Schlick", "Schlick's approximation with F0 = specular colour"),
    ("DIELECTRIC", "Dielectric", "Cook-Torrance Fresnel of eq. 14 with the IOR, times the specular colour"),
]


class PRTSGMaterialSettings(bpy.types.PropertyGroup):
    use_blender_material: BoolProperty(
        name="Use Blender Material", default=True, update=redraw_viewports,
        description="Map the material's node tree (Diffuse/Glossy/Principled BSDF) to "
                    "Cook-Torrance; off: use the settings below")
    model: EnumProperty(name="Model", items=MODEL_ITEMS, default="COOK_TORRANCE",
                        update=redraw_viewports)
    roughness: FloatProperty(name="Roughness", default=0.3, min=0.0, max=1.0,
                             subtype="FACTOR", update=redraw_viewports,
                             description="Blender roughness r; the microfacet slope is r squared")
    alpha_x: FloatProperty(name="Alpha X", default=0.3, min=sg_brdf.ALPHA_MIN, max=1.0,
                           update=redraw_viewports, description="Ward slope along the tangent")
    alpha_y: FloatProperty(name="Alpha Y", default=0.1, min=sg_brdf.ALPHA_MIN, max=1.0,
                           update=redraw_viewports, description="Ward slope along the bitangent")
    nu: FloatProperty(name="nu", default=75.0, min=1.0, max=10000.0, update=redraw_viewports,
                      description="Ashikhmin-Shirley exponent along the tangent")
    nv: FloatProperty(name="nv", default=1200.0, min=1.0, max=10000.0, update=redraw_viewports,
                      description="Ashikhmin-Shirley exponent along the bitangent")
    fresnel: EnumProperty(name="Fresnel", items=FRESNEL_ITEMS, default="DIELECTRIC",
                          update=redraw_viewports)
    ior: FloatProperty(name="IOR", default=1.5, min=1.0, max=5.0, update=redraw_viewports)
    diffuse_color: FloatVectorProperty(name="Diffuse", subtype="COLOR", size=3, min=0.0, max=1.0,
                                       default=(0.5, 0.5, 0.5), update=redraw_viewports)
    specular_color: FloatVectorProperty(name="Specular", subtype="COLOR", size=3, min=0.0,
                                        max=1.0, default=(1.0, 1.0, 1.0),
                                        update=redraw_viewports)


class PRT_PT_sg_material(bpy.types.Panel):
    bl_label = "PRT Reflectance"
    bl_space_type = "PROPERTIES"
    bl_region_type = "WINDOW"
    bl_context = "material"
    COMPAT_ENGINES = {"PRT_RELIGHT"}

    @classmethod
    def poll(cls, context):
        return context.engine in cls.COMPAT_ENGINES and context.material is not None

    def draw(self, context):
        s = context.material.prt_sg
        col = self.layout.column()
        col.prop(s, "use_blender_material")
        if s.use_blender_material:
            col.label(text="Drawn as Cook-Torrance (Beckmann) from the node tree", icon="INFO")
            return
        col.prop(s, "model")
        if s.model == "WARD_ANISO":
            col.prop(s, "alpha_x")
            col.prop(s, "alpha_y")
        elif s.model == "ASHIKHMIN_SHIRLEY":
            col.prop(s, "nu")
            col.prop(s, "nv")
        else:
            col.prop(s, "roughness")
        col.prop(s, "fresnel")
        if s.fresnel == "DIELECTRIC":
            col.prop(s, "ior")
        col.prop(s, "diffuse_color")
        col.prop(s, "specular_color")


def uses_blender_material(blender_material) -> bool:
    """Whether SSDF_SG draws the material's node tree (not its own SG model)."""
    s = getattr(blender_material, "prt_sg", None) if blender_material is not None else None
    return s is None or s.use_blender_material


def export_sg_material(blender_material, warnings: list | None = None) -> sg_brdf.SGMaterial:
    """The material's SG reflectance (``None``: Cycles' default surface)."""
    warnings = [] if warnings is None else warnings
    s = getattr(blender_material, "prt_sg", None) if blender_material is not None else None
    if uses_blender_material(blender_material):
        return sg_brdf.sg_material_from_brdf(scene_export.export_material(blender_material, warnings))
    a = max(float(s.roughness) ** 2, sg_brdf.ALPHA_MIN)
    return sg_brdf.SGMaterial(model=s.model, diffuse=tuple(s.diffuse_color),
                              specular=tuple(s.specular_color), roughness=a,
                              alpha_x=s.alpha_x, alpha_y=s.alpha_y, nu=s.nu, nv=s.nv,
                              fresnel=s.fresnel, ior=s.ior)


# --------------------------------------------------------------------------- textures

def _srgb_to_linear(c):
    return np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)


def _image_array(image) -> np.ndarray | None:
    """(H, W, 4) float32 of a Blender image, row 0 at v = 0, colour data linearised."""
    w, h = image.size
    if (w == 0 or h == 0) and not scene_export._try_load(image):
        return None
    w, h = image.size
    if w == 0 or h == 0:
        return None
    buf = np.empty(w * h * image.channels, dtype=np.float32)
    image.pixels.foreach_get(buf)
    px = buf.reshape(h, w, image.channels)
    if image.channels < 4:
        px = np.concatenate([px, np.ones((h, w, 4 - image.channels), np.float32)], axis=2)
    if image.colorspace_settings.name == "sRGB" and not image.is_float:
        px[..., :3] = _srgb_to_linear(px[..., :3])
    return px


def _linked_image(socket):
    """(image node, uv map name) when an Image Texture feeds ``socket`` directly."""
    if socket is None or not socket.is_linked:
        return None
    node = socket.links[0].from_node
    if node.type != "TEX_IMAGE" or node.image is None:
        return None
    uv = ""
    vec = node.inputs.get("Vector")
    if vec is not None and vec.is_linked and vec.links[0].from_node.type == "UVMAP":
        uv = vec.links[0].from_node.uv_map
    return node, uv


def export_material_textures(blender_material) -> dict:
    """Image textures of the Principled inputs (module docstring)."""
    out = {}
    if blender_material is None:
        return out
    node = scene_export._surface_node(blender_material)
    if node is None or node.type != "BSDF_PRINCIPLED":
        return out
    for key, name in (("base_color", "Base Color"), ("roughness", "Roughness")):
        hit = _linked_image(node.inputs.get(name))
        if hit:
            px = _image_array(hit[0].image)
            if px is not None:
                out[key] = (px, hit[1])
    nsock = node.inputs.get("Normal")
    if nsock is not None and nsock.is_linked and nsock.links[0].from_node.type == "NORMAL_MAP":
        nm = nsock.links[0].from_node
        hit = _linked_image(nm.inputs.get("Color"))
        if hit and nm.space == "TANGENT":
            px = _image_array(hit[0].image)
            strength = float(nm.inputs["Strength"].default_value)
            if px is not None:
                out["normal"] = (px, nm.uv_map or hit[1], strength)
    return out


def mesh_uv_tangents(ob_eval, uv_map: str | None = None):
    """Per-corner UVs, world tangents and bitangent signs (``mesh.calc_tangents``)."""
    mesh = ob_eval.to_mesh()
    try:
        layers = mesh.uv_layers
        if not len(layers):
            return None
        layer = layers.get(uv_map) if uv_map else layers.active
        layer = layer or layers.active
        nc = len(mesh.loops)
        uv = np.empty(nc * 2, dtype=np.float32)
        layer.data.foreach_get("uv", uv)
        try:
            mesh.calc_tangents(uvmap=layer.name)
        except RuntimeError:
            return uv.reshape(-1, 2), None, None
        tan = np.empty(nc * 3, dtype=np.float32)
        mesh.loops.foreach_get("tangent", tan)
        sign = np.empty(nc, dtype=np.float32)
        mesh.loops.foreach_get("bitangent_sign", sign)
    finally:
        ob_eval.to_mesh_clear()
    M = np.array(ob_eval.matrix_world, dtype=np.float64)[:3, :3]
    t = tan.reshape(-1, 3).astype(np.float64) @ M.T
    t /= np.maximum(np.linalg.norm(t, axis=1, keepdims=True), 1e-30)
    if np.linalg.det(M) < 0:
        sign = -sign
    return uv.reshape(-1, 2).astype(np.float64), t, sign.astype(np.float64)


# --------------------------------------------------------------------------- lamps

def export_lamps(depsgraph, warnings: list | None = None) -> list:
    """Visible point/spot/sun lights as :class:`core.sg_lighting.Lamp` (eq. 32-33)."""
    warnings = [] if warnings is None else warnings
    lamps = []
    for inst in depsgraph.object_instances:
        ob = inst.object
        if ob.type != "LIGHT":
            continue
        light = ob.data
        M = np.array(inst.matrix_world, dtype=np.float64)
        direction = -M[:3, 2]
        color = np.asarray(tuple(light.color), dtype=np.float64) * float(light.energy)
        if light.type == "SUN":
            lamps.append(sg_lighting.Lamp("SUN", color=color, direction=direction,
                                          angle=float(light.angle)))
        elif light.type in ("POINT", "SPOT"):
            kw = dict(color=color, position=M[:3, 3], direction=direction,
                      radius=float(light.shadow_soft_size))
            if light.type == "SPOT":
                kw.update(spot_size=float(light.spot_size), spot_blend=float(light.spot_blend))
            lamps.append(sg_lighting.Lamp(light.type, **kw))
        else:
            warnings.append(f"Light '{ob.name}': {light.type} lights are not modelled by SSDF_SG")
    return lamps


CLASSES = (PRTSGMaterialSettings, PRT_PT_sg_material)


def register():
    for cls in CLASSES:
        bpy.utils.register_class(cls)
    bpy.types.Material.prt_sg = PointerProperty(type=PRTSGMaterialSettings)


def unregister():
    del bpy.types.Material.prt_sg
    for cls in reversed(CLASSES):
        bpy.utils.unregister_class(cls)
