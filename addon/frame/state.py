"""What the render engine needs per frame, derived from the scene and stored results.

``FrameState.sync(depsgraph)`` exports the world and every visible mesh,
attaches the stored visibility (decoded once and cached), and caches the
view-independent diffuse sums per lighting.  ``FrameState.shade(eye)``
returns per-corner radiance for each object with the active method.
"""

from __future__ import annotations

import contextlib
import copy
from dataclasses import replace

import numpy as np

from ...core.methods.reference import shading as reference
from ...core.shading import brdf as core_brdf
from ...core.shading.materials import slot_material
from ...core.transport import bounce as core_bounce
from ...core.sphere import directions, envmap
from ...core.pipeline import frame_status
from ...core.scene import mesh as core_mesh, textures, visibility
from . import bounce, dynamic, keys
from . import sources
from .. import methods
from ..blender import scene_export, storage, surfaces, texture_export
from ...core.common import codec
from ...core.common.parallel import Cancelled  # noqa: F401  (raised by FrameState.tick)

#: What the last sync found wrong (shown in the panels; cheap to read in draw()).
LAST_MESSAGES: list = []
# Decoded visibility per stored blob (storage.key), the only copy a frame holds: an object
# keeps its compressed blob and decodes it through here when read, so a thousand instances
# hold at most 128 decoded at once, and 256 MiB (the newest one whatever its size)
VIS_CACHE = keys.cache(128, max_bytes=256 * 2**20)


class StoredBits:
    """An object's stored visibility, read without bpy (the viewport shades in a worker
    thread): its compressed blob, taken on the main thread at the sync, decoded when read
    and kept in :data:`VIS_CACHE` (bounded), not by the object."""
    __slots__ = ("key", "blob")

    def __init__(self, key, blob: bytes):
        self.key, self.blob = key, blob

    def __call__(self) -> np.ndarray:
        return keys.held(VIS_CACHE, self.key, (),
                         lambda: codec.unpack(self.blob))[0]["bits"]


def stored_visibility(ob_orig, points: int, nbytes: int, note=None):
    """A :class:`StoredBits` of an object's visibility, or None if missing/unusable
    (``note`` is told why a stored blob cannot be read)."""
    if ob_orig.prt.point_count != points:
        return None
    k = storage.key(ob_orig, storage.VISIBILITY)
    stored = storage.load(ob_orig, storage.VISIBILITY, VIS_CACHE, note=note)
    bits = None if stored is None else stored[0].get("bits")
    if bits is None or bits.shape != (points, nbytes):
        return None
    return StoredBits(k, storage.blob(ob_orig, storage.VISIBILITY))


def open_visibility(normals: np.ndarray, cube) -> np.ndarray:
    """Unshadowed visibility (every traced texel visible), for objects without data."""
    return np.packbits(visibility.hemisphere_mask(normals, cube), axis=1)


def _traced_objects(scene, run: str) -> int:
    """How many of the scene's objects and instances that renders show carry the
    precompute ``run`` (objects hidden in the viewport count: they still render)."""
    shown = [ob for ob in scene.objects if not ob.hide_render]
    return (sum(1 for ob in shown if ob.type in scene_export.GEOMETRY_TYPES
                and ob.prt.precompute_id == run)
            + sum(1 for ob in shown for r in storage.instance_records(ob)
                  if r.prt.precompute_id == run))


# core.scene.mesh.closed_side per geometry fingerprint (a cheap key: every sync exports anew)
_CLOSED_SIDE = keys.cache(256)


def closed_side(arrays, fingerprint: str) -> int:
    return keys.held(_CLOSED_SIDE, fingerprint, (), lambda: core_mesh.closed_side(arrays))


class TexturedRadiance(np.ndarray):
    """Per-corner radiance (C, 3) with the mean colour of its textured slots (what every
    consumer of plain radiance gets), plus ``diffuse`` (C, 3), the part a slot's colour
    texture multiplies per pixel, and ``specular`` (C, 3), the rest."""

    diffuse = None
    specular = None

    @classmethod
    def of(cls, radiance, diffuse, specular):
        out = np.asarray(radiance).view(cls)
        out.diffuse = np.asarray(diffuse, np.float32)
        out.specular = np.asarray(specular, np.float32)
        return out


