"""shaders/lib/sg.glsl compiled through Blender's gpu module against its numpy twins:
the SG algebra (core.sg.algebra), the specular lobes (core.sg.brdf) and the prefiltered
look-up (core.sg.prefilter), float32 GLSL against float64 numpy."""

import numpy as np
import pytest

from prt_relight.core.shading import materials
from prt_relight.core.sg import algebra as sg, brdf as sg_brdf
from prt_relight.core.sg import reflectance
from prt_relight.core.sphere.directions import orthonormal_frame
from prt_relight.bench import scenes


#: _run_glsl needs a GPU context: one Workbench render of a scene (scenes.reset registers the
#: add-on; the fixture unregisters it at the end of the module)
pytestmark = pytest.mark.usefixtures("registered_addon")


# --------------------------------------------------------------------------- GLSL twin

def _run_glsl(frag_main: str, inputs: np.ndarray, out_slots: int, extra_samplers=()):
    """Evaluate ``frag_main`` (GLSL body after shaders/lib/sg.glsl) for every row of
    ``inputs`` (N, k, 4) float32 (texture ``inp``: width k, height N).  The fragment
    at pixel (x = i, y = slot) writes output ``slot`` of input ``i``.  Returns
    (N, out_slots, 4)."""
    import bpy
    import gpu
    from gpu_extras.batch import batch_for_shader

    from prt_relight.addon.gpu import shaders

    if not getattr(_run_glsl, "context_ready", False):
        scene = scenes.reset()
        cam = bpy.data.objects.new("cam", bpy.data.cameras.new("cam"))
        scene.collection.objects.link(cam)
        scene.camera = cam
        scenes.set_resolution(8, 8)
        scene.render.engine = "BLENDER_WORKBENCH"
        bpy.ops.render.render()                 # gives the gpu module a context in -b
        _run_glsl.context_ready = True
    N, k, _ = inputs.shape
    spec = shaders.Spec(vertex=("passes/fullscreen_vert.glsl",), fragment=shaders.SG_LIBRARY,
                        samplers=(("FLOAT_2D", "inp"),) + tuple(
                            (kind, name[0]) for kind, name in extra_samplers),
                        vertex_inputs=(("VEC2", "ndc"),))
    shader = gpu.shader.create_from_info(shaders.create_info(
        spec, name="sg_twin", tail="\nvoid main()\n{\n  int idx = int(gl_FragCoord.x);\n"
        "  int slot = int(gl_FragCoord.y);\n" + frag_main + "\n}\n"))
    flat = np.ascontiguousarray(inputs, dtype=np.float32).reshape(-1)
    tex = gpu.types.GPUTexture((k, N), format="RGBA32F", data=gpu.types.Buffer("FLOAT", flat.size, flat))
    batch = batch_for_shader(shader, "TRIS", {"ndc": [(-1, -1), (1, -1), (1, 1), (-1, 1)]},
                             indices=[(0, 1, 2), (0, 2, 3)])
    off = gpu.types.GPUOffScreen(N, out_slots, format="RGBA32F")
    try:
        with off.bind():
            fb = gpu.state.active_framebuffer_get()
            fb.clear(color=(0.0, 0.0, 0.0, 0.0))
            shader.bind()
            shader.uniform_sampler("inp", tex)
            for slot, (kind, (name, t)) in enumerate(extra_samplers, start=1):
                shader.uniform_sampler(name, t)
            batch.draw(shader)
            buf = fb.read_color(0, 0, N, out_slots, 4, 0, "FLOAT")
        buf.dimensions = N * out_slots * 4
        return np.array(buf, dtype=np.float32).reshape(out_slots, N, 4).transpose(1, 0, 2)
    finally:
        off.free()


_FETCH = "  vec4 in{j} = texelFetch(inp, ivec2({j}, idx), 0);\n"


