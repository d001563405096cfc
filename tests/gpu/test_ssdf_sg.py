"""SSDF_SG's GLSL (shaders/ssdf_sg_frag.glsl, the pair pass) against the numpy evaluation of
core.methods.ssdf_sg.shading per pixel, and the pair table holding eq. 39 at the flat
points."""

from __future__ import annotations

import bpy
import numpy as np
import pytest

from prt_relight.addon.gpu import drawing
from prt_relight.addon.frame import state as runtime
from prt_relight.addon.methods.ssdf_sg import shading as method
from prt_relight.addon.methods.ssdf_sg import gpu as ssdf_sg_gpu
from prt_relight.core.methods.ssdf_sg import shading as core_ssdf_sg, scene as ssdf_sg_scene
from prt_relight.bench import scenes

from ..cases.glossy import SSDF_SG_SIZE, ssdf_sg_suzanne


pytestmark = [pytest.mark.usefixtures("registered_addon"), pytest.mark.slow]

W, H = SSDF_SG_SIZE


def _gpu_ready():
    scene = bpy.context.scene
    engine = scene.render.engine
    scene.render.engine = "BLENDER_WORKBENCH"
    bpy.ops.render.render()
    scene.render.engine = engine


def _state():
    state = runtime.FrameState()
    state.sync(bpy.context.evaluated_depsgraph_get())
    return state


def camera_matrices():
    scene = bpy.context.scene
    cam = scene.camera
    depsgraph = bpy.context.evaluated_depsgraph_get()
    view = cam.matrix_world.inverted()
    proj = cam.calc_matrix_camera(depsgraph, x=W, y=H)
    return view, proj, np.array(cam.matrix_world.translation)


@pytest.mark.parametrize("principled", [False, True])
def test_glsl_equals_numpy_per_pixel(principled):
    import embreex.rtcore_scene as rtcs
    from embreex.mesh_construction import TriangleMesh

    scene = ssdf_sg_suzanne(principled)
    assert bpy.ops.prt.precompute() == {"FINISHED"}
    _gpu_ready()
    state = _state()
    view, proj, eye = camera_matrices()
    vp = proj @ view
    draws = state.draw_objects(eye, None)
    assert draws is not None and len(draws) == len(state.objects)
    # the ground's triangles are flat: drawn by the FLAT_PAIRS shader from the pair table
    ground = next(st for st in state.objects if st.name == "Ground")
    assert ssdf_sg_scene.flat_triangles(ground.arrays, ground.points).all()
    batches = ssdf_sg_gpu.object_batches(ground, ground.data["ssdf_sg"])
    assert batches.draws and all(flat for _, flat, _ in batches.draws)
    assert len(batches.flat_points) == ground.points.count
    gpu_px = drawing.render_offscreen([], None, vp, W, H, True, draws)        # bottom row first

    # numpy: a ray through every pixel centre, the hit triangle's barycentrics, and the
    # same formulas (core.methods.ssdf_sg.scene.shade_points) at the interpolated normal / PCA coefficients
    inv = np.array(vp.inverted())
    jj, ii = np.meshgrid(np.arange(H), np.arange(W), indexing="ij")
    ndc = np.stack([(ii + 0.5) / W * 2 - 1, (jj + 0.5) / H * 2 - 1], -1).reshape(-1, 2)
    near = np.c_[ndc, -np.ones(len(ndc)), np.ones(len(ndc))] @ inv.T
    far = np.c_[ndc, np.ones(len(ndc)), np.ones(len(ndc))] @ inv.T
    near, far = near[:, :3] / near[:, 3:], far[:, :3] / far[:, 3:]
    dirs = far - near
    dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
    tris, owner = [], []
    for k, st in enumerate(state.objects):
        tp = st.arrays.triangle_positions
        tris.append(tp)
        owner.append(np.c_[np.full(len(tp), k), np.arange(len(tp))])
    rt = rtcs.EmbreeScene()
    TriangleMesh(rt, np.ascontiguousarray(np.concatenate(tris), dtype=np.float32))
    owner = np.concatenate(owner)
    hit = rt.run(near.astype(np.float32), dirs.astype(np.float32), output=1)
    prim = np.asarray(hit["primID"])
    ok = prim >= 0
    numpy_px = np.zeros((H * W, 3))
    fit, pre = state.method_impl._lighting(state)          # scene-fitted amplitudes (default)
    assert state.settings["sg_lighting_fit"] == "SCENE" and len(fit) == 5
    for k, st in enumerate(state.objects):
        sel = np.nonzero(ok & (owner[np.maximum(prim, 0), 0] == k))[0]
        t = owner[prim[sel], 1]
        u, v = np.asarray(hit["u"])[sel], np.asarray(hit["v"])[sel]
        beta = np.stack([1 - u - v, u, v], 1)
        corners = st.arrays.triangles[t]                                    # (M, 3)
        nrm = np.einsum("mk,mkj->mj", beta, st.arrays.corner_normals[corners])
        nrm /= np.linalg.norm(nrm, axis=1, keepdims=True)
        pos = np.einsum("mk,mkj->mj", beta, st.arrays.positions[st.arrays.corner_verts[corners]])
        field = st.data["ssdf_sg"]
        pts = st.points.point_of_corner[corners]
        coeffs = np.einsum("mk,mkj->mj", beta, field.coefficients[pts].astype(np.float64))
        px_field = core_ssdf_sg.PCAField(field.mean, field.eigen, coeffs, field.resolution)
        mats = st.points.materials[pts[:, 0]]
        numpy_px[sel] = ssdf_sg_scene.shade_points(px_field, nrm, pos, mats, st.materials,
                                                   state.world, fit, pre, eye=eye,
                                                   cosine=method.cosine_of(state.settings))
    gpu = gpu_px.reshape(-1, 4)
    mask = ok & (gpu[:, 3] > 0.5)
    assert mask.sum() > 0.3 * W * H
    a, b = gpu[mask, :3], numpy_px[mask]
    rel = np.linalg.norm(a - b, axis=1) / np.maximum(np.linalg.norm(b, axis=1), 1e-6)
    assert np.median(rel) < 1e-4
    assert np.quantile(rel, 0.99) < 2e-3, np.sort(rel)[-10:]


