"""Dynamic objects: shadow fields in the scene (Zhou et al. 2005; Xu et al. 2006 §4.3.2).

An object marked *dynamic* (``object.prt.dynamic``) is traced against itself only; its
occluder field and the static scene's field over where it goes over the animation are
stored with it (blob ``storage.SHADOW_FIELD``, ``core.scene.shadow_fields``).  Static objects are traced
against the static objects only.  Each frame, at the current poses:

* a dynamic object's visibility = its own (turned with it) x the static field x the other
  dynamic objects' occluder fields;
* a static object's visibility = its stored one x every dynamic object's occluder field
  (only points within a field's outermost shell change).

The product is visibility bits, so every method shades it as it shades stored bits; an
object whose bits are such a product has status ``"posed"`` (methods with data derived
at the precompute derive it from the bits instead).  Products are cached per pose.
"""

from __future__ import annotations

import numpy as np

from ...core.sphere import directions
from ...core.scene import mesh as core_mesh, rigid, shadow_fields, visibility
from . import keys
from ..blender import storage

#: frames sampled over the scene's frame range for where a dynamic object goes
REACH_FRAMES = 48

_FIELDS = keys.cache(64)          # parsed DynamicData per stored blob
_POSED = keys.cache(64)           # visibility products per object and poses
_STATIC_SCENE = keys.cache(1)     # Embree scene of the static objects (corner test)


def _bbox_world(ob) -> np.ndarray:
    M = np.array(ob.matrix_world, dtype=np.float64)
    corners = np.array([tuple(c) for c in ob.bound_box], dtype=np.float64).reshape(-1, 3)
    return corners @ M[:3, :3].T + M[:3, 3]


def _moved_box(positions, M) -> np.ndarray:
    """The 8 corners of the box of ``positions`` moved by the 4x4 ``M``."""
    lo, hi = positions.min(axis=0), positions.max(axis=0)
    corners = np.array([[(lo, hi)[(k >> i) & 1][i] for i in range(3)] for k in range(8)])
    return corners @ M[:3, :3].T + M[:3, 3]


def set_reach(scene, jobs, static_triangles):
    """Each dynamic job's ``reach``: the box its bounding box sweeps over the scene's
    frame range (sampled at :data:`REACH_FRAMES` frames and the current one), widened by a
    tenth of its size; an object that does not move over it may be moved by hand, so its
    reach also spans the static objects' box.  The current frame is restored."""
    import bpy
    if not jobs:
        return
    boxes = {j.name: [] for j in jobs}
    # an instance goes where its instancer takes it: its box moved by the instancer's
    # motion since now (its own motion relative to the instancer is not sampled)
    owners = {j.name: storage.owner(j.name) for j in jobs}
    dg = bpy.context.evaluated_depsgraph_get()
    start = {j.name: np.linalg.inv(np.array(o.instancer.evaluated_get(dg).matrix_world))
             for j in jobs for o in [owners[j.name]] if isinstance(o, storage.InstanceRecord)}
    frame, sub = scene.frame_current, scene.frame_subframe
    frames = {frame}
    if scene.frame_end > scene.frame_start:
        frames |= set(np.unique(np.linspace(scene.frame_start, scene.frame_end,
                                            REACH_FRAMES).round().astype(int)).tolist())
    try:
        for f in sorted(frames):
            if len(frames) > 1:
                scene.frame_set(int(f))
            dg = bpy.context.evaluated_depsgraph_get()
            for j in jobs:
                ob = owners[j.name]
                if j.name in start:
                    M = np.array(ob.instancer.evaluated_get(dg).matrix_world) @ start[j.name]
                    boxes[j.name].append(_moved_box(j.arrays.positions, M))
                elif ob is not None:
                    boxes[j.name].append(_bbox_world(ob.evaluated_get(dg)))
    finally:
        if len(frames) > 1:
            scene.frame_set(frame, subframe=sub)
    static = np.asarray(static_triangles, np.float64).reshape(-1, 3)
    for j in jobs:
        pts = np.concatenate(boxes[j.name] or [j.arrays.positions])
        lo, hi = pts.min(axis=0), pts.max(axis=0)
        first = boxes[j.name][0] if boxes[j.name] else pts
        still = all(np.allclose(b, first, atol=1e-6 * (1.0 + np.abs(first).max()))
                    for b in boxes[j.name])
        if len(static) and still:
            lo = np.minimum(lo, static.min(axis=0))       # not animated: anywhere in the set
            hi = np.maximum(hi, static.max(axis=0))
        pad = 0.1 * float(np.max(hi - lo)) + 1e-6
        j.reach = (lo - pad, hi + pad)


def _parse(arrays, meta):
    try:
        return shadow_fields.dynamic_of_arrays(arrays, meta)
    except ValueError as exc:
        raise storage.Unreadable(str(exc)) from None


def stored_field(ob, note=None):
    """The object's stored :class:`core.scene.shadow_fields.DynamicData`, or None."""
    return storage.load(ob, storage.SHADOW_FIELD, _FIELDS, _parse, note)


