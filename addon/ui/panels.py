"""Panels: Render properties and the 3D viewport sidebar tab."""

import bpy

from ..frame import sources
from .. import methods
from ..blender import scene_export, storage
from .operators import RUNNING
from ..frame.state import LAST_MESSAGES


def draw_settings(layout, context):
    scene = context.scene
    prt = scene.prt
    col = layout.column()
    col.prop(prt, "method")
    methods.get(prt.method).settings.draw(col, prt)
    box = col.box()
    box.label(text="Compact sources (drawn per pixel)", icon="LIGHT_SUN")
    box.prop(prt, "light_sources")
    sub = box.column()
    sub.active = prt.light_sources > 0
    sub.prop(prt, "light_threshold")
    sub.prop(prt, "light_min_share")
    for line in sources.LAST_SOURCES[:8]:
        sub.label(text=line)
    if prt.light_sources > 0 and not sources.LAST_SOURCES:
        sub.label(text="None found: the whole World goes through the method")
    col.prop(prt, "resolution")
    if any(o.prt.dynamic for o in scene.objects if o.type in ("MESH", "EMPTY")):
        col.prop(prt, "field_detail")
    col.prop(prt, "ray_offset")
    if scene_export.light_bounces(scene) > 0:
        col.prop(prt, "bounce_rows_budget")
    row = col.row()
    row.prop(prt, "write_attributes")
    sub = row.row()
    sub.active = prt.write_attributes
    sub.prop(prt, "attribute_sh_order", text="SH Order")
    col.prop(prt, "supersampling")
    sub = col.column()
    sub.active = prt.supersampling > 1
    sub.prop(scene.render, "filter_size")
    sub.prop(prt, "aa_threshold")
    row = layout.row(align=True)
    row.enabled = not RUNNING
    row.operator("prt.precompute", icon="LIGHT_SUN")
    row.operator("prt.clear", text="", icon="TRASH")
    layout.operator("prt.report", icon="GRAPH")
    layout.operator("prt.bake", icon="RENDER_STILL")
    if prt.last_report:
        layout.label(text=prt.last_report, icon="INFO")
    if prt.precomputed_resolution and str(prt.precomputed_resolution) != prt.resolution:
        layout.label(text=f"Stored data uses 6×{prt.precomputed_resolution}²: precompute again",
                     icon="ERROR")
    if scene.world is None:
        layout.label(text="No World: add one with an Environment Texture", icon="ERROR")
    for message in LAST_MESSAGES[:6]:
        layout.label(text=message, icon="ERROR")
    ob = context.active_object
    if ob is not None and ob.type == "EMPTY" and ob.instance_type == "COLLECTION":
        box = layout.box()
        box.prop(ob.prt, "dynamic", text="Dynamic Instances")
        records = storage.instance_records(ob)
        box.label(text=f"{len(records)} instance(s) stored: "
                       f"{sum(storage.stored_bytes(r) for r in records) / 2**20:.1f} MiB",
                  icon="OUTLINER_OB_GROUP_INSTANCE")
    if ob is not None and ob.type == "MESH":
        box = layout.box()
        data = ob.prt
        box.prop(data, "dynamic")
        if storage.has(ob, storage.SHADOW_FIELD):
            box.label(text=f"Shadow fields: {storage.stored_bytes(ob, storage.SHADOW_FIELD) / 2**20:.1f}"
                           " MiB stored", icon="PHYSICS")
        if not storage.has(ob, storage.VISIBILITY):
            box.label(text=f"'{ob.name}': not precomputed", icon="MESH_DATA")
        else:
            box.label(text=f"'{ob.name}': {data.point_count} shading points", icon="MESH_DATA")
            if data.coarse_warning:
                box.label(text="Too coarse for its shadows: subdivide", icon="ERROR")


class PRT_PT_render(bpy.types.Panel):
    bl_label = "PRT Relight"
    bl_space_type = "PROPERTIES"
    bl_region_type = "WINDOW"
    bl_context = "render"
    COMPAT_ENGINES = {"PRT_RELIGHT"}

    @classmethod
    def poll(cls, context):
        return context.engine in cls.COMPAT_ENGINES

    def draw(self, context):
        draw_settings(self.layout, context)


class PRT_PT_passes(bpy.types.Panel):
    """The passes F12 writes beside Combined (addon/frame/passes.py), as Cycles names them."""
    bl_label = "PRT Relight Passes"
    bl_space_type = "PROPERTIES"
    bl_region_type = "WINDOW"
    bl_context = "view_layer"
    COMPAT_ENGINES = {"PRT_RELIGHT"}

    @classmethod
    def poll(cls, context):
        return context.engine in cls.COMPAT_ENGINES

    def draw(self, context):
        layer = context.view_layer
        col = self.layout.column(heading="Data")
        for attr, label in (("use_pass_z", "Z"), ("use_pass_position", "Position"),
                            ("use_pass_normal", "Normal")):
            col.prop(layer, attr, text=label)
        col = self.layout.column(heading="Light")
        col.prop(layer, "use_pass_ambient_occlusion", text="Ambient Occlusion")
        col.prop(layer, "use_pass_environment", text="Environment")
        col.prop(context.scene.prt, "light_group_passes")
        if len(layer.lightgroups):
            col.label(text="Light Groups: " + ", ".join(g.name for g in layer.lightgroups),
                      icon="LIGHT")


class PRT_PT_sidebar(bpy.types.Panel):
    bl_label = "PRT Relight"
    bl_space_type = "VIEW_3D"
    bl_region_type = "UI"
    bl_category = "PRT"

    def draw(self, context):
        draw_settings(self.layout, context)


CLASSES = (PRT_PT_render, PRT_PT_passes, PRT_PT_sidebar)


register, unregister = bpy.utils.register_classes_factory(CLASSES)
