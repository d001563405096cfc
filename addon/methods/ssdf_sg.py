"""SSDF_SG: per-pixel all-frequency shading with spherical Gaussians and SSDF
visibility (Wang, Ren, Gong, Snyder, Guo 2009, paper 003).

Precompute (``derive``): the SSDF of every shading point (``core.ssdf``, eq. 23)
compressed by PCA (eq. 24) with as many terms as the error budget needs.
``store`` writes, per object, one blob ``ssdf_sg`` (:mod:`..storage`: mean,
eigen-images, per-point coefficients and the settings they were made with).
``sync`` loads it, or derives it from the stored visibility when it is missing or
was made with other SSDF settings (noted in the panel).

Shading: eq. 39 (diffuse: the environment's SG fit times the clamped-cosine
SG, visibility by eq. 30 at each product lobe's SSDF value) and eq. 41
(specular: the BRDF's warped SG lobes times the clamped cosine, eq. 31
visibility, eq. 35 inner product with the SG-prefiltered environment).
``draw_objects`` does it per pixel on the GPU (``shaders/ssdf_sg_*.glsl``; flat
triangles read eq. 39's per-pair SSDF angles, weights and slopes from a per-point pair
table, :func:`pair_table`, since those are exactly linear inside them);
``shade`` does it per vertex in numpy (``core.ssdf_sg``) for tests/benches.
Lighting is fitted/prefiltered once per environment image; the world's
rotation and strength are applied at draw time (eq. 7: rotating an SG rotates
its axis), so neither they nor BRDF sliders need a new precompute.  With
``sg_lighting_fit = 'SCENE'`` (default) the diffuse lobes' amplitudes are
re-solved for the scene when the world turns (:func:`scene_fit`: non-negative
least squares against the exact shadowed irradiance at <= 1024 points, ~0.1 s).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from ...core import directions, envmap, reference, sg_brdf, sg_lighting, ssdf, ssdf_sg
from ...core import mesh as core_mesh
from ...core import brdf as core_brdf
from .. import drawing, runtime, storage
from . import Method, register

#: name of the stored blob (addon.storage): one object's PCA SSDF and how it was made
BLOB = "ssdf_sg"
# (ident, resolution) -> (diffuse SGs, PrefilteredEnvironment) of the unrotated image
_LIGHTING_CACHE: dict = {}
# SSDF PCA derived at draw time per (object, visibility, settings); a field carries its
# GPU textures once drawn (``field.gpu``), so the cache is freed with the GPU objects
_FIELD_CACHE: dict = drawing.gpu_cache({})


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


#: the diffuse SG fit reads the environment at this cubemap resolution (at least), so a
#: small sun gets a lobe about one 128-texel wide (sharpness ~1000) and a sharp shadow
FIT_CUBE_RESOLUTION = 128


def environment_lighting(world: envmap.WorldLighting, resolution: int, max_lobes: int = 8):
    """``(axes, lam, mu)`` diffuse SG fit and the SG-prefiltered pyramid of the
    world's image without rotation/strength (texture space), cached per image."""
    ident = runtime.env_key(world, resolution)[0]
    key = (ident, resolution, max_lobes)
    hit = _LIGHTING_CACHE.get(key)
    if hit is None:
        base = envmap.WorldLighting(image=world.image, color=world.color, strength=1.0)
        cube = directions.cubemap(resolution)
        radiance = np.asarray(base.to_cubemap(resolution).radiance, np.float64)
        fine = max(FIT_CUBE_RESOLUTION, resolution)
        fit_radiance = (radiance if fine == resolution
                        else np.asarray(base.to_cubemap(fine).radiance, np.float64))
        axes, lam, mu, rel = sg_lighting.fit_environment_sgs(
            fit_radiance, directions.cubemap(fine), max_lobes=max_lobes)
        pre = sg_lighting.PrefilteredEnvironment(radiance, cube)
        hit = ((axes, lam, mu, rel), pre)
        _LIGHTING_CACHE.clear()
        _LIGHTING_CACHE[key] = hit
    return hit


#: scene points (drawn by surface area among the points with a diffuse part) at which
#: the diffuse lighting amplitudes are fitted (``sg_lighting_fit = 'SCENE'``)
SCENE_FIT_POINTS = 1024
#: ridge of the scene fit toward the environment fit, per unknown per point (see scene_fit)
PRIOR_WEIGHT = 1e-3
# ("points", objects) -> scene_fit_points' draw; ("fit", lighting) -> the scene-fitted
# lighting (entries keep their fields alive, which may hold GPU textures: freed with the
# GPU caches)
_SCENE_FIT_CACHE: dict = drawing.gpu_cache({})


def scene_fit_points(state, fields, count: int = SCENE_FIT_POINTS, seed: int = 0):
    """``[(object index, rows (sorted), weights)]``: the shading points whose material has
    a diffuse part, weighted by the surface area they stand for -- all of them (weights =
    their areas) when there are at most ``count``, else ``count`` draws with probability
    proportional to area (weights = how often each point was drawn)."""
    per = []
    for st in state.objects:
        pts = st.points
        area = core_mesh.point_areas(st.arrays, pts)
        diffuse = _diffuse_slots(st)
        per.append(area * diffuse[np.clip(pts.materials, 0, len(diffuse) - 1)])
    if sum(float(w.sum()) for w in per) <= 0.0:
        return []
    if sum(int(np.count_nonzero(w)) for w in per) <= count:
        picks = [(np.flatnonzero(w), w[w > 0]) for w in per]
    else:
        flat = np.concatenate(per)
        draw = np.random.default_rng(seed).choice(flat.size, count, p=flat / flat.sum())
        idx, times = np.unique(draw, return_counts=True)
        start = np.concatenate([[0], np.cumsum([len(w) for w in per])])
        picks = []
        for o in range(len(per)):
            sel = (idx >= start[o]) & (idx < start[o + 1])
            picks.append((idx[sel] - start[o], times[sel].astype(np.float64)))
    return [(o, rows, w) for o, (rows, w) in enumerate(picks) if rows.size]


