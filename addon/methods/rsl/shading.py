"""RSL: rotatable square lights (Xu, Jia, Hu, Tai 2006): the environment split into K square lights,
BRDF from summed-area tables and visibility from per-vertex distance tables (eq. 5)."""

from __future__ import annotations

import copy
import dataclasses

import numpy as np

from ....core.shading import materials
from ....core.methods.rsl import cpca, shading as rsl
from ....core.scene import distance_tables
from ....core.methods.rsl import square_lights
from ....core.sphere import directions, envmap
from ....core.methods.reference import shading as reference
from ....core.scene import rigid, shadow_fields
from ....core.scene import occluder_fields
from ...gpu import drawing, shaders
from ...frame import dynamic, keys
from ...blender import storage
from ..contract import Shading, glossy_or_layered

#: disk-map resolution of the BRDF SATs and visibility tables (§5.1: 32 x 32)
DISK_RESOLUTION = 32
#: view-elevation nodes of the isotropic BRDF SATs (§5.1: 32)
VIEW_NODES = 32
#: sub-samples per disk texel edge when tabulating a BRDF
BRDF_SUBSAMPLES = 3
#: sub-samples per disk texel edge when reading the visibility bits
VISIBILITY_SUBSAMPLES = 2

_LIGHTING = keys.cache(1)       # unrotated cubemap lighting per (content, strength, resolution)
LIGHTS = keys.cache(8)         # SquareLights per (lighting key, K / budget)
# BrdfTables per material (0.3-1.1 MB each): a frame's textured slots hold up to 32
# roughness variants each (core.scene.textures.point_variants)
_TABLES = keys.cache(100)
_VISIBILITY = keys.cache(8)     # per-vertex VDT / SAT per (object, bits)
_FACTORS = keys.cache(8)        # view-independent (V, C) per (object, bits, lights, rotation)
STORED = keys.cache(8)         # (VDT, pose) reconstructed per stored blob (storage.key)


def unrotated_lighting(world: envmap.WorldLighting, resolution: int):
    """The world's cubemap in texture space (no Mapping rotation): the decomposition
    does not change when the world rotates, only the light centres do."""
    key = keys.env_key(world, resolution)
    key = (key[0], key[1], resolution)
    return key, keys.held(_LIGHTING, key, (), lambda: dataclasses.replace(
        world, rotation=np.eye(3)).to_cubemap(resolution))


def scene_lights(state):
    """``(cache key, SquareLights)`` for the state's world and RSL settings."""
    key, lighting = unrotated_lighting(state.world, state.resolution)
    s = state.settings
    budget = s.get("rsl_error_budget") if s.get("rsl_mode", "COUNT") == "BUDGET" else None
    count = int(s.get("rsl_lights", 30))
    lkey = (key, count, budget)
    return lkey, keys.held(LIGHTS, lkey, (), lambda: square_lights.decompose(
        lighting, directions.cubemap(state.resolution), count if budget is None else None,
        error_budget=budget))


def brdf_tables(material: materials.Material) -> rsl.BrdfTables:
    material = rsl.table_material(material)
    return keys.held(_TABLES, material, (), lambda: rsl.brdf_tables(
        material, DISK_RESOLUTION, VIEW_NODES, BRDF_SUBSAMPLES))


def derive_visibility(bits, normals, resolution: int, kind: str = "VDT", dtype=np.float32,
                      progress=None) -> np.ndarray:
    """Per-vertex visibility maps in the disk map -> VDT (eq. 9) or visibility SAT."""
    return distance_tables.visibility_tables(bits, normals, directions.cubemap(resolution), kind,
                                 DISK_RESOLUTION, VISIBILITY_SUBSAMPLES, dtype=dtype,
                                 progress=progress)


def held_dtype(kind: str):
    """Tables held for drawing: a VDT in half floats (2 KB a point; |D| <= 2, so the
    distances near a boundary, the ones eq. 9 reads, keep 11 bits), a SAT in float32
    (its box integral is a difference of four values)."""
    return np.float16 if kind == "VDT" else np.float32


