"""SSDF_SG: per-pixel all-frequency shading with spherical Gaussians and SSDF
visibility (Wang, Ren, Gong, Snyder, Guo 2009).

Precompute (``derive``): the SSDF of every shading point (``core.methods.ssdf_sg.ssdf``, eq. 23)
compressed by PCA (eq. 24) with as many terms as the error budget needs.
``store`` writes, per object, one blob ``ssdf_sg`` (:mod:`.ssdf_sg_storage`).
``sync`` loads it, or derives it from the stored visibility when it is missing or
was made with other SSDF settings (noted in the panel).

Shading: eq. 39 (diffuse: the environment's SG fit times the clamped-cosine
SG, visibility by eq. 30 at each product lobe's SSDF value) and eq. 41
(specular: the BRDF's warped SG lobes times the clamped cosine, eq. 31
visibility, eq. 35 inner product with the SG-prefiltered environment).
``draw_objects`` does it per pixel on the GPU (:mod:`.ssdf_sg_gpu`); ``shade`` per
vertex in numpy (``core.methods.ssdf_sg.scene.shade_points``) for tests/benches.
Lighting is fitted/prefiltered once per environment image; the world's
rotation and strength are applied at draw time (eq. 7: rotating an SG rotates
its axis), so neither they nor BRDF sliders need a new precompute.  With
``sg_lighting_fit = 'SCENE'`` (default) the diffuse lobes' amplitudes are
re-solved for the scene when the world turns (:func:`scene_fit`, the numerics in
``core.methods.ssdf_sg.scene.scene_fit``: non-negative least squares against the exact shadowed
irradiance at <= 1024 points, ~0.1 s).  This module is the bpy side: settings,
precompute/store/sync, the caches of the lighting and the fit.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from ....core.sphere import directions
from ....core.methods.ssdf_sg import ssdf, shading as ssdf_sg
from ....core.methods.ssdf_sg import scene as scene
from ....core.pipeline import frame_status
from ...blender import storage
from ...blender.texture_export import shader_inputs
from ...frame import keys
from ...ui import sg_material
from ..contract import Shading
from .gpu import gpu_draws
from .store import field_from, open_field, read_field, write_field

# (ident, resolution) -> (diffuse SGs, PrefilteredEnvironment) of the unrotated image
_LIGHTING_CACHE = keys.cache(1)
# SSDF PCA derived at draw time per (object, visibility, settings)
FIELD_CACHE = keys.cache(8)
# ("points", objects) -> the fit's points; ("fit", lighting) -> the scene-fitted lighting
_SCENE_FIT_CACHE = keys.cache(8)


def cosine_of(settings) -> ssdf_sg.CosineLobes:
    return ssdf_sg.COSINE_MODELS.get(str(settings.get("ssdf_cosine", "SG7")), ssdf_sg.COSINE_SG7)


#: the add-on's SSDF sampling: visibility boundary from a 2x supersampled square, distances
#: at the texel centres (the 4x/2x grid like the paper's 512 -> 128 costs several times more
#: per point; bench numbers of both in docs/measurements.md)
def method_grid(resolution: int) -> ssdf.SSDFGrid:
    return ssdf.SSDFGrid(int(resolution), visibility_supersample=2, distance_supersample=1)


#: default Min Occlusion Kept: at the RMS budget alone a ground keeps ~60 % of its blocked
#: directions (small occluders' shadows fade); its flat triangles read the SSDF per point
#: (pair_table), so the terms this takes cost no per-pixel time there
OCCLUSION_TARGET_DEFAULT = 0.9


def pca_settings(settings):
    """(SSDF resolution, RMS budget, max terms, occlusion target) of the PCA."""
    return (int(settings.get("ssdf_resolution", 32)), float(settings.get("ssdf_error_budget", 0.05)),
            int(settings.get("ssdf_max_terms", 48)),
            float(settings.get("ssdf_occlusion_target", OCCLUSION_TARGET_DEFAULT)))


def derive_object(bits, normals, cube, settings, cancel=None, progress=None):
    """(basis, coefficients) of one object's SSDFs (eq. 23-24)."""
    res, budget, max_terms, occlusion = pca_settings(settings)
    return ssdf.ssdf_pca(bits, normals, cube, method_grid(res), budget, max_terms,
                         cancel=cancel, progress=progress, occlusion_target=occlusion)


def environment_lighting(world, resolution: int, max_lobes: int = 8):
    """``(axes, lam, mu)`` diffuse SG fit and the SG-prefiltered pyramid of the
    world's image without rotation/strength (texture space), cached per image
    (:func:`core.methods.ssdf_sg.scene.fit_environment`)."""
    key = (keys.env_key(world, resolution)[0], resolution, max_lobes)
    return keys.held(_LIGHTING_CACHE, key, (),
                     lambda: scene.fit_environment(world, resolution, max_lobes))


def object_sg_materials(st):
    """The SG material per slot of a synced object: a material's own "PRT Reflectance"
    model (``addon/ui/sg_material.py``, kept by ``sync``), else its core material converted
    (so a textured slot's base colour, which ``FrameState.shade`` sets to white and black,
    reaches the SG material)."""
    own = st.data.get("sg_own", {})
    return [own[slot] if slot in own else sg for slot, sg
            in enumerate(scene.sg_materials(st.materials))]


