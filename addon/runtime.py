"""What the render engine needs per frame, derived from the scene and stored results.

``FrameState.sync(depsgraph)`` exports the world and every visible mesh,
attaches the stored visibility (decoded once and cached), and caches the
view-independent diffuse sums per lighting.  ``FrameState.shade(eye)``
returns per-corner radiance for each object with the active method.
"""

from __future__ import annotations

import hashlib

import numpy as np

from ..core import brdf, directions, envmap, mesh as core_mesh, reference, sh, visibility
from . import scene_export, storage

#: What the last sync found wrong (shown in the panels; cheap to read in draw()).
LAST_MESSAGES: list = []
# Decoded visibility per (image name, precompute id, point count); small LRU.
_VIS_CACHE: dict = {}
_VIS_CACHE_MAX = 16
# View-independent diffuse sums per (object, visibility, lighting).
_IRRADIANCE_CACHE: dict = {}
# SH transfer vectors per (object, visibility, order).
_TRANSFER_CACHE: dict = {}
# SH lighting projectors per order (each caches its unrotated projection).
_SH_PROJECTORS: dict = {}
# Area-resampled environment per (world key, resolution).
_ENV_CACHE: dict = {}


def _env_key(world: envmap.WorldLighting, resolution: int):
    """Content key of the lighting (pixels hashed once per WorldLighting object)."""
    ident = getattr(world, "_content_key", None)
    if ident is None:
        img = world.image
        if img is None:
            ident = ("color",) + tuple(float(c) for c in world.color)
        else:
            ident = (img.shape, hashlib.sha1(np.ascontiguousarray(img).view(np.uint8)).hexdigest())
        world._content_key = ident
    return (ident, float(world.strength), world.rotation.round(9).tobytes(), resolution)


def environment_cubemap(world: envmap.WorldLighting, resolution: int) -> envmap.CubeLighting:
    key = _env_key(world, resolution)
    cube = _ENV_CACHE.get(key)
    if cube is None:
        cube = world.to_cubemap(resolution)
        _ENV_CACHE.clear()
        _ENV_CACHE[key] = cube
    return cube


def _per_visibility(cache: dict, key, bits, compute, limit: int = 64):
    """``cache[key]`` derived from ``bits`` (computed when missing).  An entry keeps
    its ``bits`` alive, so the ``id(bits)`` in ``key`` cannot be reused meanwhile."""
    entry = cache.get(key)
    if entry is None or entry[0] is not bits:
        if len(cache) >= limit:
            cache.pop(next(iter(cache)))
        entry = cache[key] = (bits, compute())
    return entry[1]


def stored_visibility(ob_orig, points: int, nbytes: int):
    """Decoded visibility bits of an object, or None if missing/unusable."""
    data = ob_orig.prt
    img = data.visibility
    if img is None or data.point_count != points:
        return None
    key = (img.name_full, data.precompute_id, points, nbytes)
    bits = _VIS_CACHE.get(key)
    if bits is None:
        try:
            bits = storage.read_visibility_image(img, points, nbytes)
        except (ValueError, RuntimeError):
            return None
        if len(_VIS_CACHE) >= _VIS_CACHE_MAX:
            _VIS_CACHE.pop(next(iter(_VIS_CACHE)))
        _VIS_CACHE[key] = bits
    return bits


def open_visibility(normals: np.ndarray, cube) -> np.ndarray:
    """Unshadowed visibility (every traced texel visible), for objects without data."""
    return np.packbits(visibility.hemisphere_mask(normals, cube), axis=1)


class ObjectState:
    __slots__ = ("name", "arrays", "points", "materials", "bits", "status", "irradiance",
                 "irradiance_key")

    def __init__(self, name, arrays, points, materials, bits, status):
        self.name = name
        self.arrays = arrays
        self.points = points
        self.materials = materials
        self.bits = bits
        self.status = status
        self.irradiance = None
        self.irradiance_key = None