def _diffuse_slots(st) -> np.ndarray:
    """Per material slot: whether its SG material has a diffuse part (at least one entry)."""
    table = object_sg_materials(st) or [sg_brdf.sg_material_from_brdf(core_brdf.Material())]
    return np.array([bool(np.any(np.asarray(sg_brdf.diffuse_albedo(m)) > 0)) for m in table])


def scene_fit(state, fields, fit, cosine):
    """The diffuse SG fit with its RGB amplitudes re-solved for this scene at the world's
    current rotation (:func:`core.sg_lighting.fit_scene_amplitudes`): the lobes' eq. 39
    transfer with the SSDF visibility (what is drawn) against REFERENCE's exact shadowed
    irradiance at :func:`scene_fit_points`.  Same form as ``fit`` (texture-space axes,
    amplitudes for strength 1), plus ``(error with the environment-only amplitudes,
    error after, points)`` in the scene's metric; ``fit`` itself when nothing is fitted."""
    lam = fit[1]
    world = state.world
    if len(lam) == 0 or not state.objects or float(world.strength) <= 0.0:
        return fit
    # keyed on the geometry's fingerprint, not the arrays: every F12 syncs new arrays
    refs = tuple(x for st, f in zip(state.objects, fields) for x in (st.bits, f))
    objects_key = (tuple(st.name for st in state.objects),
                   tuple(st.fingerprint for st in state.objects),
                   tuple(tuple(_diffuse_slots(st)) for st in state.objects))
    # drawn points: the same while the objects and their diffuse slots are (a turned world
    # or a new fit reuses them)
    picks = runtime.held(_SCENE_FIT_CACHE, ("points", objects_key), refs,
                         lambda: scene_fit_points(state, fields), limit=8)
    if not picks:
        return fit
    lighting_key = (runtime.env_key(world, state.resolution)[0], world.rotation.round(9).tobytes(),
                    state.resolution, cosine.sharpness, len(cosine.amplitudes), objects_key)
    return runtime.held(_SCENE_FIT_CACHE, ("fit", lighting_key), refs + (fit,),
                        lambda: _solve_scene_fit(state, fields, fit, cosine, picks), limit=8)


def _solve_scene_fit(state, fields, fit, cosine, picks):
    axes, lam, mu, rel = fit[:4]
    world = state.world
    strength = float(world.strength)
    cube = directions.cubemap(state.resolution)
    L = runtime.environment_cubemap(world, state.resolution)
    axes_w = sg_lighting.rotate_to_world(axes, world.rotation)
    T, E, W = [], [], []
    for o, rows, w in picks:
        st = state.objects[o]
        n = st.points.normals[rows]
        T.append(ssdf_sg.diffuse_lobe_transfer(fields[o].numpy, rows, n, axes_w, lam,
                                               cosine=cosine, per_cosine=True))
        E.append(reference.diffuse_irradiance(st.bits[rows], n, cube, L) / strength)
        W.append(w)
    T, E, W = np.concatenate(T), np.concatenate(E).astype(np.float64), np.concatenate(W)
    S, M, J = T.shape
    T = T.reshape(S, M * J)
    # one RGB amplitude per (cosine lobe, light lobe): each lobe of the clamped-cosine
    # mixture gets its own mix of the same light lobes (same per-pixel cost)
    # a ridge toward the environment fit's amplitudes that fades as the points outnumber
    # the unknowns (a small object: 5 points held 8 % -> 3.8 % off on tests' occluder)
    prior = cosine_amplitudes(mu, M).reshape(M * J, 3)
    scene_mu = sg_lighting.fit_scene_amplitudes(
        T, E, W, prior=prior, prior_weight=PRIOR_WEIGHT * M * J / S).reshape(M, J, 3)
    sw = np.sqrt(W)[:, None]
    norm = max(float(np.linalg.norm(E * sw)), 1e-300)
    before = float(np.linalg.norm((T @ prior - E) * sw)) / norm
    after = float(np.linalg.norm((T @ scene_mu.reshape(M * J, 3) - E) * sw)) / norm
    return (axes, lam, scene_mu, rel, (before, after, len(W)))


def cosine_amplitudes(mu, cosine_lobes: int) -> np.ndarray:
    """Amplitudes per (cosine lobe, light lobe) (M, J, 3): the scene fit's as they are,
    the environment fit's (J, 3) repeated for every cosine lobe."""
    mu = np.asarray(mu, np.float64)
    return mu if mu.ndim == 3 else np.broadcast_to(mu, (cosine_lobes,) + mu.shape)


def world_sgs(world, fit):
    """The diffuse SG fit in world space: ``L(d) = s E(R d)`` has axes ``R^T a``
    (amplitudes (J, 3), or (M, J, 3) per cosine lobe from the scene fit)."""
    axes, lam, mu = fit[:3]
    return axes @ world.rotation, lam, mu * float(world.strength)


def sg_materials(materials):
    """SG materials (core.brdf.Material converted; SGMaterial passed through)."""
    return [m if isinstance(m, sg_brdf.SGMaterial) else sg_brdf.sg_material_from_brdf(m)
            for m in materials]