@pytest.mark.slow
def test_glsl_sg_algebra_matches_numpy():
    """sg_inner_product / sg_product / sg_integral in float32 GLSL vs core.sg.algebra (float64),
    for lam in 1e-3 .. 1e5, aligned, random and antipodal lobes."""
    rng = np.random.default_rng(9)
    lams = np.array([1e-3, 0.1, 2.0, 50.0, 1e3, 1e4, 1e5])
    rows = []
    for l1 in lams:
        for l2 in (1e-3, 3.0, 1e4, 1e5):
            p1 = rng.normal(size=3)
            p1 /= np.linalg.norm(p1)
            for kind in ("same", "near", "random", "antipodal"):
                if kind == "same":
                    p2 = p1
                elif kind == "near":
                    p2 = p1 + 0.003 * rng.normal(size=3)
                elif kind == "random":
                    p2 = rng.normal(size=3)
                else:
                    p2 = -p1
                p2 = p2 / np.linalg.norm(p2)
                rows.append([[*p1, l1], [*p2, l2]])
    inputs = np.array(rows, dtype=np.float32)
    p1 = inputs[:, 0, :3].astype(np.float64)
    p2 = inputs[:, 1, :3].astype(np.float64)
    l1 = inputs[:, 0, 3].astype(np.float64)
    l2 = inputs[:, 1, 3].astype(np.float64)
    main = (_FETCH.format(j=0) + _FETCH.format(j=1) + """
  vec3 axis; float lam;
  float f = sg_product(in0.xyz, in0.w, in1.xyz, in1.w, axis, lam);
  if (slot == 0) fragColor = vec4(sg_inner_product(in0.xyz, in0.w, in1.xyz, in1.w),
                                  sg_integral(in0.w), f, lam);
  else fragColor = vec4(axis, sg_eval(in1.xyz, in0.xyz, in0.w));
""")
    out = _run_glsl(main, inputs, 2)
    ip = sg.inner_product(p1, l1, 1.0, p2, l2, 1.0)
    ax, lm, amp = sg.product(p1, l1, 1.0, p2, l2, 1.0)
    ev = sg.evaluate(p2, p1, l1)
    # float32 inputs: the exponent lam (1 - cos) is known to ~1e-7 lam |p1 - p2|: compare logs
    # where the values are representable, absolutely where they underflow
    for got, ref in ((out[:, 0, 0], ip), (out[:, 0, 2], amp), (out[:, 1, 3], ev)):
        big = ref > 1e-30
        assert np.allclose(got[big], ref[big], rtol=2e-3), np.max(np.abs(got[big] / ref[big] - 1))
        assert np.all(np.abs(got[~big]) < 1e-30)
    assert np.allclose(out[:, 0, 1], sg.integral(l1), rtol=1e-5)
    assert np.allclose(out[:, 0, 3], lm, rtol=1e-4, atol=1e-3)
    ok = lm > 1e-2
    assert np.allclose(out[ok, 1, :3], ax[ok], atol=1e-3)


def _glsl_specular(material, n, v, t):
    """specular_lobes through GLSL for one material at P points: (axes, lam, mu, K)."""
    P = len(n)
    mi = sg_brdf.MODEL_INDEX[material.model]
    fi = sg_brdf.FRESNEL_INDEX[material.fresnel]
    ndf = np.zeros((8, 4))
    ndf_mu = np.zeros(8)
    nn = 0
    if material.is_anisotropic:
        f = sg_brdf.ndf_lobes(material)
        nn = len(f.lam)
        ndf[:nn, :3] = f.axes
        ndf[:nn, 3] = f.lam
        ndf_mu[:nn] = f.mu
    rough = np.broadcast_to(np.asarray(material.roughness, float), (P,))
    ior = np.broadcast_to(np.asarray(material.ior, float), (P,))
    met = np.broadcast_to(np.asarray(material.metallic, float), (P,))
    ks = np.broadcast_to(material.specular, (P, 3))
    base = np.broadcast_to(material.diffuse, (P, 3))
    rows = np.zeros((P, 6 + 8 + 2, 4))
    rows[:, 0] = np.stack([np.full(P, mi), np.full(P, fi), rough, ior], 1)
    rows[:, 1, :3], rows[:, 1, 3] = ks, met
    rows[:, 2, :3], rows[:, 2, 3] = base, nn
    rows[:, 3, :3], rows[:, 4, :3], rows[:, 5, :3] = n, v, t
    rows[:, 6:14] = ndf[None]
    rows[:, 14] = ndf_mu[None, :4]
    rows[:, 15] = ndf_mu[None, 4:]
    fetch = "".join(_FETCH.format(j=j) for j in range(16))
    main = fetch + """
  vec4 ndf[SG_MAX_LOBES] = vec4[SG_MAX_LOBES](in6, in7, in8, in9, in10, in11, in12, in13);
  float ndf_mu[SG_MAX_LOBES] = float[SG_MAX_LOBES](in14.x, in14.y, in14.z, in14.w,
                                                   in15.x, in15.y, in15.z, in15.w);
  vec3 axes[SG_MAX_LOBES]; float lams[SG_MAX_LOBES]; vec3 mus[SG_MAX_LOBES];
  int K = specular_lobes(in0, in1, in2, normalize(in3.xyz), normalize(in4.xyz), in5.xyz,
                         int(in2.w + 0.5), ndf, ndf_mu, axes, lams, mus);
  int k = slot / 2;
  if (slot % 2 == 0) fragColor = vec4(axes[k], lams[k]);
  else fragColor = vec4(mus[k], float(K));
"""
    out = _run_glsl(main, rows.astype(np.float32), 16).astype(np.float64)
    K = int(round(out[0, 1, 3]))
    return out[:, 0:2 * K:2, :3], out[:, 0:2 * K:2, 3], out[:, 1:2 * K:2, :3], K