def _per_corner(slots: dict, corners):
    """Per-slot exported values read per corner (UVs, colours, tangents: arrays of one row
    per corner of the mesh's own) at every corner of a two-sided mesh (``corners``:
    core.scene.mesh.corner_source; None: the mesh's own corners only)."""
    if corners is None:
        return slots

    def extend(v):
        if isinstance(v, np.ndarray) and v.ndim >= 1 and len(v) * 2 == len(corners):
            return v[corners]
        if isinstance(v, tuple):
            return tuple(extend(x) for x in v)
        if isinstance(v, dict):
            return {k: extend(x) for k, x in v.items()}
        return v
    return {slot: extend(v) for slot, v in slots.items()}


def _with_base(state, value: float):
    """``state`` (a shallow copy) whose objects' textured slots have base colour ``value``."""
    sub = copy.copy(state)
    sub.objects = []
    for st in state.objects:
        twin = copy.copy(st)
        twin.data = st.data
        twin.materials = [replace(m, diffuse_albedo=(value, value, value))
                          if textured else m
                          for m, textured in zip(st.materials, _textured_slots(st))]
        sub.objects.append(twin)
    return sub


def _textured_slots(st) -> list[bool]:
    """Per entry of ``st.materials``: whether its slot has a colour texture."""
    return [st.slot_of[k] in st.textures for k in range(len(st.materials))]


def _textured_mean(st) -> np.ndarray:
    """(C, 3) per corner of ``st``: the base colour of its slot where that slot is textured
    (the texture's mean colour, what plain radiance is shaded with), else 0."""
    pts = st.points
    count = max(len(st.materials), 1)
    colours = np.zeros((count, 3), np.float32)
    for k, (m, textured) in enumerate(zip(st.materials, _textured_slots(st))):
        if textured:
            colours[k] = m.diffuse_albedo
    # the index clamped into the slots, as core.shading.materials.slot_material does
    index = np.clip(np.asarray(pts.materials, np.int64), 0, count - 1)[pts.point_of_corner]
    return colours[index]