def object_sg_materials(st):
    """The SG material per slot of a synced object: the material's "PRT Reflectance"
    settings (``addon/sg_material.py``) when synced, else converted from its Cycles
    material."""
    table = st.data.get("sg_materials")
    return table if table is not None else sg_materials(st.materials)


def shade_object(field, normals, positions, materials_of_points, materials, world, fit, pre,
                 eye=None, view_dir=None, chunk=4096, cosine=ssdf_sg.COSINE_EQ40, lamps=()):
    """Per-point radiance (P, 3) by eq. 39 + 41, plus eq. 42 + 43 for Blender lamps
    (``core.sg_lighting.Lamp``, one SG each per point: eq. 32-33) (numpy, per vertex)."""
    P = len(normals)
    out = np.zeros((P, 3))
    axes, lam, mu = world_sgs(world, fit)
    rot = world.rotation
    strength = float(world.strength)

    def env_lookup(d, lam_q):
        return (pre.lookup(d, lam_q, rotation=rot) * strength
                * ssdf_sg.sg.integral(lam_q)[:, None])

    table = sg_materials(materials)
    for slot in np.unique(materials_of_points):
        sel_all = np.nonzero(materials_of_points == slot)[0]
        mat = table[int(slot)] if 0 <= slot < len(table) else sg_brdf.sg_material_from_brdf(
            core_brdf.Material())
        kd = sg_brdf.diffuse_albedo(mat) / np.pi
        glossy = bool(np.any(np.asarray(mat.specular) > 0) or np.any(np.asarray(mat.metallic) > 0))
        for a in range(0, len(sel_all), chunk):
            sel = sel_all[a:a + chunk]
            n = normals[sel]
            t, b = ssdf.ssdf_frames(n)
            rd = ssdf_sg.diffuse_transfer_per_cosine(
                field, sel, n, axes, lam, cosine_amplitudes(mu, len(cosine.amplitudes)), t, b,
                cosine=cosine)
            out[sel] = rd * kd
            lobes = (None, None, None)
            if glossy:
                if view_dir is not None:
                    v = np.broadcast_to(np.asarray(view_dir, np.float64), n.shape)
                else:
                    v = positions[sel] - 0.0
                    v = np.asarray(eye, np.float64)[None, :] - v
                    v = v / np.maximum(np.linalg.norm(v, axis=1, keepdims=True), 1e-30)
                lobes = sg_brdf.specular_lobes(mat, n, v)
                out[sel] += ssdf_sg.specular_radiance(field, sel, n, *lobes, env_lookup, t, b,
                                                      cosine=cosine)
            if lamps:
                la, ll, lm = sg_lighting.lamp_sgs(lamps, positions[sel])
                out[sel] += ssdf_sg.lamp_radiance(field, sel, n, la, ll, lm, kd, *lobes, t, b,
                                                  cosine=cosine)
    return np.nan_to_num(out, nan=0.0, posinf=0.0, neginf=0.0)


