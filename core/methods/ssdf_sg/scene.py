"""SSDF_SG on a scene (no bpy): the world's lighting as SGs, an object's per-point shading
(eq. 39 + 41, eq. 42 + 43 for lamps) and the scene-fitted lighting amplitudes.

* :func:`fit_environment` -- the diffuse SG fit of the world's image and its SG-prefiltered
  pyramid, both in texture space (no rotation, strength 1): a turned world or another
  strength changes neither (eq. 7: rotating an SG rotates its axis).
* :func:`world_sgs` -- that fit in world space for the world's rotation and strength.
* :func:`shade_points` -- per-point radiance of one object in numpy (what the GLSL pass
  draws per pixel; used per vertex, by tests and benches).
* The scene fit: the fit's diffuse lobes keep their axes and sharpnesses; their RGB
  amplitudes are solved again for the scene (:func:`scene_fit`: non-negative least
  squares of eq. 39's transfer with the SSDF visibility -- what is drawn -- against the
  exact shadowed irradiance at up to :data:`SCENE_FIT_POINTS` surface points drawn by
  area, :func:`fit_points`), so the error that reaches the image is the one minimised.
* :func:`flat_triangles` -- triangles on which every eq. 39 pair's product lobe is the
  same at the corners and inside (the GPU pass reads those from a per-point table).
"""

from __future__ import annotations

import numpy as np

from ...sphere import directions, envmap
from ..reference import shading as reference
from ...sg import algebra as sg, brdf as sg_brdf, lighting as sg_lighting
from ...sg import prefilter
from ...sg import albedo
from ...sg import lamp_lobes, reflectance
from . import ssdf
from ...scene import mesh as core_mesh
from ...shading.materials import slot_material
from .shading import COSINE_EQ40, diffuse_lobe_transfer, diffuse_transfer_per_cosine, lamp_radiance, specular_radiance

#: the diffuse SG fit reads the environment at this cubemap resolution (at least), so a
#: small sun gets a lobe about one 128-texel wide (sharpness ~1000) and a sharp shadow
FIT_CUBE_RESOLUTION = 128
#: scene points (drawn by surface area among the points with a diffuse part) at which
#: the diffuse lighting amplitudes are fitted
SCENE_FIT_POINTS = 1024
#: ridge of the scene fit toward the environment fit, per unknown per point (see scene_fit)
PRIOR_WEIGHT = 1e-3
#: corner normals closer than this (per component) are "the same" for flat triangles
FLAT_TOLERANCE = 1e-6


# --------------------------------------------------------------------------- lighting

def fit_environment(world: envmap.WorldLighting, resolution: int, max_lobes: int = 8,
                    fit_resolution: int = FIT_CUBE_RESOLUTION):
    """``((axes, lam, mu, rel), PrefilteredEnvironment)``: the diffuse SG fit of the
    world's image (``core.sg.lighting.fit_environment_sgs`` on a cubemap of at least
    ``fit_resolution``) and the SG-prefiltered pyramid of its ``resolution`` cubemap,
    without the world's rotation and strength (texture space)."""
    base = envmap.WorldLighting(image=world.image, color=world.color, strength=1.0)
    cube = directions.cubemap(resolution)
    radiance = np.asarray(base.to_cubemap(resolution).radiance, np.float64)
    fine = max(fit_resolution, resolution)
    fit_radiance = (radiance if fine == resolution
                    else np.asarray(base.to_cubemap(fine).radiance, np.float64))
    axes, lam, mu, rel = sg_lighting.fit_environment_sgs(
        fit_radiance, directions.cubemap(fine), max_lobes=max_lobes)
    return (axes, lam, mu, rel), prefilter.PrefilteredEnvironment(radiance, cube)


def cosine_amplitudes(mu, cosine_lobes: int) -> np.ndarray:
    """Amplitudes per (cosine lobe, light lobe) (M, J, 3): the scene fit's as they are,
    the environment fit's (J, 3) repeated for every cosine lobe."""
    mu = np.asarray(mu, np.float64)
    return mu if mu.ndim == 3 else np.broadcast_to(mu, (cosine_lobes,) + mu.shape)


def world_sgs(world: envmap.WorldLighting, fit):
    """The diffuse SG fit in world space: ``L(d) = s E(R d)`` has axes ``R^T a``
    (amplitudes (J, 3), or (M, J, 3) per cosine lobe from the scene fit)."""
    axes, lam, mu = fit[:3]
    return axes @ world.rotation, lam, mu * float(world.strength)