def object_visibility(st, resolution: int, kind: str, normals=None, rows=None,
                      progress=None) -> np.ndarray:
    """The object's VDT (stored CPCA reconstruction when synced, else derived from the
    visibility bits) or visibility SAT (always derived: the exact option), one table per
    current point.  ``normals``: the normals the bits were traced with (the precompute
    orientation); ``rows``: the stored row of each current point after a turn."""
    normals = st.points.normals if normals is None else normals
    stored = st.data.get("rsl")
    if kind == "VDT" and stored is not None:
        if rows is None:
            return stored
        return keys.per_visibility(_VISIBILITY, (st.name, "rows", rows.tobytes()), stored,
                                   lambda: stored[rows])
    bits = st.bits if rows is None else st.bits[rows]
    key = (st.name, kind, id(st.bits), resolution, None if rows is None else rows.tobytes())
    return keys.per_visibility(
        _VISIBILITY, key, st.bits,
        lambda: derive_visibility(bits, normals, resolution, kind, held_dtype(kind), progress))


def field_visibility(st, evaluator, state, cos_tables) -> np.ndarray:
    """Fig. 8's occluder factors of a posed object, (P, K): for each dynamic object near,
    ``V_oj`` -- eq. 9 on its occluder field at the point for light ``j``'s square (centre
    turned back into the field's frame, the same half side: the disk map is equal-area);
    for a dynamic object, the static scene's share too, from its static field (a VDT per
    point of the blended visibility, eq. 9 per light as the self VDTs)."""
    pts = st.points
    centres = np.asarray(evaluator.centres, np.float64)
    half = np.asarray(evaluator.half, np.float64).reshape(-1)
    # a square's centre may lie outside the occluder's cone while its edge overlaps it:
    # widen the cone by the largest square's angular radius (solid angle 2 (2a)^2)
    margin = 0.05 + float(np.sqrt(8.0 * half.max(initial=0.0) ** 2 / np.pi))
    V = np.ones((pts.count, len(centres)), np.float64)
    for mover in st.near:
        data, (T, R, _s) = mover.dynamic
        p, k, frac = occluder_fields.occluder_fractions(
            data.field, shadow_fields.to_field_frame(T, pts.positions), centres @ R, half,
            margin=margin, normals=np.asarray(pts.normals, np.float64) @ R)
        V[p, k] *= frac
    static = dynamic.static_bits(st, state)
    if static is not None:
        vdt = derive_visibility(static, pts.normals, state.resolution, "VDT", held_dtype("VDT"))
        V *= evaluator.diffuse_factors(pts.normals, "VDT", vdt, cos_tables)[0]
    return V


# ------------------------------------------------------------------ storage (§5.1)

#: name of the stored blob (addon.blender.storage): the CPCA of the VDTs and the pose then
BLOB = "rsl"


def cpca_blob(model: cpca.ClusteredPCA, resolution: int, rotation, probe) -> bytes:
    """One object's CPCA (float32 tables, int32 labels) and its pose at precompute
    (``rotation`` 3x3, ``probe`` object-space vertices) as a stored blob."""
    return storage.pack({"labels": np.asarray(model.labels, np.int32),
                         "means": np.asarray(model.means, np.float32),
                         "bases": np.asarray(model.bases, np.float32),
                         "coeffs": np.asarray(model.coeffs, np.float32),
                         "rotation": np.asarray(rotation, np.float64).reshape(3, 3),
                         "probe": np.asarray(probe, np.float64).reshape(-1, 3)},
                        {"resolution": int(resolution)})