class ObjectState:
    __slots__ = ("name", "arrays", "points", "materials", "_bits", "_stored", "_pose", "status",
                 "data", "fingerprint", "closed_side", "textures", "inputs", "normals", "slot_of",
                 "dynamic", "bounce", "matrix", "shape", "near", "source", "local_source")

    def __init__(self, name, arrays, points, materials, bits, status, fingerprint=""):
        self.name = name
        #: core.scene.mesh.fingerprint of ``arrays`` (what caches of derived geometry key on:
        #: every sync exports new arrays)
        self.fingerprint = fingerprint
        self.arrays = arrays
        self.points = points
        self.materials = materials
        self._pose = None
        self._stored = None
        if isinstance(bits, StoredBits):
            self._bits, self._stored = None, bits
        else:
            self.bits = bits
        #: "ok", "stale" (changed since its precompute), "missing" (never precomputed),
        #: "unshadowed" (hidden from renders, drawn in the viewport only, never traced) or
        #: "posed" (its bits are the product with dynamic objects' fields: addon.frame.dynamic)
        self.status = status
        #: a dynamic object's stored fields and motion since the precompute (addon.frame.dynamic)
        self.dynamic = None
        #: the geometry up to a dynamic object's rigid motion (its precompute's fingerprint;
        #: ``fingerprint`` for the others): what a choice that survives motion keys on
        self.shape = fingerprint
        #: the dynamic objects whose fields reach this one now (addon.frame.dynamic.apply)
        self.near = []
        self.data = {}               # per-method data loaded in Method.sync
        #: core.scene.mesh.closed_side: which side of a closed mesh is its (black) inside
        self.closed_side = closed_side(arrays, fingerprint) if fingerprint else 0
        #: {slot: (core.scene.textures.ColorSource, per-corner UVs or colours)}: the slots whose
        #: colour varies per pixel (addon.blender.texture_export)
        self.textures = {}
        #: {slot: {input: (core.scene.textures.ScalarSource, per-corner UVs or colours)}} and
        #: {slot: Principled constants}: textured scalar inputs (roughness, metallic, ...)
        self.inputs = ({}, {})
        #: {slot: (core.scene.textures.NormalSource, per-corner UVs (C, 2), per-corner world
        #: tangents and bitangent signs (C, 4))}: normal- or bump-mapped slots (drawn per
        #: pixel by the sources' pass and SSDF_SG; the per-vertex transport ignores them)
        self.normals = {}
        #: the material slot of each entry of ``materials`` (per-point variants of
        #: textured scalar inputs follow the slots, core.scene.textures.point_variants)
        self.slot_of = np.arange(len(materials))
        #: the stored bounce transfer of its precompute (addon.frame.bounce.stored_rows)
        self.bounce = None
        #: its world matrix (4x4; an instance's placed by its instancer)
        self.matrix = np.eye(4)
        #: an instance's source as the lights pass shares it, and whatever its sides
        self.source = self.local_source = None       # (SharedArrays.source, .local_source)

    @property
    def bits(self):
        """Visibility bits (P, 6N²/8): stored (decoded through a bounded cache, not held
        here), or their product with the fields of the dynamic objects near (made when
        first read and held: RSL reads the fields instead)."""
        if self._pose is not None:
            make, self._pose = self._pose, None
            self._bits, self._stored = make(), None
        return self.stored_bits()

    @bits.setter
    def bits(self, value):
        self._bits, self._stored, self._pose = value, None, None

    def stored_bits(self):
        """The bits as stored (or as set); once a posed product is made (:attr:`bits`),
        that product."""
        return self._stored() if self._stored is not None else self._bits

    def pose(self, make):
        """The bits become ``make()`` when next read (addon.frame.dynamic)."""
        self._pose = make