def check(orig, matrix, positions, note):
    """``(status, moving)`` of a synced object with respect to its field: ``"ok"`` when
    its dynamic flag matches what was precomputed and (for a dynamic one) it only moved,
    turned or scaled uniformly, ``moving`` then its stored data and motion ``(data, (T,
    R, s))`` (None for a static object); otherwise ``"stale"`` (``note`` says why).
    ``orig``: the original object (or an instance's storage record), ``matrix`` its world
    matrix now."""
    data = stored_field(orig, note) if storage.has(orig, storage.SHADOW_FIELD) else None
    if orig.prt.dynamic != (data is not None):
        note(f"'{orig.name}' was {'marked' if orig.prt.dynamic else 'unmarked'} dynamic "
             "since the precompute (stale, press Precompute)")
        return "stale", None
    if data is None:
        return "ok", None
    now = np.asarray(matrix, dtype=np.float64)
    motion = shadow_fields.relative_motion(data.matrix, now)
    if motion is None:
        note(f"'{orig.name}' is dynamic but scaled non-uniformly or sheared since the "
             "precompute (stale, press Precompute)")
        return "stale", None
    if rigid.rigid_turn(now, positions, data.rotation, data.probe) is None:
        return "stale", None    # its mesh was edited: the fields are of the old shape
    return "ok", (data, motion)


def _static_scene(state):
    """Embree scene of the static objects' triangles (for the static field's corner
    test), kept per their geometry."""
    static = [st for st in state.objects if st.dynamic is None and st.status != "unshadowed"]
    if not static or not visibility.have_embree():
        return None
    return keys.held(_STATIC_SCENE, tuple((st.name, st.fingerprint) for st in static), (),
                     lambda: visibility.build_occluder_scene(np.concatenate(
                         [core_mesh.occluder_triangles(st.arrays)[0] for st in static])))


def _pose_key(motion) -> bytes:
    return np.round(motion[0], 6).tobytes()


def reach(mover) -> tuple[np.ndarray, float]:
    """Centre and radius (current world) of the sphere beyond which a dynamic object's
    field casts nothing."""
    data, (T, _R, scale) = mover.dynamic
    centre = T[:3, :3] @ data.field.centre + T[:3, 3]
    return centre, scale * data.field.radius * data.field.layout.outer


def apply(state):
    """Poses every object a dynamic object's field reaches, and every dynamic object
    (see the module docstring): status ``"posed"``, ``near`` the dynamic objects whose
    fields reach it, and its bits the product, made when first read (cached per pose).
    Notes a dynamic object beyond its static field's box."""
    movers = [st for st in state.objects if st.dynamic is not None]
    if not movers:
        return
    cube = directions.cubemap(state.resolution)
    spheres = [reach(m) for m in movers]
    for st in movers:
        data = st.dynamic[0]
        if data.static is not None and \
                not shadow_fields.in_field_box(data.static, st.points.positions):
            state.note(f"'{st.name}' moved beyond where its animation went at the precompute: "
                       "the shadows static objects cast on it are extrapolated (press "
                       "Precompute for exact ones)")
    for st in state.objects:
        if st.status != "ok":
            continue
        pos = np.asarray(st.points.positions, np.float64)
        st.near = [m for m, (c, r) in zip(movers, spheres) if m is not st and len(pos) and
                   float(np.min(np.sum((pos - c) ** 2, axis=1))) < r * r]
        moved = st.dynamic is not None and (
            st.dynamic[0].static is not None
            or not np.allclose(st.dynamic[1][1], np.eye(3), atol=1e-9))
        if not st.near and not moved:
            continue

        def product(st=st, poses=poses_of(st)):
            stored = st.stored_bits()
            key = (st.name, id(stored), state.resolution, poses)
            return keys.held(_POSED, key, (stored,), lambda: posed_bits(
                st, stored, st.near, cube, state))

        st.status = "posed"
        st.pose(product)


def posed_bits(st, stored, others, cube, state):
    pts = st.points
    bits = stored
    if st.dynamic is not None:
        data, (T, R, _s) = st.dynamic
        if not np.allclose(R, np.eye(3), atol=1e-9):
            rows = rigid.stored_rows(pts, st.arrays, R)
            bits = shadow_fields.turned_bits(bits[rows], cube, R)
        if data.static is not None:
            bits = bits & static_bits(st, state)
    for o in others:
        data, (T, R, _s) = o.dynamic
        bits = shadow_fields.block_by_field(bits, data.field, pts.positions, cube, T, R,
                                            normals=pts.normals)
    return bits


def poses_of(st) -> tuple:
    """The poses an object's product depends on: its own (a dynamic object) and those of
    the dynamic objects near it (what its cached products are keyed on)."""
    own = (_pose_key(st.dynamic[1]),) if st.dynamic is not None else ()
    return own + tuple((m.name, _pose_key(m.dynamic[1])) for m in st.near)


def static_bits(st, state):
    """Packed visibility the static scene leaves at a dynamic object's points now (its
    static field, blended over the corners each point sees), or None (a static object,
    or no static occluders); cached per pose."""
    if st.dynamic is None or st.dynamic[0].static is None:
        return None
    data = st.dynamic[0]
    pts = st.points
    key = (st.name, "static", id(data), state.resolution, _pose_key(st.dynamic[1]))

    def make():
        scene = _static_scene(state)
        # where the precompute's rays start: out of a static surface the object touches
        origins = (visibility.ray_origins(pts.positions, pts.normals, data.offset)
                   if scene is None else visibility.contact_origins(
                       scene, pts.positions, pts.normals, st.arrays.triangle_positions,
                       pts.point_of_corner[st.arrays.triangles], data.offset)[0])
        return shadow_fields.static_bits(data.static, scene, origins, pts.positions)
    return keys.held(_POSED, key, (data,), make)