# --------------------------------------------------------------------------- materials

def sg_materials(materials) -> list:
    """SG materials (core.shading.brdf.Material converted, its Lambert part alone when its lobes
    are drawn per pixel elsewhere (``per_pixel_lobe``); SGMaterial passed through)."""
    out = []
    for m in materials:
        if not isinstance(m, reflectance.SGMaterial):
            sg = sg_brdf.sg_material_from_brdf(m)
            m = sg_brdf.without_glossy(sg) if m.per_pixel_lobe else sg
        out.append(m)
    return out


def is_glossy(material: reflectance.SGMaterial) -> bool:
    """Whether an SG material has a specular lobe drawn here (specular or metallic above 0,
    and its lobes not drawn elsewhere)."""
    return material.lobes and bool(np.any(np.asarray(material.specular) > 0)
                or np.any(np.asarray(material.metallic) > 0))


def diffuse_slots(sg_table) -> np.ndarray:
    """Per material slot: whether its SG material has a diffuse part (at least one slot:
    an empty table is Cycles' default surface)."""
    table = sg_materials(sg_table) or sg_materials([slot_material([], 0)])
    return np.array([bool(np.any(np.asarray(albedo.diffuse_albedo(m)) > 0)) for m in table])


# --------------------------------------------------------------------------- shading

def shade_points(field, normals, positions, materials_of_points, materials, world, fit, pre,
                 eye=None, view_dir=None, chunk=4096, cosine=COSINE_EQ40, lamps=()):
    """Per-point radiance (P, 3) by eq. 39 + 41, plus eq. 42 + 43 for Blender lamps
    (``core.sg.lighting.Lamp``, one SG each per point: eq. 32-33), in numpy.

    ``field``: the object's SSDFs (``core.methods.ssdf_sg.shading.PCAField``); ``materials`` per slot
    (core or SG materials, a point's slot through :func:`core.shading.brdf.slot_material`);
    ``fit``, ``pre``: :func:`fit_environment` (or the scene fit) of ``world``; ``eye``
    (perspective) or ``view_dir`` (unit, toward an orthographic camera)."""
    P = len(normals)
    out = np.zeros((P, 3))
    axes, lam, mu = world_sgs(world, fit)
    rot = world.rotation
    strength = float(world.strength)

    def env_lookup(d, lam_q):
        return (pre.lookup(d, lam_q, rotation=rot) * strength
                * sg.integral(lam_q)[:, None])

    table = sg_materials(materials)
    for slot in np.unique(materials_of_points):
        sel_all = np.nonzero(materials_of_points == slot)[0]
        mat = sg_materials([slot_material(table, slot)])[0]
        kd = albedo.diffuse_albedo(mat) / np.pi
        glossy = is_glossy(mat)
        for a in range(0, len(sel_all), chunk):
            sel = sel_all[a:a + chunk]
            n = normals[sel]
            t, b = ssdf.ssdf_frames(n)
            rd = diffuse_transfer_per_cosine(
                field, sel, n, axes, lam, cosine_amplitudes(mu, len(cosine.amplitudes)), t, b,
                cosine=cosine)
            v = reference.point_views(positions[sel], eye, view_dir)
            kd_o = kd * albedo.diffuse_view_ratio(mat, np.sum(n * v, axis=1))[:, None]
            out[sel] = rd * kd_o
            lobes = (None, None, None)
            if glossy:
                lobes = sg_brdf.specular_lobes(mat, n, v, cosine=cosine, cosine_frame=(t, b),
                                               horizon=True)
                out[sel] += specular_radiance(field, sel, n, *lobes, env_lookup, t, b,
                                              cosine=cosine)
            if lamps:
                la, ll, lm = lamp_lobes.lamp_sgs(lamps, positions[sel])
                out[sel] += lamp_radiance(field, sel, n, la, ll, lm, kd_o, *lobes, t, b,
                                          cosine=cosine)
    return np.nan_to_num(out, nan=0.0, posinf=0.0, neginf=0.0)


# --------------------------------------------------------------------------- scene fit

def diffuse_point_weights(arrays: core_mesh.MeshArrays, points: core_mesh.ShadingPoints,
                          diffuse: np.ndarray) -> np.ndarray:
    """Per shading point: the surface area it stands for where its slot has a diffuse
    part (``diffuse``: :func:`diffuse_slots`), else 0."""
    area = core_mesh.point_areas(arrays, points)
    return area * diffuse[np.clip(points.materials, 0, len(diffuse) - 1)]