class FrameState:
    """Scene data for drawing one or more frames."""

    def __init__(self):
        self.objects: list[ObjectState] = []
        #: the lighting the methods shade: the world less its compact sources
        self.world: envmap.WorldLighting | None = None
        #: the world as exported (the background, the per-pixel sharp lobes)
        self.full_world: envmap.WorldLighting | None = None
        #: addon.gpu.lights.DrawnSource of the world's compact sources (drawn per pixel)
        self.sources: list = []
        self.drawn_lamps: list = []  # core.sg.lighting.Lamp drawn per pixel (addon/gpu/lights.py)
        self.warnings: list[str] = []
        #: the warnings of the objects, lamps and method data (:meth:`relit` keeps them)
        self.object_warnings: list[str] = []
        self.error: str | None = None
        self.resolution = 32
        self.method = "REFERENCE"
        self.settings: dict = {}     # scene.prt values of every method's settings
        self.lamps: list = []        # core.sg.lighting.Lamp the method draws itself (SSDF_SG)
        self.background = None       # (world, GPU texture) cached by the engine
        #: the frame's bounced light (addon.frame.bounce.FrameBounce), None: direct only
        self.bounce = None
        #: the light group of the World and of each compact source (addon.frame.passes)
        self.world_group = "World"
        self.source_groups: list[str] = []
        #: the World is muted (a light group pass without it): its part of the frame is zero
        self.world_muted = False
        #: the camera of the frame being drawn (set by the engine before shading):
        #: dict(clip=4×4 world-to-clip, width, height, eye, view_dir), or None
        self.camera: dict | None = None
        #: the frame being drawn is all that shading serves (engine.render_pixels): a
        #: method may leave out points the camera cannot see (:meth:`seen_points`)
        self.visible_only = False
        #: :meth:`seen_points` per object's points, once per camera (parts and twins share)
        self._seen_memo: dict = {}
        #: the whole frame's state when this one shades a part of its objects (:meth:`shade`:
        #: the untextured objects, the textured ones at base colour white and black): what a
        #: stored AUTO choice is checked against; None for the whole frame itself
        self.whole = None
        #: set by F12 (engine.render): ``progress(fraction)`` reports 0..1 of the frame,
        #: ``cancelled()`` is true once the user pressed ESC (see :meth:`tick`)
        self.progress = None
        self.cancelled = None
        #: the part of the frame's progress that ticks now report in (:meth:`span`)
        self._span = (0.0, 1.0)

    # ------------------------------------------------------------------ progress
    def tick(self, fraction=None):
        """Called between objects and chunks of work (methods, AUTO, the sync): raises
        :class:`Cancelled` when the frame was stopped (ESC), reports ``fraction`` of the
        current :meth:`span` when given.  Costs nothing without hooks (the viewport)."""
        if self.cancelled is not None and self.cancelled():
            raise Cancelled()
        if self.progress is not None and fraction is not None:
            lo, hi = self._span
            self.progress(lo + (hi - lo) * min(max(float(fraction), 0.0), 1.0))

    @contextlib.contextmanager
    def span(self, lo: float, hi: float):
        """Ticks inside report within ``[lo, hi]`` of the current span."""
        outer = self._span
        a, b = outer
        self._span = (a + (b - a) * lo, a + (b - a) * hi)
        try:
            yield self
        finally:
            self._span = outer

    # ------------------------------------------------------------------ sync
    def sync(self, depsgraph):
        """Read the whole scene: its objects, lamps and method data, then the World's part
        (:meth:`_sync_lighting`)."""
        scene = depsgraph.scene
        self.warnings = []
        self.error = None
        self.resolution = scene.prt.precomputed_resolution or int(scene.prt.resolution)
        self.method = scene.prt.method
        self.settings = {name: getattr(scene.prt, name) for name in methods.scene_properties()}
        cube = directions.cubemap(self.resolution)
        nbytes = cube.size // 8
        objects = []
        notes = frame_status.SyncNotes()
        shown_only = [] if depsgraph.mode != "RENDER" else None
        found = surfaces.scene_surfaces(depsgraph, shown_only)
        run = scene.prt.precompute_id
        listed = found + (shown_only or [])
        shared = surfaces.SharedArrays()
        coarse = []                    # (tessellation note, surfaces.note_group)
        for i, surface in enumerate(listed):
            self.tick(i / len(listed))          # F12's progress; ESC stops here
            ob, orig = surface.ob, surface.owner
            arrays = shared.arrays(surface)
            if len(arrays.triangles) == 0:
                continue
            if not isinstance(arrays, core_mesh.PlacedArrays):   # those repair as read
                core_mesh.repair_normals(arrays)
            if orig.prt.back_sides and not surface.hidden:
                arrays = core_mesh.with_back_sides(arrays)    # as its precompute traced it
            corners = core_mesh.corner_source(arrays) if arrays.two_sided else None
            points = shared.shared_points(surface, core_mesh.shading_points(arrays))
            fingerprint = core_mesh.fingerprint(arrays)
            # textured colour inputs: their mean colour in the material, drawn per pixel
            textured = _per_corner(texture_export.slot_sources(ob, self.warnings), corners)
            colours = {slot: texture_export.mean_albedo(src, values)
                       for slot, (src, values) in textured.items()}
            scalars = _per_corner(texture_export.slot_scalars(ob, self.warnings), corners)
            means = {slot: texture_export.mean_scalars(inputs)
                     for slot, inputs in scalars.items()}
            # lobes too narrow for the cubemap are drawn per pixel (addon/gpu/sharp.py)
            mats = [core_brdf.with_sharp_lobe(m, self.resolution)
                    for m in scene_export.object_materials(ob, self.warnings, colours, means)]
            data = orig.prt
            bits = None
            status = "ok"
            moving = None
            unreadable = False
            if surface.hidden:
                status = "unshadowed"          # viewport only: never traced, casts nothing
            elif storage.has(orig, storage.VISIBILITY) and data.resolution == self.resolution:
                why = []
                bits = stored_visibility(orig, points.count, nbytes, why.append)
                if why:                        # drawn like an object without data
                    status, unreadable = "missing", True
                    notes.unreadable += why
                else:
                    status = frame_status.stored_status(
                        bits is not None, data.dynamic or storage.has(orig, storage.SHADOW_FIELD),
                        data.fingerprint == fingerprint)
                    if status == "dynamic":
                        status, moving = dynamic.check(orig, surface.matrix, arrays.positions,
                                                       self.note)
                    elif status == "ok" and run and data.precompute_id != run:
                        notes.earlier.append(surface.name)
            else:
                status = "missing"
            if bits is None:
                bits = open_visibility(points.normals, cube)
            if not unreadable:
                notes.add(surface.name, status, status == "missing" and storage.legacy(orig))
            if data.coarse_warning and status == "ok":
                coarse.append((data.coarse_warning, surfaces.note_group(surface)))
            st = ObjectState(surface.name, arrays, points, mats, bits, status, fingerprint)
            st.textures = textured
            st.matrix = surface.matrix
            st.source = shared.source(surface, arrays)
            st.local_source = shared.local_source(surface)
            st.normals = _per_corner(texture_export.slot_normals(ob, self.warnings,
                                                                 surface.matrix), corners)
            if status == "ok" and moving is None:
                st.bounce = bounce.stored_rows(orig, points.count, self.note)
            st.dynamic = moving if status == "ok" else None
            if st.dynamic is not None:
                st.shape = data.fingerprint
            if scalars:
                # per-vertex methods: each point's values, as material variants
                constants = {slot: texture_export.principled_constants(
                    ob.material_slots[slot].material) for slot in scalars}
                per_point = {slot: {name: textures.point_values(
                    scalar, values, points.point_of_corner, points.count)
                    for name, (scalar, values) in inputs.items()}
                    for slot, inputs in scalars.items()}
                variants, point_mat, st.slot_of = textures.point_variants(
                    mats, points, per_point, constants)
                variants = [core_brdf.with_sharp_lobe(m, self.resolution) for m in variants]
                # a slot's lobes are drawn by one pass: all per pixel (addon/sharp.py, at
                # each pixel's roughness) once any of its points' lobes is too narrow
                sharp = {int(st.slot_of[i]) for i, m in enumerate(variants) if m.per_pixel_lobe}
                st.materials = [replace(m, per_pixel_lobe=True) if st.slot_of[i] in sharp
                                else m for i, m in enumerate(variants)]
                st.points = replace(points, materials=point_mat)
                st.inputs = (scalars, constants)
            # the original material per slot, for methods with their own material settings
            st.data["material_names"] = [
                slot.material.original.name if slot.material is not None else None
                for slot in ob.material_slots] or [None]
            objects.append(st)
        self.warnings += frame_status.grouped_notes(coarse)
        self.warnings += notes.messages(
            bool(run) and _traced_objects(scene, run) < scene.prt.precomputed_objects)
        self.objects = objects
        dynamic.apply(self)       # the fields at the current poses (before methods sync)
        lamp_warnings = []
        lamps = scene_export.export_lamps(depsgraph, lamp_warnings)
        # lamps are drawn per pixel (addon/gpu/lights.py), except the point and spot lamps of a
        # method set to draw them itself (SSDF_SG's spherical Gaussians, eq. 32-33)
        own = self.method_impl.draws_lamps(self.settings)
        mine = ("POINT", "SPOT") if own else ()
        self.lamps = [lamp for lamp in lamps if lamp.kind in mine]
        self.drawn_lamps = [lamp for lamp in lamps if lamp.kind not in mine]
        self.warnings += lamp_warnings
        self.method_impl.sync(self)
        self.bounce = bounce.FrameBounce.of(self, scene_export.light_bounces(scene))
        self.object_warnings = list(self.warnings)
        self._sync_lighting(depsgraph)

    def _sync_lighting(self, depsgraph):
        """The World's part of the state, all an HDRI turn changes: its lighting, its
        compact sources and light groups, and the shadow maps' budget (sources and lamps)."""
        scene = depsgraph.scene
        try:
            self.world = scene_export.export_world(scene, self.warnings)
        except scene_export.ExportError as exc:
            self.error = str(exc)
            self.world = envmap.WorldLighting(color=(0.0, 0.0, 0.0))
        # the compact sources are drawn per pixel (addon/gpu/lights.py); methods shade the rest
        self.full_world = self.world
        self.world, self.sources = sources.split_world(self.world,
                                                      sources.extraction_settings(scene.prt))
        self.world_group, self.source_groups = scene_export.world_groups(
            scene, depsgraph.view_layer, len(self.sources))
        # every source and lamp is drawn; the panel and the log say what the shadow maps'
        # budget changed (smaller tiles; past it, no shadow)
        self.warnings += sources.shadow_plan(
            list(self.sources) + sources.lamp_sources(self.drawn_lamps)).messages
        LAST_MESSAGES[:] = ([self.error] if self.error else []) + self.warnings

    def relit(self, depsgraph) -> "FrameState":
        """A new state for a change of the World alone (an HDRI turned, its strength
        dragged; core.pipeline.frame_status.world_only): this state's objects, lamps and
        method data (nothing of theirs depends on the World), the World read again.  The
        old state is left as it was (a shading worker may still be reading it)."""
        new = copy.copy(self)
        new.objects = list(self.objects)
        new.lamps, new.drawn_lamps = list(self.lamps), list(self.drawn_lamps)
        new.warnings = list(self.object_warnings)
        new.error = None
        new.camera = None
        new.visible_only = False
        new._seen_memo = {}
        new.progress = new.cancelled = None
        new._span = (0.0, 1.0)
        new._sync_lighting(depsgraph)
        return new

    def note(self, message: str):
        """Add a warning for the panels/status bar once (methods call this while shading)."""
        if message not in self.warnings:
            self.warnings.append(message)
            LAST_MESSAGES[:] = ([self.error] if self.error else []) + self.warnings

    @property
    def method_impl(self):
        return methods.get(self.method).shading

    @property
    def view_dependent(self) -> bool:
        """Whether shading changes with the camera (e.g. REFERENCE with glossy or
        layered materials); SH and diffuse-only scenes do not."""
        return self.method_impl.view_dependent(self)

    def seen_points(self, st) -> np.ndarray | None:
        """(P,) bool of ``st``'s points the frame's camera may see
        (core.scene.mesh.seen_points), or None (all) unless :attr:`visible_only`."""
        cam = self.camera
        if not self.visible_only or cam is None:
            return None
        memo, key = self._seen_memo, (id(st.arrays), id(st.points), st.closed_side)
        if memo.get("camera") is not cam:
            memo.clear()
            memo["camera"] = cam
        got = memo.get(key)
        if got is None or got[0] is not st.arrays or got[1] is not st.points:
            seen = core_mesh.seen_points(st.arrays, st.points, cam["clip"], st.closed_side,
                                         cam["eye"], cam["view_dir"])
            seen.flags.writeable = False                # shared by the frame's passes
            got = memo[key] = (st.arrays, st.points, seen)
        return got[2]

    # ------------------------------------------------------------------ shade
    def shade(self, eye, view_dirs_for=None):
        """Per-corner radiance (C, 3) float32 for each object, by the active method.

        ``eye``: camera position for perspective views; ``view_dirs_for`` a unit
        direction toward an orthographic camera (then ``eye`` is ignored).
        """
        textured = [i for i, st in enumerate(self.objects) if st.textures]
        plain = [i for i, st in enumerate(self.objects) if not st.textures]
        out = [None] * len(self.objects)
        if plain:
            shaded = self._method_shade(self._part(plain), eye, view_dirs_for)
            if shaded is None:                 # the method draws per pixel
                return None
            for i, r in zip(plain, shaded):
                out[i] = r
        if textured:
            # Radiance is linear in a slot's base colour (Lambert base, metal F0): shaded
            # with white and with black, their difference is what the texture multiplies
            # per pixel, and black + mean colour x difference is the radiance at the
            # textured slots' mean colours (not shaded a third time)
            sub = self._part(textured)
            white_radiance = self._method_shade(_with_base(sub, 1.0), eye, view_dirs_for)
            if white_radiance is None:
                return None
            black = self._method_shade(_with_base(sub, 0.0), eye, view_dirs_for)
            for i, w, b in zip(textured, white_radiance, black):
                diff = np.asarray(w) - np.asarray(b)
                out[i] = TexturedRadiance.of(
                    (np.asarray(b) + _textured_mean(self.objects[i]) * diff).astype(np.float32),
                    diff, b)
        if self.bounce is not None:
            # the bounce reaches every receiver (addon.frame.bounce)
            for i, (b, white, glossy) in enumerate(self.bounced_radiance(eye, view_dirs_for)):
                if b is None:
                    continue
                r = out[i]
                if isinstance(r, TexturedRadiance):
                    out[i] = TexturedRadiance.of(np.asarray(r) + b, r.diffuse + white,
                                                 r.specular + glossy)
                else:
                    out[i] = np.asarray(r) + b
        return out

    def _part(self, indices) -> "FrameState":
        """A shallow copy holding the objects at ``indices``, a part of this frame
        (:attr:`whole`)."""
        sub = copy.copy(self)
        sub.objects, sub.whole = [self.objects[i] for i in indices], self
        return sub

    def _method_shade(self, state, eye, view_dirs_for):
        """The method's per-corner radiance of ``state``; zero without computing it when
        the World is muted and the method draws no lit lamp of its own (a light group pass:
        a per-vertex method's radiance is the World's light alone)."""
        impl = state.method_impl
        if state.world_muted and not (impl.draws_lamps and any(
                np.any(np.asarray(lamp.color) != 0.0) for lamp in state.lamps)):
            return [np.zeros((len(st.arrays.corner_verts), 3), np.float32)
                    for st in state.objects]
        return impl.shade(state, eye, view_dirs_for)

    def bounced_radiance(self, eye, view_dirs_for=None):
        """Per object in turn (a generator: a thousand instances' at once were 0.7 GB),
        per corner (C, 3) float32 or None: the bounced light it sends toward the view
        (diffuse base with each slot's colour, plus glossy part); its diffuse base's with a
        textured slot's colour white (what that colour multiplies per pixel); and its
        glossy part's alone.  The glossy part takes the bounce as if it came evenly from
        the hemisphere (core.transport.bounce.glossy_albedo)."""
        for st, E in zip(self.objects, self.bounce.irradiance(self)):
            if E is None:
                yield None, None, None
                continue
            pts = st.points
            views = reference.point_views(pts.positions, eye, view_dirs_for)
            cos_o = np.einsum("ij,ij->i", pts.normals, views)
            rad = np.zeros((pts.count, 3), np.float32)
            unit = np.zeros((pts.count, 3), np.float32)
            spec = np.zeros((pts.count, 3), np.float32)
            for m in np.unique(pts.materials):
                sel = np.nonzero(pts.materials == m)[0]
                mat = slot_material(st.materials, m)
                spec[sel] = E[sel] / np.pi * core_bounce.glossy_albedo(mat, cos_o[sel])
                rad[sel] = reference.lambert_layer(mat, E[sel], pts.normals[sel], views[sel])
                if st.slot_of[min(int(m), len(st.slot_of) - 1)] in st.textures:
                    unit[sel] = reference.lambert_layer(replace(mat, diffuse_albedo=(
                        1.0, 1.0, 1.0)), E[sel], pts.normals[sel], views[sel])
            corner = pts.point_of_corner
            yield (rad + spec)[corner], unit[corner], spec[corner]

    def draw_objects(self, eye, view_dirs_for=None):
        """Per-pixel draw callables of the active method, or None (see methods)."""
        return self.method_impl.draw_objects(self, eye, view_dirs_for)