def _stored_tables(arrays, meta):
    """(VDT (P, res, res) float16, rotation, probe) of a stored ``rsl`` blob."""
    try:
        res = int(meta["resolution"])
        labels, means, bases, coeffs = (arrays[k] for k in ("labels", "means", "bases",
                                                             "coeffs"))
        rotation, probe = arrays["rotation"], arrays["probe"]
    except (KeyError, TypeError, ValueError):
        raise storage.Unreadable("RSL data incomplete") from None
    C, E, D = bases.shape if bases.ndim == 3 else (0, 0, -1)
    if (res * res != D or means.shape != (C, D) or coeffs.shape != (len(labels), E)
            or (labels.size and not 0 <= labels.min() <= labels.max() < C)):
        raise storage.Unreadable("RSL data inconsistent")
    model = cpca.ClusteredPCA(labels.astype(np.int64), means, bases, coeffs)
    vdt = model.reconstruct(dtype=held_dtype("VDT"))
    return vdt.reshape(-1, res, res), rotation, probe


class RSLShading(Shading):




    # ---------------------------------------------------------- precompute
    def derive(self, job):
        """Per object: visibility maps in each vertex's disk map -> VDT (eq. 9) ->
        clustered PCA within the error budget (§5.1)."""
        from ....core.common.parallel import Cancelled
        budget = float(job.settings.get("rsl_cpca_error", 0.02))
        out, notes = {}, []
        for o in job.objects:
            if job.cancel_requested:
                raise Cancelled()
            def progress(_fraction):
                if job.cancel_requested:
                    raise Cancelled()
            vdt = derive_visibility(o.bits, o.points.normals, job.resolution, "VDT",
                                    np.float32, progress)
            model, err, ratio = cpca.compress_by_budget(vdt.reshape(len(vdt), -1), budget)
            out[o.name] = (model, err, ratio)
            C, E, _ = model.bases.shape
            notes.append(f"{o.name}: CPCA {C}x{E} error {err:.3f} ratio 1:{ratio:.0f}")
        job.timings["rsl_cpca"] = "; ".join(notes)
        return out

    def store(self, scene, job, derived):
        for name, (model, _err, _ratio) in (derived or {}).items():
            ob = storage.owner(name)
            if ob is None:
                continue
            # pose at precompute: the VDTs live in vertex frames that turn with the object
            job_ob = next(o for o in job.objects if o.name == name)
            M = np.asarray(job_ob.matrix, dtype=np.float64)
            storage.put(ob, BLOB, cpca_blob(model, DISK_RESOLUTION, rigid.rotation_part(M),
                                            rigid.local_probe(job_ob.arrays.positions, M)))

    def sync(self, state):
        for st in state.objects:
            ob = storage.owner(st.name)
            got = storage.load(ob, BLOB, STORED, _stored_tables, state.note)
            if got is None or len(got[0]) != st.points.count:
                continue
            vdt, R0, probe = got
            if st.status != "ok":
                turn = rigid.rigid_turn(np.asarray(st.matrix, dtype=np.float64),
                                        st.arrays.positions, R0, probe)
                if turn is None:
                    continue
                if not np.allclose(turn, np.eye(3), atol=1e-9):
                    st.data["rsl_rotation"] = turn
                    st.data["rsl_rows"] = rigid.stored_rows(st.points, st.arrays, turn)
                    if st.dynamic is None:
                        state.note(f"RSL: {st.name} turned since precompute; its "
                                   "self-shadowing turns with it (shadows on other objects "
                                   "are not updated)")
            st.data["rsl"] = vdt

    def view_dependent(self, state) -> bool:
        return glossy_or_layered(state)

    def shade(self, state, eye, view_dir):
        lkey, lights = scene_lights(state)
        R = state.world.rotation
        evaluator = rsl.Evaluator(lights, R)
        kind = state.settings.get("rsl_visibility", "VDT")
        use_gpu = bool(state.settings.get("rsl_gpu", True)) and drawing.gpu_available()
        cos_tables = brdf_tables(materials.Material())
        out = []
        for i, st in enumerate(state.objects):
            state.tick(i / len(state.objects))      # progress; ESC stops here
            pts = st.points
            turn = st.data.get("rsl_rotation")
            ev, normals = evaluator, pts.normals
            if turn is not None:        # work in the object's precompute orientation
                ev = copy.copy(evaluator)
                ev.centres = evaluator.centres @ turn
                normals = np.asarray(pts.normals, np.float64) @ turn
            rows = st.data.get("rsl_rows")
            vis = object_visibility(st, state.resolution, kind, normals, rows,
                                    lambda f, i=i: state.tick((i + 0.9 * f) / len(state.objects)))
            rkey = (lkey, R.round(9).tobytes(), None if turn is None else turn.round(9).tobytes())
            # Fig. 8: a posed object's stored VDTs times the fields of the dynamic objects
            # near (and, for a dynamic one, the static scene's) at each light
            fields = (st.status == "posed" and kind == "VDT" and st.data.get("rsl") is not None)
            if fields:
                rkey += (dynamic.poses_of(st),)
            radiance = None
            if use_gpu and not fields:
                try:
                    radiance = self._shade_gpu(st, ev, kind, vis, eye, view_dir, rkey, normals,
                                               turn)
                except Exception as exc:                  # numpy below gives the same sums
                    state.note(f"RSL GPU pass failed ({exc}); shading with numpy")
                    use_gpu = False
            if radiance is None:
                def factors(ev=ev, normals=normals, vis=vis, st=st, fields=fields):
                    V, C = ev.diffuse_factors(normals, kind, vis, cos_tables)
                    if fields:
                        V = V * field_visibility(st, evaluator, state, cos_tables)
                    return V, C

                V, C = keys.per_visibility(_FACTORS, (st.name, id(vis), kind, rkey), vis,
                                           factors)
                radiance = np.zeros((pts.count, 3))
                for mat, sel, vd in _groups(st, eye, view_dir, turn):
                    radiance[sel] = ev.shade(mat, brdf_tables(mat), normals[sel], vd,
                                             V[sel], C[sel])
            radiance = np.nan_to_num(radiance, nan=0.0, posinf=0.0, neginf=0.0)
            out.append(radiance[pts.point_of_corner].astype(np.float32))
        return out

    @staticmethod
    def _shade_gpu(st, evaluator, kind, vis, eye, view_dir, lighting_key, normals, turn):
        batches = keys.held(_GPU, ("vis", st.name, kind), (vis,), lambda: vis_textures(vis))
        pts = st.points
        radiance = np.zeros((pts.count, 3))

        def shade(groups):
            """One pass per visibility batch for every material of ``groups``."""
            sel = np.concatenate([g[1] for g in groups])
            tables = [brdf_tables(mat) for mat, _, _ in groups]
            table_of = np.repeat(np.arange(len(groups)), [len(g[1]) for g in groups])
            views = np.concatenate([normals[g[1]] if g[2] is None else g[2] for g in groups])
            weights = [rsl.point_weights(mat, normals[s], vd) for mat, s, vd in groups]
            T = max(len(w) for w in weights)
            stacked = np.zeros((len(sel), T, 3))
            at = 0
            for w in weights:
                stacked[at:at + len(w[0]), :len(w)] = np.stack(w, axis=1)
                at += len(w[0])
            out = np.zeros((len(sel), 3))
            for start, stop, texture in batches:
                part = np.nonzero((sel >= start) & (sel < stop))[0]
                if part.size:
                    out[part] = gpu_shade(evaluator.centres, evaluator.half[0], evaluator.energy,
                                          tables, table_of[part], normals[sel[part]],
                                          views[part], stacked[part], kind, texture,
                                          vis.shape[-1] - (kind == "SAT"), sel[part] - start)
            return sel, out

        groups = list(_groups(st, eye, view_dir, turn))
        for group in groups:
            mat, sel, vd = group
            if vd is None:                  # view independent: once per lighting/rotation
                radiance[sel] = keys.held(_GPU_DIFFUSE, (st.name, kind, mat, lighting_key),
                                          (vis,), lambda group=group: shade([group])[1])
        # every view-dependent material (a textured slot's variants) in one pass
        viewed = [g for g in groups if g[2] is not None]
        if viewed:
            sel, out = shade(viewed)
            radiance[sel] = out
        return radiance