def fit_points(weights, count: int = SCENE_FIT_POINTS, seed: int = 0) -> list:
    """``[(object index, rows (sorted), weights)]`` of the points the scene fit uses, from
    per-object point weights (:func:`diffuse_point_weights`): all points of positive
    weight (weights as they are) when there are at most ``count``, else ``count`` draws
    with probability proportional to weight (weights = how often each point was drawn).
    Objects without a point are left out; [] when every weight is 0."""
    per = [np.asarray(w, np.float64) for w in weights]
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


def fit_scene_lobes(transfer, irradiance, weights, mu):
    """The scene fit's algebra: ``(scene amplitudes (M, J, 3), weighted rel-L2 error of
    the environment amplitudes, error after)`` from eq. 39's per-(cosine lobe, light
    lobe) transfer at the points ``transfer`` (S, M, J), the exact irradiance there per
    unit strength ``irradiance`` (S, 3), point weights (S,) and the environment fit's
    amplitudes ``mu`` (J, 3) or (M, J, 3).  One RGB amplitude per (cosine lobe, light
    lobe): each lobe of the clamped-cosine mixture gets its own mix of the same light
    lobes (same per-pixel cost), with a ridge toward ``mu`` that fades as the points
    outnumber the unknowns (:data:`PRIOR_WEIGHT`), so an object with few points stays
    determined (docs/measurements.md, scene-fitted amplitudes)."""
    T = np.asarray(transfer, np.float64)
    E = np.asarray(irradiance, np.float64)
    W = np.asarray(weights, np.float64)
    S, M, J = T.shape
    T = T.reshape(S, M * J)
    prior = cosine_amplitudes(mu, M).reshape(M * J, 3)
    scene_mu = sg_lighting.fit_scene_amplitudes(
        T, E, W, prior=prior, prior_weight=PRIOR_WEIGHT * M * J / S).reshape(M, J, 3)
    sw = np.sqrt(W)[:, None]
    norm = max(float(np.linalg.norm(E * sw)), 1e-300)
    before = float(np.linalg.norm((T @ prior - E) * sw)) / norm
    after = float(np.linalg.norm((T @ scene_mu.reshape(M * J, 3) - E) * sw)) / norm
    return scene_mu, before, after


def scene_fit(fit, cosine, samples, world: envmap.WorldLighting, cube, lighting):
    """The diffuse SG fit with its RGB amplitudes solved for a scene at the world's
    rotation: same form as ``fit`` (texture-space axes, amplitudes for strength 1, now
    (M, J, 3)), plus ``(error with the environment amplitudes, error after, points)``.

    ``samples``: per object with fitted points ``(field, rows, normals, visibility bits,
    weights)`` of those points (:func:`fit_points`); ``cube``/``lighting``: the cubemap
    and the world resampled to it (``lighting`` as drawn: rotated, with its strength),
    for the exact shadowed irradiance (``core.methods.reference.shading.diffuse_irradiance``)."""
    axes, lam, mu, rel = fit[:4]
    strength = float(world.strength)
    axes_w = sg_lighting.rotate_to_world(axes, world.rotation)
    T, E, W = [], [], []
    for field, rows, normals, bits, weights in samples:
        T.append(diffuse_lobe_transfer(field, rows, normals, axes_w, lam, cosine=cosine,
                                       per_cosine=True))
        E.append(reference.diffuse_irradiance(bits, normals, cube, lighting) / strength)
        W.append(weights)
    T, E, W = np.concatenate(T), np.concatenate(E).astype(np.float64), np.concatenate(W)
    scene_mu, before, after = fit_scene_lobes(T, E, W, mu)
    return (axes, lam, scene_mu, rel, (before, after, len(W)))


# --------------------------------------------------------------------------- flat triangles

def flat_triangles(arrays: core_mesh.MeshArrays, points: core_mesh.ShadingPoints) -> np.ndarray:
    """Per triangle: whether its three corner normals and their shading points' normals
    are one normal (a plane's or a flat-shaded face's triangles), so that every eq. 39
    pair's product lobe is the same at its points and inside it."""
    tri = arrays.triangles
    cn = arrays.corner_normals[tri]                                       # (T, 3, 3)
    pn = points.normals[points.point_of_corner[tri]]
    first = cn[:, :1]
    return (np.all(np.abs(cn - first) <= FLAT_TOLERANCE, axis=(1, 2))
            & np.all(np.abs(pn - first) <= FLAT_TOLERANCE, axis=(1, 2)))