def scene_fit(state, fields, fit, cosine):
    """The diffuse SG fit with its RGB amplitudes re-solved for this scene at the world's
    current rotation (:func:`core.methods.ssdf_sg.scene.scene_fit`) at the points
    :func:`core.methods.ssdf_sg.scene.fit_points` draws, both kept: the points while the objects
    and their diffuse slots are the same, the fit per lighting.  ``fit`` itself when
    nothing is fitted."""
    lam = fit[1]
    world = state.world
    if len(lam) == 0 or not state.objects or float(world.strength) <= 0.0:
        return fit
    diffuse = [scene.diffuse_slots(object_sg_materials(st)) for st in state.objects]
    # keyed on the geometry's fingerprint, not the arrays: every F12 syncs new arrays
    refs = tuple(x for st, f in zip(state.objects, fields) for x in (st.bits, f))
    objects_key = (tuple(st.name for st in state.objects),
                   tuple(st.fingerprint for st in state.objects),
                   tuple(tuple(d) for d in diffuse))
    picks = keys.held(_SCENE_FIT_CACHE, ("points", objects_key), refs,
                      lambda: scene.fit_points([
                          scene.diffuse_point_weights(st.arrays, st.points, d)
                          for st, d in zip(state.objects, diffuse)]))
    if not picks:
        return fit
    lighting_key = (keys.env_key(world, state.resolution)[0], world.rotation.round(9).tobytes(),
                    state.resolution, cosine.sharpness, len(cosine.amplitudes), objects_key)

    def solve():
        samples = [(fields[o].numpy, rows, state.objects[o].points.normals[rows],
                    state.objects[o].bits[rows], w) for o, rows, w in picks]
        return scene.scene_fit(fit, cosine, samples, world, directions.cubemap(state.resolution),
                               keys.environment_cubemap(world, state.resolution))
    return keys.held(_SCENE_FIT_CACHE, ("fit", lighting_key), refs + (fit,), solve)