class SSDFSGMethod(Method):
    #: Blender point/sun/spot lights are drawn (eq. 32-33, 42-43); FrameState notes
    #: that other methods light the scene from the World only
    draws_lamps = True
    id = "SSDF_SG"
    label = "SSDF + Spherical Gaussians"
    description = ("Per-pixel all-frequency shading (Wang et al. 2009): spherical-Gaussian "
                   "BRDF and lighting, visibility as PCA-compressed signed distance fields")
    budget = ("ssdf_error_budget", [0.2, 0.1, 0.05, 0.025])

    def scene_properties(self):
        from bpy.props import EnumProperty, FloatProperty, IntProperty
        return {
            "ssdf_cosine": EnumProperty(
                name="Clamped Cosine", default="SG7", update=runtime.redraw_viewports,
                items=[("EQ40", "1 lobe (paper, eq. 40)",
                        "One SG on the normal: fastest, L2 error 17.7 %"),
                       ("SG7", "7 lobes", "SG mixture over the hemisphere, L2 error 6.3 %"),
                       ("SG19", "19 lobes", "SG mixture over the hemisphere, L2 error 3.7 %")],
                description="SG mixture standing in for max(0, n.i) in eq. 39/41; more lobes "
                            "are more accurate and probe visibility more locally, but slower"),
            "ssdf_resolution": IntProperty(
                name="SSDF Resolution", default=32, min=8, max=64,
                description="Texels per edge of each point's SSDF square (Shirley-Chiu map of "
                            "the hemisphere); its visibility boundary is supersampled 2x"),
            "ssdf_error_budget": FloatProperty(
                name="SSDF Error Budget", default=0.05, min=0.001, max=1.0, precision=3,
                subtype="ANGLE",
                description="RMS angular error allowed for the PCA-compressed SSDFs; decides "
                            "the number of PCA terms per object (needs a precompute)"),
            "ssdf_max_terms": IntProperty(
                name="SSDF Max Terms", default=48, min=4, max=60,
                description="Upper limit of PCA terms per object"),
            "ssdf_occlusion_target": FloatProperty(
                name="Min Occlusion Kept", default=OCCLUSION_TARGET_DEFAULT, min=0.0, max=1.0,
                subtype="FACTOR",
                description="Take more PCA terms (up to the maximum) until this share of each "
                            "object's blocked directions stays blocked after compression; the "
                            "RMS budget alone can drop small occluders' shadows on a ground. "
                            "Flat triangles (a ground) pay the terms only when the lighting "
                            "changes, curved ones per pixel (0 = the budget alone; needs a "
                            "precompute)"),
            "sg_lighting_fit": EnumProperty(
                name="Lighting Fit", default="SCENE", update=runtime.redraw_viewports,
                items=[("SCENE", "Scene",
                        "Lobes from the environment, amplitudes fitted to the scene's exact "
                        "shadowed irradiance at up to 1024 surface points (redone when the "
                        "world turns, tens of milliseconds)"),
                       ("ENVIRONMENT", "Environment",
                        "Lobes and amplitudes from the environment alone (the paper's §6): "
                        "keeps the unshadowed irradiance")],
                description="How the diffuse term's SG lighting (eq. 39) is fitted"),
            "sg_environment_lobes": IntProperty(
                name="Environment Lobes", default=8, min=1, max=16,
                update=runtime.redraw_viewports,
                description="SG lobes fitted to the environment for the diffuse term"),
        }

    def draw_settings(self, layout, prt):
        for name in self.scene_properties():
            layout.prop(prt, name)
        for line in LAST_TERMS:
            layout.label(text=line)

    def view_dependent(self, state) -> bool:
        return any(bool(np.any(np.asarray(m.specular) > 0) or np.any(np.asarray(m.metallic) > 0))
                   for st in state.objects for m in object_sg_materials(st))

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
        import bpy
        if not derived:
            return
        for o in job.objects:
            if o.name not in derived:
                continue
            basis, coeffs = derived[o.name]
            write_field(bpy.data.objects[o.name], basis, coeffs, job.resolution)

    # ------------------------------------------------------------- sync
    def sync(self, state):
        import bpy
        from .. import sg_material
        for st in state.objects:
            names = st.data.get("material_names")
            if names is not None:
                sgm = []
                for slot, n in enumerate(names):
                    mat = bpy.data.materials.get(n) if n else None
                    m = sg_material.export_sg_material(mat, state.warnings)
                    if slot < len(st.materials) and st.materials[slot].per_pixel_lobe:
                        if sg_material.uses_blender_material(mat):
                            m = sg_brdf.without_glossy(m)     # its lobes: addon/sharp.py
                        else:                                 # its own SG model draws them
                            st.materials[slot] = replace(st.materials[slot],
                                                         per_pixel_lobe=False)
                    sgm.append(m)
                st.data["sg_materials"] = sgm
        cube = directions.cubemap(state.resolution)
        res, budget, max_terms, occlusion = pca_settings(state.settings)
        derived_now = []
        faded = []
        LAST_TERMS.clear()
        for st in state.objects:
            field = None
            loaded = read_field(bpy.data.objects.get(st.name), st.points.count,
                                state.resolution, res, budget, max_terms, occlusion, state.note)
            if loaded is not None and st.status == "ok":
                field = loaded
            elif st.status in ("missing", "unshadowed"):
                field = open_field(st.points.count, res)        # no shadows: exact, instant
            else:
                key = (st.name, id(st.bits), res, budget, max_terms, occlusion,
                       state.resolution)
                field = runtime.per_visibility(
                    _FIELD_CACHE, key, st.bits,
                    lambda: _field_from(derive_object(st.bits, st.points.normals, cube,
                                                      state.settings)), limit=8)
                if st.status == "ok":
                    derived_now.append(st.name)
            st.data["ssdf_sg"] = field
            LAST_TERMS.append(f"{st.name}: {field.terms} PCA terms, RMS {field.rms:.3f} rad, "
                              f"{field.occlusion_kept:.0%} of blocked directions kept")
            if field.occlusion_kept < OCCLUSION_KEPT_WARNING:
                faded.append(f"'{st.name}' {field.occlusion_kept:.0%} ({field.terms} terms)")
        if derived_now:
            state.note("SSDF_SG: SSDFs computed at draw time (precompute with SSDF_SG to "
                       "store them): " + ", ".join(derived_now))
        if LAST_TERMS:
            state.note("SSDF_SG PCA: " + "; ".join(LAST_TERMS))
        if faded:
            state.note("SSDF_SG: the PCA keeps only " + ", ".join(faded) + " of the blocked "
                       "directions: shadows of small occluders (a low sun's) fade; Min Occlusion "
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
            rad = shade_object(field.numpy, pts.normals, pts.positions, pts.materials,
                               object_sg_materials(st), state.world, fit, pre, eye, view_dir,
                               cosine=cosine_of(state.settings), lamps=state.lamps)
            out.append(rad[pts.point_of_corner].astype(np.float32))
        return out

    def draw_objects(self, state, eye, view_dir):
        """Per-pixel eq. 39 + 41 on the GPU (``shaders/ssdf_sg_*.glsl``); None (per-vertex
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
            state.note("SSDF_SG: scenes with lights are shaded per vertex (eq. 42-43; the "
                       "per-pixel shader draws the World only)")
            return None
        fields = []
        for st in state.objects:
            field = self._field(state, st)
            if field.terms + 1 > 4 * MAX_COEFF_TEXELS:
                return None
            fields.append(field)
        fit, pre = self._lighting(state)
        return gpu_draws(state, fields, fit, pre, eye, view_dir)


#: the fragment shader holds (1, w_1..w_K) in at most this many vec4
MAX_COEFF_TEXELS = 16
#: "object: K terms, RMS" lines of the last sync (panel)
LAST_TERMS: list = []
#: below this share of blocked directions kept by the PCA (core.ssdf.SSDFBasis.occlusion_kept)
#: the user is told that small occluders' shadows fade (the report scenes' grounds keep
#: 57-58 % at the RMS budget's 8 terms alone, ~80 % at 20-24, ~90 % at 48)
OCCLUSION_KEPT_WARNING = 0.75


class StoredField:
    """One object's PCA SSDF as loaded/derived: numpy evaluator + raw arrays for the GPU."""

    def __init__(self, basis_mean, eigen, coeffs, resolution, rms, precompute_id="",
                 occlusion_kept=1.0):
        self.mean = np.asarray(basis_mean, np.float32)
        self.eigen = np.asarray(eigen, np.float32)
        self.coefficients = np.asarray(coeffs, np.float32)
        self.resolution = int(resolution)
        self.rms = float(rms)
        self.occlusion_kept = float(occlusion_kept)   # see core.ssdf.SSDFBasis
        self.precompute_id = precompute_id
        self.numpy = ssdf_sg.PCAField(self.mean, self.eigen, self.coefficients, self.resolution)
        self.gpu = None          # textures, built by the GPU path

    @property
    def terms(self):
        return len(self.eigen)


def open_field(points, resolution):
    """The SSDF of a fully open hemisphere for every point (objects without visibility
    data): the elevation ``asin(z)`` of each texel (distance to the horizon), no PCA terms."""
    mean = np.arcsin(np.clip(ssdf.square_centres(resolution)[..., 2], 0.0, 1.0)).reshape(-1)
    D = resolution * resolution
    return StoredField(mean, np.zeros((4, D), np.float32), np.zeros((points, 4), np.float32),
                       resolution, 0.0)


def _field_from(result):
    basis, coeffs = result
    return StoredField(basis.mean, basis.eigen, coeffs, basis.resolution, basis.rms_error,
                       occlusion_kept=basis.occlusion_kept)


# ----------------------------------------------------------------- storage

def write_field(ob, basis, coeffs, cube_resolution):
    """Store the PCA SSDF of one object (float32, as it is drawn) with its settings."""
    storage.put(ob, BLOB, storage.pack(
        {"mean": np.asarray(basis.mean, np.float32).ravel(),
         "eigen": np.asarray(basis.eigen, np.float32),
         "coeffs": np.asarray(coeffs, np.float32)},
        {"ssdf_resolution": int(basis.resolution), "budget": float(basis.budget),
         "rms": float(basis.rms_error), "occlusion_kept": float(basis.occlusion_kept),
         "occlusion_target": float(basis.occlusion_target),
         "cube_resolution": int(cube_resolution)}))


def _stored_field(arrays, meta):
    """(meta, StoredField) of a stored ``ssdf_sg`` blob."""
    try:
        mean, eigen, coeffs = arrays["mean"], arrays["eigen"], arrays["coeffs"]
        res = int(meta["ssdf_resolution"])
        rms, kept = float(meta["rms"]), float(meta["occlusion_kept"])
    except (KeyError, TypeError, ValueError):
        raise storage.Unreadable("SSDF data incomplete") from None
    D = res * res
    if mean.shape != (D,) or eigen.ndim != 2 or eigen.shape[1] != D or \
            coeffs.ndim != 2 or coeffs.shape[1] != len(eigen):
        raise storage.Unreadable("SSDF data inconsistent")
    if not (np.isfinite(mean).all() and np.isfinite(eigen).all() and np.isfinite(coeffs).all()):
        raise storage.Unreadable("SSDF data not finite")
    return meta, StoredField(mean, eigen, coeffs, res, rms, occlusion_kept=kept)


_READ_CACHE: dict = drawing.gpu_cache({})    # fields read from the .blend (GPU textures too)


def read_field(ob, points, cube_resolution, resolution, budget, max_terms,
               occlusion_target=0.0, note=None):
    """The stored StoredField of ``ob``, or None when missing or made otherwise (other
    settings, point count or cube); ``note`` is told why stored data is unreadable."""
    got = storage.load(ob, BLOB, _READ_CACHE, _stored_field, note)
    if got is None:
        return None
    meta, field = got
    try:
        made = (int(meta["cube_resolution"]), float(meta["budget"]),
                float(meta["occlusion_target"]))
    except (KeyError, TypeError, ValueError):
        return None
    if (len(field.coefficients) != points or field.resolution != resolution
            or made[0] != cube_resolution or abs(made[1] - budget) > 1e-9
            or field.terms > max(max_terms, 4) + 3 or abs(made[2] - occlusion_target) > 1e-9):
        return None
    field.precompute_id = ob.prt.precompute_id          # the run its blob belongs to
    return field


# ----------------------------------------------------------------- GPU (per pixel)

_GPU = drawing.gpu_cache({})


_SAMPLERS = (("FLOAT_2D", "coeffTex"), ("FLOAT_2D_ARRAY", "eigenTex"), ("FLOAT_2D", "envTex"),
             ("FLOAT_2D", "lightTex"), ("FLOAT_2D", "paramTex"))


def _fragment_source(main: str) -> str:
    """sg_common.glsl (the SG algebra, BRDF factors and cube-face lookup shared with the
    material helpers' GLSL twin, tested against numpy there), ssdf_sg_lib.glsl, ``main``."""
    from ..drawing import SHADER_DIR
    return "".join((SHADER_DIR / name).read_text()
                   for name in ("sg_common.glsl", "ssdf_sg_lib.glsl", main))


def _gpu_shader(flat: bool = False):
    """The per-pixel shader; ``flat``: its variant for flat triangles (FLAT_PAIRS: eq. 39
    from the pair table, see :func:`pair_table`)."""
    import gpu
    name = "shader_flat" if flat else "shader"
    sh = _GPU.get(name)
    if sh is None:
        from ..drawing import SHADER_DIR
        info = gpu.types.GPUShaderCreateInfo()
        if flat:
            info.define("FLAT_PAIRS", "1")
        for kind, ident in (("MAT4", "viewProjection"), ("MAT3", "envRot"),
                            ("FLOAT", "closedSide")):
            info.push_constant(kind, ident)
        for slot, (kind, ident) in enumerate(_SAMPLERS + ((("FLOAT_2D", "pairTex"),) if flat
                                                         else ())):
            info.sampler(slot, kind, ident)
        inputs = (("VEC3", "pos"), ("VEC3", "nrm"), ("VEC3", "triPoints"), ("VEC3", "bary"))
        for slot, (kind, ident) in enumerate(inputs + ((("VEC3", "triFlat"),) if flat else ())):
            info.vertex_in(slot, kind, ident)
        iface = gpu.types.GPUStageInterfaceInfo("prt_ssdf_sg_flat_iface" if flat
                                                else "prt_ssdf_sg_iface")
        iface.smooth("VEC3", "vPos")
        iface.smooth("VEC3", "vNrm")
        iface.smooth("VEC3", "vBary")
        iface.flat("VEC3", "vTri")
        if flat:
            iface.flat("VEC3", "vFlat")
        info.vertex_out(iface)
        info.fragment_out(0, "VEC4", "fragColor")
        info.vertex_source((SHADER_DIR / "ssdf_sg_vert.glsl").read_text())
        info.fragment_source(_fragment_source("ssdf_sg_frag.glsl"))
        sh = _GPU[name] = gpu.shader.create_from_info(info)
    return sh


def _pairs_shader():
    """The pair pass (``shaders/ssdf_sg_pairs_frag.glsl``) over a full-screen quad."""
    import gpu
    sh = _GPU.get("pairs")
    if sh is None:
        info = gpu.types.GPUShaderCreateInfo()
        info.push_constant("MAT3", "envRot")
        info.push_constant("INT", "flatCount")
        for slot, (kind, ident) in enumerate(_SAMPLERS + (("FLOAT_2D", "flatTex"),)):
            info.sampler(slot, kind, ident)
        info.vertex_in(0, "VEC2", "ndc")
        info.fragment_out(0, "VEC4", "fragColor")
        info.vertex_source("void main() { gl_Position = vec4(ndc, 0.0, 1.0); }")
        info.fragment_source(_fragment_source("ssdf_sg_pairs_frag.glsl"))
        sh = _GPU["pairs"] = gpu.shader.create_from_info(info)
    return sh


def _texture(rgba, layers=0):
    import gpu
    flat = np.ascontiguousarray(rgba, dtype=np.float32).reshape(-1)
    buf = gpu.types.Buffer("FLOAT", flat.size, flat)
    if layers:
        h, w = rgba.shape[1:3]
        return gpu.types.GPUTexture((w, h), layers=layers, format="RGBA32F", data=buf)
    h, w = rgba.shape[:2]
    return gpu.types.GPUTexture((w, h), format="RGBA32F", data=buf)


def field_textures(field):
    """(coefficient texture, eigen-image array, texels per point) of a StoredField."""
    if field.gpu is None:
        K, D, n = field.terms, field.resolution ** 2, field.resolution
        kt = -(-(K + 1) // 4)
        weights = np.zeros((len(field.coefficients), kt * 4), np.float32)
        weights[:, 0] = 1.0
        weights[:, 1:K + 1] = field.coefficients
        total = len(weights) * kt
        rows = max(1, -(-total // 4096))
        data = np.zeros((rows * 4096, 4), np.float32)
        data[:total] = weights.reshape(-1, 4)
        images = np.zeros((kt * 4, D), np.float32)
        images[0] = field.mean
        images[1:K + 1] = field.eigen
        layers = images.reshape(kt, 4, n, n).transpose(0, 2, 3, 1)          # (kt, n, n, 4)
        field.gpu = (_texture(data.reshape(rows, 4096, 4)), _texture(layers, layers=kt), kt)
    return field.gpu


def environment_textures(fit, pre, cosine_lobes: int):
    """(prefiltered atlas texture, light-lobe texture, lobe count): the atlas is made
    once per pyramid, the small lobe texture per fit (a turned world re-solves the
    scene-fitted amplitudes, the pyramid stays).  Lobe texture row j: texel 0 = (axis,
    lam), texel 1 + m = the amplitude seen by cosine lobe m."""
    atlas = _GPU.get("atlas")
    if atlas is None or atlas[0] is not pre:
        atlas = _GPU["atlas"] = (pre, _texture(pre.atlas()))
    lights = _GPU.get("lights")
    if lights is None or lights[0] is not fit or lights[1] != cosine_lobes:
        axes, lam, mu = fit[:3]
        J = max(len(lam), 1)
        light = np.zeros((J, 1 + cosine_lobes, 4), np.float32)
        light[:len(lam), 0, :3] = axes
        light[:len(lam), 0, 3] = lam
        if len(lam):
            light[:len(lam), 1:, :3] = cosine_amplitudes(mu, cosine_lobes).transpose(1, 0, 2)
        lights = _GPU["lights"] = (fit, cosine_lobes, _texture(light), len(lam))
    return atlas[1], lights[2], lights[3]


def material_uniforms(material):
    """Push-constant values of one material slot (the CPU half of specular_lobes)."""
    m = sg_materials([material])[0]
    kd = np.asarray(sg_brdf.diffuse_albedo(m), np.float64).reshape(3) / np.pi
    lam, mu = sg_brdf.iso_ndf_sg(m.model, m.roughness)
    A, Bd, Bs = (np.asarray(x, np.float64).reshape(3) for x in sg_brdf.fresnel_coefficients(m))
    glossy = bool(np.any(np.asarray(m.specular) > 0) or np.any(np.asarray(m.metallic) > 0))
    model = {"COOK_TORRANCE": 0, "BLINN_PHONG": 0, "WARD": 1}.get(m.model, 2)
    return dict(kd=(*kd, 1.0), glossy=int(glossy), brdfModel=model,
                principled=int(m.fresnel == "PRINCIPLED"),
                roughness=float(np.asarray(m.roughness).reshape(-1)[0]),
                ior=float(np.asarray(m.ior).reshape(-1)[0]), ndfLambda=float(lam),
                ndfMu=float(mu), fresA=(*A, 0.0), fresBd=(*Bd, 0.0), fresBs=(*Bs, 0.0))


def parameter_texture(env, mat, res, kt, eye4, cosine):
    """The parameter texels read by ``read_parameters`` in ssdf_sg_frag.glsl: 9 scalars
    texels, then (count, sharpness) and (local direction, amplitude) per cosine lobe."""
    M = len(cosine.amplitudes)
    p = np.zeros((1, 10 + M, 4), np.float32)
    p[0, 8] = eye4
    p[0, 9] = (M, cosine.sharpness, 0.0, 0.0)
    p[0, 10:, :3] = cosine.directions
    p[0, 10:, 3] = cosine.amplitudes
    p[0, 0] = (env["envStrength"], env["lightCount"], res, kt)
    p[0, 1] = (env["envRes"], env["envLevels"], env["envLambdaFirst"], env["envRatio"])
    p[0, 2] = (env["envTop"], mat["glossy"], mat["brdfModel"], mat["principled"])
    p[0, 3] = (mat["roughness"], mat["ior"], mat["ndfLambda"], mat["ndfMu"])
    p[0, 4], p[0, 5], p[0, 6], p[0, 7] = mat["kd"], mat["fresA"], mat["fresBd"], mat["fresBs"]
    return _texture(p)


#: an object whose pair table would pass this many texels (256 MiB) is drawn without it
MAX_PAIR_TEXELS = 1 << 24
#: corner normals closer than this (per component) are "the same" for flat triangles
FLAT_TOLERANCE = 1e-6


def flat_triangles(arrays, points) -> np.ndarray:
    """Per triangle: whether its three corner normals and their shading points' normals
    are one normal (a plane's or a flat-shaded face's triangles), so that every eq. 39
    pair's product lobe is the same at its points and inside it."""
    tri = arrays.triangles
    cn = arrays.corner_normals[tri]                                       # (T, 3, 3)
    pn = points.normals[points.point_of_corner[tri]]
    first = cn[:, :1]
    return (np.all(np.abs(cn - first) <= FLAT_TOLERANCE, axis=(1, 2))
            & np.all(np.abs(pn - first) <= FLAT_TOLERANCE, axis=(1, 2)))


class ObjectBatches:
    """Per material slot the batches of one object: ``draws`` = [(slot, flat, batch)];
    ``flat_points`` the shading points of its flat triangles (pair table rows)."""

    def __init__(self, draws, flat_points):
        self.draws = draws
        self.flat_points = flat_points


def object_batches(st, field, use_flat: bool = True) -> ObjectBatches:
    """Per material slot: per-corner position, normal, triangle points, barycentrics -- the
    flat triangles (:func:`flat_triangles`) in a second batch for the FLAT_PAIRS shader
    with their points' rows in the pair table."""
    from gpu_extras.batch import batch_for_shader
    key = ("batches", st.name, st.fingerprint, use_flat)
    cache = field.__dict__.setdefault("_batches", {})
    if key in cache:
        return cache[key]
    arrays, pts = st.arrays, st.points
    tri = arrays.triangles
    corner = tri.reshape(-1)
    pos = arrays.positions[arrays.corner_verts[corner]].astype(np.float32)
    nrm = arrays.corner_normals[corner].astype(np.float32)
    tri_points = np.repeat(pts.point_of_corner[tri].astype(np.float32), 3, axis=0)
    bary = np.tile(np.eye(3, dtype=np.float32), (len(tri), 1))
    slots = arrays.corner_materials[tri[:, 0]]
    flat = flat_triangles(arrays, pts) if use_flat else np.zeros(len(tri), bool)
    flat_points = np.unique(pts.point_of_corner[tri[flat]])
    row = np.full(len(pts.normals), -1, np.int64)
    row[flat_points] = np.arange(len(flat_points))
    tri_flat = np.repeat(row[pts.point_of_corner[tri]].astype(np.float32), 3, axis=0)
    draws = []
    for slot in np.unique(slots):
        for is_flat in (False, True):
            sel = np.repeat((slots == slot) & (flat == is_flat), 3)
            if not sel.any():
                continue
            attrs = {"pos": np.ascontiguousarray(pos[sel]), "nrm": np.ascontiguousarray(nrm[sel]),
                     "triPoints": np.ascontiguousarray(tri_points[sel]),
                     "bary": np.ascontiguousarray(bary[sel])}
            if is_flat:
                attrs["triFlat"] = np.ascontiguousarray(tri_flat[sel])
            draws.append((int(slot), is_flat,
                          batch_for_shader(_gpu_shader(is_flat), "TRIS", attrs)))
    out = ObjectBatches(draws, flat_points)
    cache.clear()
    cache[key] = out
    return out


def pair_texels(cosine_lobes: int, light_count: int) -> int:
    """Texels per flat point in the pair table: ceil(P / 4) angles, then P (w, k)."""
    pairs = cosine_lobes * light_count
    return -(-pairs // 4) + pairs


def pair_table(st, field, flat_points, light_tex, param_tex, light_count, cosine_lobes,
               rotation):
    """Run the pair pass for the object's flat points: a GPUTexture (rows of 4096 texels,
    :func:`pair_texels` per point).  Eq. 39's per-pair work that a flat triangle's pixels
    share, done once per point."""
    import gpu
    import mathutils
    from gpu_extras.batch import batch_for_shader
    coeff_tex, eigen_tex, _ = field_textures(field)
    normals = st.points.normals[flat_points]
    count = len(flat_points)
    flat = np.zeros((max(1, -(-count // 4096)) * 4096, 4), np.float32)
    flat[:count, :3] = normals
    flat[:count, 3] = flat_points
    flat_tex = _texture(flat.reshape(-1, 4096, 4))
    total = count * pair_texels(cosine_lobes, light_count)
    rows = max(1, -(-total // 4096))
    sh = _pairs_shader()
    quad = _GPU.get("quad")
    if quad is None:
        quad = _GPU["quad"] = batch_for_shader(sh, "TRIS", {"ndc": [(-1, -1), (3, -1), (-1, 3)]})
    offscreen = gpu.types.GPUOffScreen(4096, rows, format="RGBA32F")
    try:
        with offscreen.bind():
            gpu.state.depth_test_set("NONE")
            gpu.state.blend_set("NONE")
            sh.bind()
            sh.uniform_float("envRot", mathutils.Matrix(rotation))
            sh.uniform_int("flatCount", count)
            sh.uniform_sampler("coeffTex", coeff_tex)
            sh.uniform_sampler("eigenTex", eigen_tex)
            sh.uniform_sampler("envTex", _GPU["atlas"][1])
            sh.uniform_sampler("lightTex", light_tex)
            sh.uniform_sampler("paramTex", param_tex)
            sh.uniform_sampler("flatTex", flat_tex)
            quad.draw(sh)
            fb = gpu.state.active_framebuffer_get()
            buf = fb.read_color(0, 0, 4096, rows, 4, 0, "FLOAT")
    finally:
        offscreen.free()
    buf.dimensions = 4096 * rows * 4
    # read back and uploaded again (once per lighting change): a plain texture outlives the
    # offscreen and may be drawn from the viewport's and the F12 render's GPU contexts
    return _texture(np.array(buf, dtype=np.float32).reshape(rows, 4096, 4))


# pair tables per (object, geometry, lighting): entries hold the field and the fit
_PAIR_TABLES: dict = drawing.gpu_cache({})


def gpu_draws(state, fields, fit, pre, eye, view_dir):
    """draw(view_projection) callables, one per object."""
    cosine = cosine_of(state.settings)
    M = len(cosine.amplitudes)
    env_tex, light_tex, light_count = environment_textures(fit, pre, M)
    world = state.world
    rot = [list(map(float, r)) for r in np.asarray(world.rotation, np.float64)]
    eye4 = ((*map(float, view_dir), 0.0) if view_dir is not None
            else (*map(float, eye), 1.0))
    env_common = dict(envStrength=float(world.strength), lightCount=int(light_count),
                      envRes=int(pre.resolution), envLevels=int(pre.n_levels),
                      envLambdaFirst=float(pre.lambda_first), envRatio=float(pre.ratio),
                      envTop=float(pre.lambdas[-2]))
    draws = []
    for st, field in zip(state.objects, fields):
        coeff_tex, eigen_tex, kt = field_textures(field)
        table = object_sg_materials(st)
        batches = object_batches(st, field, use_flat=bool(_diffuse_slots(st).any()))
        if len(batches.flat_points) * pair_texels(M, int(light_count)) > MAX_PAIR_TEXELS:
            batches = object_batches(st, field, use_flat=False)
        params = {slot: parameter_texture(env_common, material_uniforms(
                      table[slot] if 0 <= slot < len(table) else core_brdf.Material()),
                      field.resolution, kt, eye4, cosine) for slot in
                  sorted({slot for slot, _, _ in batches.draws})}
        pair_tex = None
        if len(batches.flat_points):
            key = (st.name, st.fingerprint, np.asarray(world.rotation).round(12).tobytes(),
                   cosine.sharpness, M, int(light_count))
            pair_tex = runtime.held(
                _PAIR_TABLES, key, (field, fit, batches),
                lambda: pair_table(st, field, batches.flat_points, light_tex,
                                   next(iter(params.values())), int(light_count), M, rot),
                limit=8)

        def draw(view_projection, batches=batches, params=params, coeff_tex=coeff_tex,
                 eigen_tex=eigen_tex, pair_tex=pair_tex, side=float(st.closed_side)):
            import mathutils
            for flat in (False, True):
                todo = [(slot, batch) for slot, f, batch in batches.draws if f == flat]
                if not todo:
                    continue
                sh = _gpu_shader(flat)
                sh.bind()
                sh.uniform_float("viewProjection", view_projection)
                sh.uniform_float("envRot", mathutils.Matrix(rot))
                sh.uniform_float("closedSide", side)
                sh.uniform_sampler("coeffTex", coeff_tex)
                sh.uniform_sampler("eigenTex", eigen_tex)
                sh.uniform_sampler("envTex", env_tex)
                sh.uniform_sampler("lightTex", light_tex)
                if flat:
                    sh.uniform_sampler("pairTex", pair_tex)
                for slot, batch in todo:
                    sh.uniform_sampler("paramTex", params[slot])
                    batch.draw(sh)

        draws.append(draw)
    return draws


register(SSDFSGMethod())