@pytest.mark.slow
def test_glsl_specular_lobes_match_numpy():
    rng = np.random.default_rng(4)
    P = 48
    n = rng.normal(size=(P, 3))
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    t = rng.normal(size=(P, 3))
    cosv = np.concatenate([np.linspace(1.0, 0.05, P - 4), [0.01, 0.0, -0.05, 1e-3]])
    tt, _ = orthonormal_frame(n)
    v = n * cosv[:, None] + tt * np.sqrt(1 - cosv ** 2)[:, None]
    n, v, t = n.astype(np.float32).astype(float), v.astype(np.float32).astype(float), t.astype(np.float32).astype(float)
    cases = [
        reflectance.SGMaterial(model="COOK_TORRANCE", roughness=0.09, specular=(0.8, 0.7, 0.6)),
        reflectance.SGMaterial(model="COOK_TORRANCE", roughness=0.45, fresnel="DIELECTRIC", ior=1.45),
        reflectance.SGMaterial(model="BLINN_PHONG", roughness=0.2, fresnel="SCHLICK"),
        reflectance.SGMaterial(model="WARD", roughness=0.15),
        reflectance.SGMaterial(model="WARD_ANISO", alpha_x=0.3, alpha_y=0.1),
        reflectance.SGMaterial(model="ASHIKHMIN_SHIRLEY", nu=75, nv=1200, fresnel="SCHLICK", specular=(0.05, 0.05, 0.05)),
        # the twin's models are 0-4: the Principled layering on a Beckmann lobe (GGX is drawn
        # by ssdf_sg_frag.glsl: tests/integration/cycles/test_textures.py's sphere against Cycles)
        sg_brdf.sg_material_from_brdf(materials.principled_material(base_color=(0.8, 0.4, 0.2), metallic=0.3, roughness=0.4), ggx=False),
    ]
    for mat in cases:
        ax, lam, mu = sg_brdf.specular_lobes(mat, n, v, t)
        gax, glam, gmu, K = _glsl_specular(mat, n, v, t)
        assert K == ax.shape[1], mat.model
        scale = np.max(np.abs(mu)) + 1e-30
        ok = np.abs(mu).max(axis=-1) > 1e-6 * scale
        assert np.allclose(gax[ok], ax[ok], atol=2e-4), mat.model
        assert np.allclose(glam[ok], lam[ok], rtol=2e-4), mat.model
        # views within 1 deg of the horizon: M ~ 1/c^2 amplifies float32 rounding of c = o.n
        rtol = np.where(np.abs(cosv) < 0.02, 3e-2, 1e-3)[:, None, None]
        assert np.all(np.isfinite(gmu))
        bad = ~np.isclose(gmu, mu, rtol=rtol, atol=1e-5 * scale).all(axis=(1, 2))
        assert not bad.any(), (mat.model, np.flatnonzero(bad), cosv[bad], gmu[bad], mu[bad])


@pytest.mark.slow
def test_glsl_prefiltered_lookup_matches_numpy():
    import gpu

    from prt_relight.core.sg import prefilter
    from prt_relight.core.sphere.directions import cubemap

    cube = cubemap(8)
    rng = np.random.default_rng(1)
    L = rng.random((cube.size, 3)) + sg.evaluate(cube.directions, [0, 0, 1.0], 5.0, 3.0)[:, None]
    pe = prefilter.PrefilteredEnvironment(L, cube)
    P = 256
    d = rng.normal(size=(P, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    d = d.astype(np.float32).astype(float)
    lam = np.concatenate([[0.0, 1e-3, 0.1, 1e5], np.geomspace(0.01, 1e4, P - 4)]).astype(np.float32).astype(float)
    ref = pe.lookup(d, lam)
    _run_glsl("", np.zeros((1, 1, 4), np.float32), 1)        # context
    atlas = pe.atlas()
    flat = np.ascontiguousarray(atlas).reshape(-1)
    tex = gpu.types.GPUTexture((atlas.shape[1], atlas.shape[0]), format="RGBA32F",
                               data=gpu.types.Buffer("FLOAT", flat.size, flat))
    rows = np.zeros((P, 1, 4))
    rows[:, 0, :3], rows[:, 0, 3] = d, lam
    main = _FETCH.format(j=0) + (
        f"  fragColor = vec4(prefiltered_lookup(env, in0.xyz, in0.w, {cube.resolution}, "
        f"{pe.n_levels}, {pe.lambda_first!r}, {np.log(pe.ratio)!r}, {pe.lambdas[-2]!r}), 1.0);\n")
    out = _run_glsl(main, rows.astype(np.float32), 1, extra_samplers=[("FLOAT_2D", ("env", tex))])
    assert np.allclose(out[:, 0, :3], ref, rtol=1e-4, atol=1e-5), np.max(np.abs(out[:, 0, :3] - ref))
