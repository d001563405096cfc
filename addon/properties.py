"""Scene and object settings (``scene.prt``, ``object.prt``)."""

import bpy
from bpy.props import (EnumProperty, FloatProperty, IntProperty, PointerProperty,
                       StringProperty)

METHOD_ITEMS = [
    ("REFERENCE", "Reference",
     "Pixel-basis triple product over every cubemap texel (exact for the cubemap; slowest)"),
    ("SH", "Spherical Harmonics",
     "Diffuse shadowed transfer in spherical harmonics (Sloan 2002): low frequency, fastest; "
     "draws the diffuse part of materials only"),
]

RESOLUTION_ITEMS = [
    ("32", "6×32×32", "6144 directions: the default"),
    ("64", "6×64×64", "24576 directions: sharper shadows, 4× the rays and storage"),
    ("128", "6×128×128", "98304 directions: 16× the rays and storage"),
]


def _redraw(self, context):
    for window in getattr(context.window_manager, "windows", []):
        for area in window.screen.areas:
            if area.type == "VIEW_3D":
                area.tag_redraw()


class PRTSceneSettings(bpy.types.PropertyGroup):
    method: EnumProperty(name="Method", items=METHOD_ITEMS, default="REFERENCE",
                         description="How the stored transfer is turned into pixels",
                         update=_redraw)
    sh_order: IntProperty(name="SH Order", default=4, min=2, max=5, update=_redraw,
                          description="Spherical-harmonic bands kept by the SH method "
                                      "(order n: n*n coefficients)")
    resolution: EnumProperty(name="Directions", items=RESOLUTION_ITEMS, default="32",
                             description="Cubemap resolution of the precomputed visibility")
    ray_offset: FloatProperty(name="Ray Offset", default=1e-4, min=1e-7, max=1e-1,
                              precision=6, subtype="FACTOR",
                              description="Self-intersection offset, relative to the scene's "
                                          "bounding diagonal")
    supersampling: IntProperty(name="Anti-Aliasing", default=3, min=1, max=4,
                               description="Final renders are drawn at this many times the "
                                           "resolution per axis and box-filtered")
    # Written by the precompute operator (read-only in the UI).
    precomputed_resolution: IntProperty(name="Precomputed Directions", default=0)
    last_report: StringProperty(name="Last Precompute", default="")
    scene_fingerprint: StringProperty(name="Scene Fingerprint", default="",
                                      description="Geometry of every object at the precompute")


class PRTObjectData(bpy.types.PropertyGroup):
    """Per-object link to the stored transfer (an image in the .blend)."""

    visibility: PointerProperty(name="Visibility", type=bpy.types.Image,
                                description="Packed float image holding bit-packed visibility")
    resolution: IntProperty(name="Directions", default=0)
    point_count: IntProperty(name="Shading Points", default=0)
    fingerprint: StringProperty(name="Geometry Fingerprint", default="")
    precompute_id: StringProperty(name="Precompute ID", default="",
                                  description="Unique per precompute: identifies the stored data")
    coarse_warning: StringProperty(name="Tessellation Note", default="")


CLASSES = (PRTSceneSettings, PRTObjectData)


def register():
    for cls in CLASSES:
        bpy.utils.register_class(cls)
    bpy.types.Scene.prt = PointerProperty(type=PRTSceneSettings)
    bpy.types.Object.prt = PointerProperty(type=PRTObjectData)


def unregister():
    del bpy.types.Object.prt
    del bpy.types.Scene.prt
    for cls in reversed(CLASSES):
        bpy.utils.unregister_class(cls)