def test_pair_table_holds_eq39_at_the_flat_points():
    """The pair pass (shaders/methods/ssdf_sg_pairs_frag.glsl) read back from the GPU: per point of
    the ground's flat triangles, sum_p w_p sigma(theta_p, k_p) over the (cosine lobe, light
    lobe) pairs equals numpy's eq. 39 (core.methods.ssdf_sg.shading.diffuse_transfer_per_cosine) there."""
    from prt_relight.core.sg import algebra as core_sg
    scene = ssdf_sg_suzanne()
    assert bpy.ops.prt.precompute() == {"FINISHED"}
    _gpu_ready()
    state = _state()
    _, _, eye = camera_matrices()
    ssdf_sg_gpu.PAIR_TABLES.clear()
    assert state.draw_objects(eye, None) is not None
    ground = next(st for st in state.objects if st.name == "Ground")
    field = ground.data["ssdf_sg"]
    flat_points = ssdf_sg_gpu.object_batches(ground, field).flat_points
    tex = next(v[1] for k, v in ssdf_sg_gpu.PAIR_TABLES.items() if k[0] == "Ground")
    fit, _ = state.method_impl._lighting(state)
    cosine = method.cosine_of(state.settings)
    M, J = len(cosine.amplitudes), len(fit[1])
    pairs, stride = M * J, ssdf_sg_gpu.pair_texels(M, J)
    theta_texels = stride - pairs
    buf = tex.read()
    buf.dimensions = tex.width * tex.height * 4             # (numpy reads a 3D Buffer wrongly)
    table = np.array(buf, dtype=np.float64).reshape(-1, 4)[:len(flat_points) * stride]
    table = table.reshape(len(flat_points), stride, 4)
    theta = table[:, :theta_texels].reshape(len(flat_points), -1)[:, :pairs]
    w, k = table[:, theta_texels:, :3], table[:, theta_texels:, 3]
    gpu_rd = np.einsum("qpc,qp->qc", w, core_sg.fh_hat_slope(theta, k))
    normals = ground.points.normals[flat_points]
    numpy_rd = core_ssdf_sg.diffuse_transfer_per_cosine(
        field.numpy, flat_points, normals, fit[0] @ state.world.rotation, fit[1],
        ssdf_sg_scene.cosine_amplitudes(fit[2], M), cosine=cosine)
    rel = np.linalg.norm(gpu_rd - numpy_rd, axis=1) / np.maximum(
        np.linalg.norm(numpy_rd, axis=1), 1e-6)
    assert np.median(rel) < 1e-4 and rel.max() < 2e-3, np.sort(rel)[-5:]
