"""Scene and object settings (``scene.prt``, ``object.prt``)."""

import bpy
from bpy.props import (BoolProperty, EnumProperty, FloatProperty, IntProperty,
                       PointerProperty, StringProperty)

from ...core.shading import pixel_filter
from ...core.transport import transfer
from .. import methods
from ..gpu.drawing import redraw_viewports
from ..methods import catalog  # noqa: F401  (registers every method before the enum is built)

RESOLUTION_ITEMS = [
    ("32", "6×32×32", "6144 directions: the default"),
    ("64", "6×64×64", "24576 directions: sharper shadows, 4× the rays and storage"),
    ("128", "6×128×128", "98304 directions: 16× the rays and storage"),
]


class PRTSceneSettings(bpy.types.PropertyGroup):
    method: EnumProperty(name="Method", items=methods.enum_items(), default="REFERENCE",
                         description="How the stored transfer is turned into pixels",
                         update=redraw_viewports)
    resolution: EnumProperty(name="Directions", items=RESOLUTION_ITEMS, default="32",
                             description="Cubemap resolution of the precomputed visibility")
    ray_offset: FloatProperty(name="Ray Offset", default=1e-4, min=1e-7, max=1e-1,
                              precision=6, subtype="FACTOR",
                              description="Self-intersection offset, relative to the scene's "
                                          "bounding diagonal")
    supersampling: IntProperty(name="Anti-Aliasing", default=3, min=1, max=4,
                               description="Final renders are drawn at this many times the "
                                           "resolution per axis and resolved with the Film's "
                                           "Filter Size (Blackman-Harris, as Cycles)")
    aa_threshold: FloatProperty(name="Adaptive Threshold", default=pixel_filter.REFINE_THRESHOLD,
                                min=0.0, max=1.0, precision=3,
                                description="Final renders draw a pilot frame of one sample per "
                                            "pixel and give every sample only to the pixels "
                                            "that differ from a neighbour by more than this "
                                            "relative contrast (edges, highlights, texture "
                                            "detail); 0 = every pixel gets every sample")
    light_sources: IntProperty(name="Compact Sources", default=8, min=0, max=8,
                               description="Most bright, compact sources (a sun, softboxes) "
                                           "taken out of the World and drawn per pixel with "
                                           "their own shadows; 0 = every method shades the "
                                           "whole World", update=redraw_viewports)
    light_threshold: FloatProperty(name="Source Threshold", default=8.0, min=1.0, max=1e4,
                                   description="A pixel belongs to a source when it is this "
                                               "many times brighter than the World's mean",
                                   update=redraw_viewports)
    light_min_share: FloatProperty(name="Min Source Share", default=0.01, min=0.0, max=1.0,
                                   subtype="FACTOR",
                                   description="A source must carry this share of the "
                                               "World's energy", update=redraw_viewports)
    bounce_rows_budget: IntProperty(
        name="Bounce Rows Budget", default=transfer.ROW_BUDGET_MIB, min=0, max=65536,
        description="MiB the precompute may give the bounced light's rows (each point's "
                    "share of every surface cluster it sees: 32 entries, 268 bytes a point "
                    "while gathered); past it rows keep fewer entries, the bounce's amount "
                    "kept and its colours from fewer clusters (a large scatter of instances)")
    field_detail: EnumProperty(
        name="Field Detail", default="HIGH",
        items=[("LOW", "Low", "8 shells of 6×8² samples, 16² maps: fastest, coarse shadows"),
               ("MEDIUM", "Medium", "12 shells of 6×12² samples, 24² maps"),
               ("HIGH", "High", "16 shells of 6×16² samples, 32² maps (Xu et al. 2006)")],
        description="Sampling of the dynamic objects' shadow fields (precomputed with them)")
    light_group_passes: BoolProperty(
        name="Light Group Passes", default=False,
        description="F12 writes a Combined_<group> pass per light group -- the World, each "
                    "compact source of it, each lamp, or the view layer's Light Groups -- "
                    "summing to Combined, for the compositor; each group costs another "
                    "frame (on as well when the view layer has Light Groups)")
    write_attributes: BoolProperty(
        name="Mesh Attributes", default=True,
        description="Precompute writes each object's PRT AO, PRT Bent Normal and SH transfer "
                    "(PRT SH 0, ...) as Face Corner attributes of its mesh (the Spreadsheet, "
                    "the Attribute node, Geometry Nodes); Clear removes them")
    attribute_sh_order: IntProperty(
        name="SH Attribute Order", default=3, min=0, max=5,
        description="Order of the SH transfer vector written as attributes (order² of "
                    "them, PRT SH 0 ...; 0 = none)")
    # Written by the precompute operator (read-only in the UI).
    precomputed_resolution: IntProperty(name="Precomputed Directions", default=0)
    last_report: StringProperty(name="Last Precompute", default="")
    scene_fingerprint: StringProperty(name="Scene Fingerprint", default="",
                                      description="Geometry of every object at the precompute")
    precompute_id: StringProperty(name="Precompute ID", default="",
                                  description="The last precompute's run (each object it "
                                              "traced carries the same ID)")
    precomputed_objects: IntProperty(name="Precomputed Objects", default=0,
                                     description="How many objects the last precompute traced")


class PRTObjectData(bpy.types.PropertyGroup):
    """Per-object record of the last precompute (its data: ``addon.blender.storage``)."""

    resolution: IntProperty(name="Directions", default=0)
    point_count: IntProperty(name="Shading Points", default=0)
    fingerprint: StringProperty(name="Geometry Fingerprint", default="")
    precompute_id: StringProperty(name="Precompute ID", default="",
                                  description="Unique per precompute: identifies the stored data")
    coarse_warning: StringProperty(name="Tessellation Note", default="")
    back_sides: BoolProperty(name="Back Sides", default=False,
                             description="The precompute traced this open surface's back "
                                         "side too (light reaches it, or the camera sees it)")
    dynamic: BoolProperty(name="Dynamic", default=False,
                          description="Precompute a shadow field for this object, so that it "
                                      "can move, turn and scale uniformly (keyframed or by "
                                      "hand) with live shadows on itself and on others, "
                                      "with no new precompute (an instancer: each of its "
                                      "instances, following it)")


CLASSES = (PRTSceneSettings, PRTObjectData)


def register():
    # Every method's settings (budgets, sliders) become scene.prt properties.
    PRTSceneSettings.__annotations__.update(methods.scene_properties())
    for cls in CLASSES:
        bpy.utils.register_class(cls)
    bpy.types.Scene.prt = PointerProperty(type=PRTSceneSettings)
    bpy.types.Object.prt = PointerProperty(type=PRTObjectData)


def unregister():
    del bpy.types.Object.prt
    del bpy.types.Scene.prt
    for cls in reversed(CLASSES):
        bpy.utils.unregister_class(cls)