def _groups(st, eye, view_dir, turn=None):
    """(material, point indices, view directions or None) per material slot; views in
    the object's precompute orientation when it has turned (``turn``)."""
    pts = st.points
    for slot in np.unique(pts.materials):
        sel = np.nonzero(pts.materials == slot)[0]
        mat = materials.slot_material(st.materials, slot)
        vd = None
        if not mat.is_diffuse_only or mat.fresnel == "DIELECTRIC":
            vd = reference.point_views(pts.positions[sel], eye, view_dir)
            if turn is not None:
                vd = vd @ turn
        yield mat, sel, vd



# --------------------------------------------------------------------------- #
# GLSL per-vertex pass (§5.2: one texel per vertex, rendered to a float target)
# --------------------------------------------------------------------------- #

#: most glossy terms the GPU pass sums (its glossy[MAX_TERMS]: shaders/lib/constants.glsl)
MAX_TERMS = 8
TEXTURE_WIDTH = 8192
# cached textures: per object its visibility tables; per material its BRDF SATs (as many as
# _TABLES holds: a textured slot's variants would otherwise push the objects' tables out)
_GPU = drawing.gpu_cache({}, limit=16)
_GPU_TABLES = drawing.gpu_cache({}, limit=100)
# view-independent GPU results per (object, material, lighting)
_GPU_DIFFUSE = drawing.gpu_cache({}, limit=16)