class FrameState:
    """Scene data for drawing one or more frames."""

    def __init__(self):
        self.objects: list[ObjectState] = []
        self.world: envmap.WorldLighting | None = None
        self.warnings: list[str] = []
        self.error: str | None = None
        self.resolution = 32
        self.method = "REFERENCE"
        self.sh_order = 4
        self.background = None       # (world, GPU texture) cached by the engine

    # ------------------------------------------------------------------ sync
    def sync(self, depsgraph):
        scene = depsgraph.scene
        self.warnings = []
        self.error = None
        try:
            self.world = scene_export.export_world(scene, self.warnings)
        except scene_export.ExportError as exc:
            self.error = str(exc)
            self.world = envmap.WorldLighting(color=(0.0, 0.0, 0.0))
        self.resolution = scene.prt.precomputed_resolution or int(scene.prt.resolution)
        self.method = scene.prt.method
        self.sh_order = scene.prt.sh_order
        cube = directions.cubemap(self.resolution)
        nbytes = cube.size // 8
        objects = []
        missing, stale = [], []
        fingerprints = []
        skipped = []
        for ob in scene_export.visible_mesh_objects(depsgraph, skipped):
            arrays = scene_export.mesh_arrays(ob)
            if len(arrays.triangles) == 0:
                continue
            core_mesh.repair_normals(arrays)
            points = core_mesh.shading_points(arrays)
            fingerprint = core_mesh.fingerprint(arrays)
            fingerprints.append((ob.original.name, fingerprint))
            mats = scene_export.object_materials(ob, self.warnings)
            orig = ob.original
            data = orig.prt
            bits = None
            status = "ok"
            if data.visibility is not None and data.resolution == self.resolution:
                bits = stored_visibility(orig, points.count, nbytes)
                if bits is None:
                    status = "stale"
                elif data.fingerprint != fingerprint:
                    status = "stale"   # same topology: old data, correctly indexed
            else:
                status = "missing"
            if bits is None:
                bits = open_visibility(points.normals, cube)
            (stale if status == "stale" else missing if status == "missing" else []).append(
                orig.name)
            if data.coarse_warning and status == "ok":
                self.warnings.append(data.coarse_warning)
            objects.append(ObjectState(orig.name, arrays, points, mats, bits, status))
        self.warnings += scene_export.instance_warning(skipped)
        if missing:
            self.warnings.append("Not precomputed (drawn without shadows): " + ", ".join(missing))
        if stale:
            self.warnings.append("Changed since precompute (stale, press Precompute): "
                                 + ", ".join(stale))
        elif (scene.prt.scene_fingerprint and not missing
              and core_mesh.scene_fingerprint(fingerprints) != scene.prt.scene_fingerprint):
            self.warnings.append("Scene geometry changed since precompute (objects added, "
                                 "removed or moved): shadows are stale, press Precompute")
        self.objects = objects
        LAST_MESSAGES[:] = ([self.error] if self.error else []) + self.warnings

    @property
    def view_dependent(self) -> bool:
        """Whether shading changes with the camera (REFERENCE with glossy or layered
        materials); SH and diffuse-only scenes do not."""
        if self.method == "SH":
            return False
        return any(not m.is_diffuse_only or m.fresnel == "DIELECTRIC"
                   for st in self.objects for m in st.materials)

    # ------------------------------------------------------------------ shade
    def shade(self, eye, view_dirs_for=None):
        """Per-corner radiance (C, 3) float32 for each object.

        ``eye``: camera position for perspective views; ``view_dirs_for`` a unit
        direction toward an orthographic camera (then ``eye`` is ignored).
        """
        if self.method == "SH":
            return self._shade_sh(eye, view_dirs_for)
        cube = directions.cubemap(self.resolution)
        L = environment_cubemap(self.world, self.resolution)
        env_key = _env_key(self.world, self.resolution)
        out = []
        for st in self.objects:
            pts = st.points
            key = (st.name, id(st.bits), env_key)
            if st.irradiance is None or st.irradiance_key != key:
                st.irradiance = _per_visibility(
                    _IRRADIANCE_CACHE, key, st.bits,
                    lambda: reference.diffuse_irradiance(st.bits, pts.normals, cube, L))
                st.irradiance_key = key
            view_dirs = None
            if view_dirs_for is not None:
                view_dirs = np.broadcast_to(np.asarray(view_dirs_for, dtype=np.float64),
                                            pts.normals.shape)
            radiance = reference.shade_points(st.bits, pts.positions, pts.normals, pts.materials,
                                              st.materials, eye, cube, L,
                                              irradiance=st.irradiance, view_dirs=view_dirs)
            radiance = np.nan_to_num(radiance, nan=0.0, posinf=0.0, neginf=0.0)
            out.append(radiance[pts.point_of_corner])
        return out

    def _shade_sh(self, eye, view_dirs_for):
        """SH method: Lambert (and Principled base layer) radiance from transfer vectors."""
        order = int(self.sh_order)
        cube = directions.cubemap(self.resolution)
        projector = _SH_PROJECTORS.setdefault(order, sh.LightingProjector(order))
        light = projector.coefficients(self.world, _env_key(self.world, 0)[0])
        out = []
        glossy = []
        for st in self.objects:
            pts = st.points
            transfer = _per_visibility(
                _TRANSFER_CACHE, (st.name, id(st.bits), order), st.bits,
                lambda: sh.transfer(st.bits, pts.normals, cube, order))
            sums = sh.shade_diffuse(transfer, light)
            radiance = np.zeros_like(sums)
            for slot in np.unique(pts.materials):
                sel = np.nonzero(pts.materials == slot)[0]
                mat = st.materials[int(slot)] if 0 <= slot < len(st.materials) else brdf.Material()
                vd = None
                if mat.fresnel == "DIELECTRIC":
                    if view_dirs_for is not None:
                        vd = np.broadcast_to(np.asarray(view_dirs_for, np.float64), (len(sel), 3))
                    else:
                        vd = reference.view_directions(pts.positions[sel], eye)
                radiance[sel] = reference.lambert_layer(mat, sums[sel], pts.normals[sel], vd)
                if not mat.is_diffuse_only:
                    glossy.append(st.name)
            radiance = np.nan_to_num(radiance, nan=0.0, posinf=0.0, neginf=0.0)
            out.append(radiance[pts.point_of_corner])
        if glossy:
            note = ("SH draws diffuse transfer only; the glossy part of these materials is "
                    "left out: " + ", ".join(sorted(set(glossy))))
            if note not in self.warnings:
                self.warnings.append(note)
        return out
