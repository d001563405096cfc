"""RSL: rotatable square lights (seed 000): the environment split into K square lights,
BRDF from summed-area tables and visibility from per-vertex distance tables (eq. 5)."""

from __future__ import annotations

import dataclasses

import numpy as np

from ...core import brdf, directions, envmap, reference, rsl
from .. import runtime
from . import Method, register

#: disk-map resolution of the BRDF SATs and visibility tables (§5.1: 32 x 32)
DISK_RESOLUTION = 32
#: view-elevation nodes of the isotropic BRDF SATs (§5.1: 32)
VIEW_NODES = 32
#: sub-samples per disk texel edge when tabulating a BRDF
BRDF_SUBSAMPLES = 3

_LIGHTING: dict = {}        # unrotated cubemap lighting per (content, strength, resolution)
_LIGHTS: dict = {}          # SquareLights per (lighting key, K / budget)
_TABLES: dict = {}          # BrdfTables per material
_VISIBILITY: dict = {}      # per-vertex VDT / SAT per (object, bits)
_FACTORS: dict = {}         # view-independent (V, C) per (object, bits, lights, rotation)


def _unrotated_lighting(world: envmap.WorldLighting, resolution: int):
    """The world's cubemap in texture space (no Mapping rotation): the decomposition
    does not change when the world rotates, only the light centres do."""
    key = runtime.env_key(world, resolution)
    key = (key[0], key[1], resolution)
    got = _LIGHTING.get(key)
    if got is None:
        flat = dataclasses.replace(world, rotation=np.eye(3))
        got = flat.to_cubemap(resolution)
        _LIGHTING.clear()
        _LIGHTING[key] = got
    return key, got


def square_lights(state) -> rsl.SquareLights:
    key, lighting = _unrotated_lighting(state.world, state.resolution)
    s = state.settings
    budget = s.get("rsl_error_budget") if s.get("rsl_mode", "COUNT") == "BUDGET" else None
    count = int(s.get("rsl_lights", 30))
    lkey = (key, count, budget)
    got = _LIGHTS.get(lkey)
    if got is None:
        cube = directions.cubemap(state.resolution)
        got = rsl.decompose(lighting, cube, count if budget is None else None,
                            error_budget=budget)
        if len(_LIGHTS) > 8:
            _LIGHTS.pop(next(iter(_LIGHTS)))
        _LIGHTS[lkey] = got
    return lkey, got


def brdf_tables(material: brdf.Material) -> rsl.BrdfTables:
    got = _TABLES.get(material)
    if got is None:
        got = rsl.brdf_tables(material, DISK_RESOLUTION, VIEW_NODES, BRDF_SUBSAMPLES)
        if len(_TABLES) > 32:
            _TABLES.pop(next(iter(_TABLES)))
        _TABLES[material] = got
    return got


def derive_visibility(bits, normals, resolution: int) -> dict:
    """Per-vertex visibility maps in the disk map -> VDT (eq. 9) and visibility SAT."""
    cube = directions.cubemap(resolution)
    maps = rsl.visibility_maps(bits, normals, cube, DISK_RESOLUTION)
    return {"VDT": rsl.visibility_distance_table(maps), "SAT": rsl.visibility_sat(maps)}


def object_visibility(st, resolution: int) -> dict:
    stored = st.data.get("rsl")
    if stored is not None:
        return stored
    return runtime.per_visibility(
        _VISIBILITY, (st.name, id(st.bits), resolution), st.bits,
        lambda: derive_visibility(st.bits, st.points.normals, resolution), limit=8)


class RSLMethod(Method):
    id = "RSL"
    label = "Rotatable Square Lights"
    description = ("Environment split into K rotatable square lights; BRDF from summed-area "
                   "tables, visibility from distance tables (Wang et al.)")
    budget = ("rsl_lights", [10, 30, 60, 100])

    def scene_properties(self):
        from bpy.props import EnumProperty, FloatProperty, IntProperty
        upd = runtime.redraw_viewports
        return {
            "rsl_lights": IntProperty(
                name="Lights", default=30, min=1, max=2000, update=upd,
                description="Number of rotatable square lights the environment is split into"),
            "rsl_mode": EnumProperty(
                name="Light Count", update=upd,
                items=[("COUNT", "Count", "Use exactly the given number of lights"),
                       ("BUDGET", "Error Budget", "Merge until the RSL fitting error reaches "
                                                  "the budget")],
                default="COUNT"),
            "rsl_error_budget": FloatProperty(
                name="Fitting Error", default=0.3, min=1e-4, max=1.0, update=upd,
                description="Error budget mode: summed RSL fitting error relative to the "
                            "lighting's squared energy"),
            "rsl_visibility": EnumProperty(
                name="Visibility", update=upd,
                items=[("VDT", "Distance Table", "One look-up per light (eq. 9)"),
                       ("SAT", "Summed-Area Table", "Exact box integral, four look-ups")],
                default="VDT"),
        }

    def draw_settings(self, layout, prt):
        layout.prop(prt, "rsl_mode")
        if prt.rsl_mode == "BUDGET":
            layout.prop(prt, "rsl_error_budget")
        else:
            layout.prop(prt, "rsl_lights")
        layout.prop(prt, "rsl_visibility")

    def view_dependent(self, state) -> bool:
        return any(not m.is_diffuse_only or m.fresnel == "DIELECTRIC"
                   for st in state.objects for m in st.materials)

    def shade(self, state, eye, view_dir):
        lkey, lights = square_lights(state)
        R = state.world.rotation
        evaluator = rsl.Evaluator(lights, R)
        kind = state.settings.get("rsl_visibility", "VDT")
        cos_tables = brdf_tables(brdf.Material())
        out = []
        for st in state.objects:
            pts = st.points
            vis = object_visibility(st, state.resolution)[kind]
            V, C = runtime.per_visibility(
                _FACTORS, (st.name, id(st.bits), lkey, kind, R.round(9).tobytes()), st.bits,
                lambda: evaluator.diffuse_factors(pts.normals, kind, vis, cos_tables), limit=8)
            radiance = np.zeros((pts.count, 3))
            for slot in np.unique(pts.materials):
                sel = np.nonzero(pts.materials == slot)[0]
                mat = st.materials[int(slot)] if 0 <= slot < len(st.materials) else brdf.Material()
                vd = None
                if not mat.is_diffuse_only or mat.fresnel == "DIELECTRIC":
                    if view_dir is not None:
                        vd = np.broadcast_to(np.asarray(view_dir, np.float64), (len(sel), 3))
                    else:
                        vd = reference.view_directions(pts.positions[sel], eye)
                radiance[sel] = evaluator.shade(mat, brdf_tables(mat), pts.normals[sel], vd,
                                                V[sel], C[sel])
            radiance = np.nan_to_num(radiance, nan=0.0, posinf=0.0, neginf=0.0)
            out.append(radiance[pts.point_of_corner].astype(np.float32))
        return out


register(RSLMethod())