def _shader():
    return shaders.shader("rsl_vertex")


def _texture(values: np.ndarray, fmt: str):
    """GPU texture from (H, W, C) float32 (C = 1 for R32F, 4 for RGBA32F)."""
    import gpu
    h, w = values.shape[:2]
    flat = np.ascontiguousarray(values, dtype=np.float32).reshape(-1)
    return gpu.types.GPUTexture((w, h), format=fmt,
                                data=gpu.types.Buffer("FLOAT", flat.size, flat))


#: points per visibility texture: 16384 VDTs in R16F are 32 MiB, 2048 rows of 8192
BATCH_POINTS = 16384


def vis_textures(tables: np.ndarray, batch: int = BATCH_POINTS):
    """Per-point tables (P, m, m) as GPU textures of ``batch`` points each, ``[(start,
    stop, texture)]``: each point's m² texels in a row of texels read in row-major order
    (point ``i`` of a batch starts at texel ``i m²``), in half floats for a VDT (the
    values held), float32 for a SAT.  Batches keep each texture within the GPU's
    size limit and the float32 copy made for the upload small."""
    import gpu
    P, m, _ = tables.shape
    fmt = "R16F" if tables.dtype == np.float16 else "R32F"
    limit = gpu.capabilities.max_texture_size_get()
    width = min(TEXTURE_WIDTH, limit)
    batch = max(1, min(batch, limit * width // (m * m)))
    out = []
    for start in range(0, max(P, 1), batch):
        stop = min(P, start + batch)
        flat = tables[start:stop].reshape(-1)
        rows = max(1, -(-flat.size // width))
        img = np.zeros((rows, width, 1), np.float32)
        img.reshape(-1)[:flat.size] = flat
        out.append((start, stop, _texture(img, fmt)))
    return out


def _max_texture_size() -> int:
    import gpu
    return gpu.capabilities.max_texture_size_get()


def brdf_texture_atlas(tables: list, block_cols: int) -> np.ndarray:
    """Every material's :func:`brdf_texture_blocks`, one after another, ``block_cols``
    blocks to a row of blocks: (rows, block_cols * (N+2), 1) float32."""
    n = tables[0].resolution
    blocks = np.concatenate([brdf_texture_blocks(t)[..., 0] for t in tables])
    count = len(blocks) // (n + 1)
    grid = np.zeros((-(-count // block_cols) * block_cols, n + 1, n + 2), np.float32)
    grid[:count] = blocks.reshape(count, n + 1, n + 2)
    grid = grid.reshape(-1, block_cols, n + 1, n + 2).transpose(0, 2, 1, 3)
    return grid.reshape(-1, block_cols * (n + 2))[..., None]


def brdf_texture_blocks(tables: rsl.BrdfTables) -> np.ndarray:
    """The cosine SAT then every glossy term's SAT per view node, each an
    (N+1) x (N+2) block whose last column holds the block's offset in row 0."""
    n = tables.resolution
    blocks = [(tables.cosine, tables.cosine_offset)]
    for S, off in zip(tables.glossy, tables.glossy_offsets):
        blocks += list(zip(S, off))
    out = np.zeros((len(blocks) * (n + 1), n + 2), np.float32)
    for i, (S, off) in enumerate(blocks):
        out[i * (n + 1):(i + 1) * (n + 1), :n + 1] = S
        out[i * (n + 1), n + 1] = off
    return out[..., None]


def gpu_shade(lights_centres, lights_half, energy, tables: list, table_of, normals, views,
              weights, vis_kind: str, vis_texture, vis_res: int, indices):
    """Per-vertex radiance (P, 3) by the GLSL pass: point i reads the BRDF tables
    ``tables[table_of[i]]`` (every material of the pass in one texture) and its visibility
    table ``indices[i]`` in the batch's texture ``vis_texture``; ``views`` (P, 3);
    ``weights`` (P, T, 3): the diffuse weight ``albedo/pi * W``, then each glossy term's
    weight of the point's material, zero past its terms
    (:func:`..core.methods.rsl.shading.point_weights`)."""
    P = len(normals)
    if P == 0:
        return np.zeros((0, 3))
    terms = weights.shape[1] - 1
    if terms > MAX_TERMS:
        raise ValueError(f"{terms} BRDF terms; the GPU pass takes {MAX_TERMS}")
    width = min(P, 1024)
    rows = -(-P // width)
    first = np.cumsum([0] + [1 + len(t.glossy) * len(t.view_angles) for t in tables])
    pd = np.zeros((3 * rows * width, 4), np.float32)
    pd[:P, :3] = normals
    pd[rows * width:rows * width + P, :3] = views
    index = pd[2 * rows * width:2 * rows * width + P]
    index[:, 0] = indices                                         # exact below 2**24
    index[:, 1] = first[table_of]
    index[:, 2] = np.array([len(t.glossy) for t in tables])[table_of]
    pd = pd.reshape(3 * rows, width, 4)
    wt = np.zeros(((terms + 1) * rows * width, 4), np.float32)
    for k in range(terms + 1):
        wt[k * rows * width:k * rows * width + P, :3] = weights[:, k]
    wt = wt.reshape((terms + 1) * rows, width, 4)
    K = len(lights_half)
    lt = np.zeros((2, K, 4), np.float32)
    lt[0, :, :3] = lights_centres
    lt[0, :, 3] = lights_half
    lt[1, :, :3] = energy
    n = tables[0].resolution
    block_cols = max(1, min(_max_texture_size() // (n + 2), int(first[-1])))
    brdf_texture = keys.held(_GPU_TABLES, tuple(map(id, tables)), tables,
                             lambda: _texture(brdf_texture_atlas(tables, block_cols), "R32F"))
    # keep the textures referenced until the draw is done
    point_tex, weight_tex = _texture(pd, "RGBA32F"), _texture(wt, "RGBA32F")
    out = drawing.texel_pass(
        _shader(), width, rows,
        ints=(("width", width), ("pointCount", P), ("lightCount", K), ("termCount", terms),
              ("visMode", 0 if vis_kind == "VDT" else 1), ("visRes", vis_res),
              ("visTile", vis_res if vis_kind == "VDT" else vis_res + 1),
              ("brdfRes", n), ("viewNodes", len(tables[0].view_angles)),
              ("blockCols", block_cols)),
        floats=(("viewStep", float(tables[0].view_angles[1] - tables[0].view_angles[0])),),
        samplers=(("pointData", point_tex), ("weights", weight_tex),
                  ("lights", _texture(lt, "RGBA32F")), ("visTable", vis_texture),
                  ("brdfTables", brdf_texture)))
    return out[:P, :3].astype(np.float64)