class SSDFSGShading(Shading):
    def draws_lamps(self, settings: dict) -> bool:
        """Point and spot lamps as SG lobes with SSDF visibility (eq. 32-33, 42-43, per
        vertex) when ``ssdf_lamps`` asks for them; by default the shared lamp pass draws
        them per pixel and SSDF_SG's own pass stays per pixel."""
        return settings.get("ssdf_lamps", "PASS") == "SG"

    def view_dependent(self, state) -> bool:
        return any(scene.is_glossy(m) for st in state.objects for m in object_sg_materials(st))

    # ------------------------------------------------------------- precompute
    def derive(self, job):
        cube = directions.cubemap(job.resolution)
        out = {}
        total = max(job.point_count, 1)
        base = [0]

        def cancel():
            return job.cancel_requested

        for o in job.objects:
            def progress(done, count, start=base[0]):
                job.progress_done = int(start + done * o.points.count / max(count, 1))

            basis, coeffs = derive_object(o.bits, o.points.normals, cube, job.settings,
                                          cancel=cancel, progress=progress)
            out[o.name] = (basis, coeffs)
            base[0] += o.points.count
        job.progress_done = total
        return out

    def store(self, scene, job, derived):
        if not derived:
            return
        for o in job.objects:
            if o.name not in derived:
                continue
            basis, coeffs = derived[o.name]
            write_field(storage.owner(o.name), basis, coeffs, job.resolution)

    # ------------------------------------------------------------- sync
    def sync(self, state):
        import bpy
        for st in state.objects:
            # slots with their own SG model (not the node tree); its lobes are drawn here,
            # even when narrower than the cubemap (addon/gpu/sharp.py draws the node tree's)
            own = {}
            for slot, n in enumerate(st.data.get("material_names") or ()):
                mat = bpy.data.materials.get(n) if n else None
                if mat is None or sg_material.uses_blender_material(mat) \
                        or slot >= len(st.materials):
                    continue
                own[slot] = sg_material.export_sg_material(mat, state.warnings)
                # the slot's textured-input variants too (addon/gpu/sharp.py draws by slot)
                st.materials = [replace(m, per_pixel_lobe=False) if st.slot_of[i] == slot
                                else m for i, m in enumerate(st.materials)]
            # a Roughness image read per pixel: the slot table's nodes span 0-1, closer to
            # Cycles than addon/gpu/sharp.py's samples (not under AUTO: its other methods need
            # the sharp pass)
            if state.method == "SSDF_SG":
                mine = [slot for slot in st.inputs[0] if "Roughness" in shader_inputs(st, slot)]
                st.materials = [replace(m, per_pixel_lobe=False) if st.slot_of[i] in mine
                                else m for i, m in enumerate(st.materials)]
            st.data["sg_own"] = own
        cube = directions.cubemap(state.resolution)
        res, budget, max_terms, occlusion = pca_settings(state.settings)
        derived_now = []
        faded = []
        LAST_TERMS.clear()
        for st in state.objects:
            field = None
            loaded = read_field(storage.owner(st.name), st.points.count,
                                state.resolution, res, budget, max_terms, occlusion, state.note)
            if loaded is not None and st.status == "ok":
                field = loaded
            elif st.status in ("missing", "unshadowed"):
                field = open_field(st.points.count, res)        # no shadows: exact, instant
            else:
                key = (st.name, id(st.bits), res, budget, max_terms, occlusion,
                       state.resolution)
                field = keys.per_visibility(
                    FIELD_CACHE, key, st.bits,
                    lambda: field_from(derive_object(st.bits, st.points.normals, cube,
                                                     state.settings)))
                if st.status == "ok":
                    derived_now.append(st.name)
            st.data["ssdf_sg"] = field
            LAST_TERMS.append(f"{st.name}: {field.terms} PCA terms, RMS {field.rms:.3f} rad, "
                              f"{field.occlusion_kept:.0%} of blocked directions kept")
            if field.occlusion_kept < OCCLUSION_KEPT_WARNING:
                faded.append(f"'{st.name}' {field.occlusion_kept:.0%} ({field.terms} terms)")
        if derived_now:
            state.note("SSDF_SG: SSDFs computed at draw time (precompute with SSDF_SG to "
                       "store them): " + frame_status.listing(derived_now))
        if LAST_TERMS:
            state.note("SSDF_SG PCA: " + "; ".join(LAST_TERMS))
        if faded:
            state.note("SSDF_SG: the PCA keeps only " + frame_status.listing(faded) + " of the "
                       "blocked directions: shadows of small occluders (a low sun's) fade; Min Occlusion "
                       "Kept (or a smaller SSDF Error Budget) takes more terms (slower), then "
                       "precompute")

    # ------------------------------------------------------------- shading
    def _lighting(self, state):
        lobes = int(state.settings.get("sg_environment_lobes", 8))
        fit, pre = environment_lighting(state.world, state.resolution, lobes)
        if str(state.settings.get("sg_lighting_fit", "SCENE")) == "SCENE":
            fields = [self._field(state, st) for st in state.objects]
            fit = scene_fit(state, fields, fit, cosine_of(state.settings))
            if len(fit) > 4:
                before, after, count = fit[4]
                # one line for the current fit (a turned world re-fits: replace, not add)
                state.warnings[:] = [w for w in state.warnings
                                     if not w.startswith("SSDF_SG lighting:")]
                state.note(f"SSDF_SG lighting: {len(fit[1])} lobes, diffuse error at {count} "
                           f"scene points {after:.1%} (environment-only amplitudes {before:.1%})")
        return fit, pre

    def _field(self, state, st):
        """The object's SSDF field (``sync`` loads or derives it when a state was built
        without it)."""
        if st.data.get("ssdf_sg") is None:
            self.sync(state)
        return st.data["ssdf_sg"]

    def shade(self, state, eye, view_dir):
        fit, pre = self._lighting(state)
        out = []
        for i, st in enumerate(state.objects):
            state.tick(i / len(state.objects))      # progress; ESC stops here
            field = self._field(state, st)
            pts = st.points
            rad = scene.shade_points(field.numpy, pts.normals, pts.positions, pts.materials,
                                     object_sg_materials(st), state.world, fit, pre, eye,
                                     view_dir, cosine=cosine_of(state.settings),
                                     lamps=state.lamps)
            out.append(rad[pts.point_of_corner].astype(np.float32))
        return out

    def draw_objects(self, state, eye, view_dir):
        """Per-pixel eq. 39 + 41 on the GPU (``shaders/methods/ssdf_sg_*.glsl``); None (per-vertex
        ``shade``) when an object has a material the shader does not model."""
        if not state.objects:
            return None
        unsupported = [st.name for st in state.objects
                       if any(m.is_anisotropic for m in object_sg_materials(st))]
        if unsupported:
            state.note("SSDF_SG: anisotropic materials are shaded per vertex: "
                       + ", ".join(unsupported))
            return None
        if state.lamps:
            state.note("SSDF_SG: lamps as spherical Gaussians (eq. 42-43) are shaded per "
                       "vertex (the per-pixel shader draws the World only; Lamps: Shadow "
                       "Maps keeps it per pixel)")
            return None
        fields = []
        for st in state.objects:
            field = self._field(state, st)
            if field.terms + 1 > 4 * MAX_COEFF_TEXELS:
                return None
            fields.append(field)
        fit, pre = self._lighting(state)
        return gpu_draws(state, fields, [object_sg_materials(st) for st in state.objects], fit,
                         pre, cosine_of(state.settings), eye, view_dir)


#: the fragment shader holds (1, w_1..w_K) in at most this many vec4
MAX_COEFF_TEXELS = 16
#: "object: K terms, RMS" lines of the last sync (panel)
LAST_TERMS: list = []
#: below this share of blocked directions kept by the PCA (core.methods.ssdf_sg.ssdf.SSDFBasis.occlusion_kept)
#: the user is told that small occluders' shadows fade (the report scenes' grounds keep
#: 57-58 % at the RMS budget's 8 terms alone, ~80 % at 20-24, ~90 % at 48)
OCCLUSION_KEPT_WARNING = 0.75

