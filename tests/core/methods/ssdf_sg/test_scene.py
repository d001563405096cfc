"""core.methods.ssdf_sg.scene (no Blender): SSDF_SG's lighting in world space, the per-point shading
of an object, the scene fit's points and algebra, flat triangles -- against quadrature,
closed forms and hand counts."""

import numpy as np
import pytest

from prt_relight.core.shading import materials
from prt_relight.core.sphere import directions, envmap
from prt_relight.core.scene import mesh, visibility
from prt_relight.core.methods.reference import shading as reference
from prt_relight.core.sg import algebra as sg, brdf as sg_brdf, prefilter
from prt_relight.core.methods.ssdf_sg import ssdf, shading as ssdf_sg
from prt_relight.core.methods.ssdf_sg import scene as scene


def _unit(v):
    v = np.asarray(v, float)
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def _open_field(points: int, n: int = 16):
    """The SSDF of an unoccluded hemisphere (elevation of each texel), no PCA terms."""
    mean = np.arcsin(np.clip(ssdf.square_centres(n)[..., 2], 0.0, 1.0)).reshape(-1)
    return ssdf_sg.PCAField(mean, np.zeros((1, n * n)), np.zeros((points, 1)), n)


ROTATION = envmap.euler_xyz_matrix(0.3, -0.2, 1.1)


def test_world_sgs_turn_and_scale_the_texture_space_fit():
    """L_world(d) = s L_tex(R d) for the world's rotation R and strength s."""
    rng = np.random.default_rng(1)
    axes, lam, mu = _unit(rng.normal(size=(3, 3))), np.array([4.0, 20.0, 90.0]), \
        rng.uniform(0.1, 2.0, (3, 3))
    world = envmap.WorldLighting(color=(1.0, 1.0, 1.0), strength=2.5, rotation=ROTATION)
    d = _unit(rng.normal(size=(50, 3)))
    got = ssdf_sg.sg_mixture_radiance(d, *scene.world_sgs(world, (axes, lam, mu)))
    want = 2.5 * ssdf_sg.sg_mixture_radiance(d @ ROTATION.T, axes, lam, mu)
    np.testing.assert_allclose(got, want, rtol=1e-12)


def test_cosine_amplitudes():
    mu = np.arange(6.0).reshape(2, 3)
    per = scene.cosine_amplitudes(mu, 7)
    assert per.shape == (7, 2, 3) and np.all(per == mu)
    np.testing.assert_array_equal(scene.cosine_amplitudes(np.asarray(per), 3), per)


def test_shade_points_diffuse_against_quadrature():
    """An unoccluded Lambert point under one SG light lobe, the world turned and scaled:
    eq. 39 (eq. 40's cosine lobe) equals the quadrature of kd L(w) C*(w) over the upper
    hemisphere within the eq. 47-49 fit of f_h (a lobe far above the horizon)."""
    n = _unit([[0.1, -0.2, 1.0]])
    axis, lam, mu = _unit([0.3, 0.1, 0.9]), 30.0, np.array([1.0, 2.0, 3.0])
    world = envmap.WorldLighting(color=(1.0, 1.0, 1.0), strength=1.7, rotation=ROTATION)
    fit = (axis[None], np.array([lam]), mu[None], 0.0)
    albedo = np.array([0.5, 0.4, 0.3])
    got = scene.shade_points(_open_field(1), n, np.zeros((1, 3)), np.zeros(1, np.int64),
                             [materials.Material(diffuse_albedo=tuple(albedo))], world, fit, None,
                             view_dir=n[0], cosine=ssdf_sg.COSINE_EQ40)
    cube = directions.cubemap(256)
    w = cube.directions
    light = 1.7 * ssdf_sg.sg_mixture_radiance(w @ ROTATION.T, axis[None], [lam], mu[None])
    cosine = sg.evaluate(w, n, ssdf_sg.LAMBDA_C, ssdf_sg.MU_C) * (w @ n[0] > 0)
    want = albedo / np.pi * np.sum(light * (cosine * cube.solid_angles)[:, None], axis=0)
    np.testing.assert_allclose(got[0], want, rtol=5e-3)


def test_shade_points_material_slots_as_cycles():
    """A face's material index past the object's slots takes the last slot (Cycles clamps);
    an object without slots has Cycles' default surface (Principled)."""
    n = np.array([[0.0, 0.0, 1.0]])
    cube = directions.cubemap(8)
    pre = prefilter.PrefilteredEnvironment(np.ones((cube.size, 3)), cube)
    world = envmap.WorldLighting(color=(1.0, 1.0, 1.0))
    fit = (np.array([[0.0, 0.0, 1.0]]), np.array([2.0]), np.ones((1, 3)), 0.0)
    table = [materials.Material(diffuse_albedo=(0.2, 0.2, 0.2)),
             materials.Material(diffuse_albedo=(0.6, 0.1, 0.1))]

    def shade(slot, materials):
        return scene.shade_points(_open_field(1), n, np.zeros((1, 3)), np.array([slot]),
                                  materials, world, fit, pre, view_dir=n[0])
    np.testing.assert_array_equal(shade(5, table), shade(1, table))
    np.testing.assert_array_equal(shade(-1, table), shade(0, table))
    np.testing.assert_array_equal(shade(0, []), shade(0, [materials.DEFAULT_MATERIAL]))
    assert not np.allclose(shade(0, []), shade(0, [materials.Material()]))     # not a Lambert 0.8


def test_slot_material():
    table = ["a", "b"]
    assert [materials.slot_material(table, s) for s in (-3, 0, 1, 2, 9)] == ["a", "a", "b", "b", "b"]
    assert materials.slot_material([], 4) is materials.DEFAULT_MATERIAL
    assert materials.DEFAULT_MATERIAL.fresnel == "DIELECTRIC" and materials.DEFAULT_MATERIAL.metallic == 0


def test_diffuse_slots_and_point_weights():
    """Per-point weights are the area a point stands for on slots with a diffuse part:
    a 2 x 2 grid, the faces of x > 0 a metal (no diffuse part)."""
    g = mesh.grid(2.0, 2)
    tri_x = g.triangle_positions[:, :, 0].mean(axis=1)
    g.corner_materials = np.repeat((tri_x > 0).astype(np.int64), 3)
    pts = mesh.shading_points(g)
    metal = materials.principled_material(metallic=1.0)
    slots = scene.diffuse_slots([materials.Material(), metal])
    assert slots.tolist() == [True, False]
    assert scene.diffuse_slots([]).tolist() == [True]         # the default surface
    w = scene.diffuse_point_weights(g, pts, slots)
    assert np.isclose(w.sum(), 2.0)                           # the half with x < 0
    assert np.all(w[pts.positions[:, 0] > 0.5] == 0)


def test_fit_points_all_or_drawn_by_weight():
    a, b, none = np.array([0.0, 2.0, 1.0]), np.array([0.5]), np.zeros(4)
    got = scene.fit_points([a, none, b], count=8)
    assert [o for o, _, _ in got] == [0, 2]
    np.testing.assert_array_equal(got[0][1], [1, 2])
    np.testing.assert_array_equal(got[0][2], [2.0, 1.0])
    assert scene.fit_points([none]) == []
    # more points than draws: draws in proportion to weight, weights = times drawn
    heavy, light = np.full(1500, 3.0), np.full(1500, 1.0)
    got = scene.fit_points([heavy, light], count=1000, seed=3)
    drawn = [float(w.sum()) for _, _, w in got]
    assert sum(drawn) == 1000
    assert abs(drawn[0] - 750.0) < 5 * np.sqrt(1000 * 0.75 * 0.25)
    assert all(np.all(np.diff(rows) > 0) for _, rows, _ in got)


def test_fit_scene_lobes_recovers_exact_amplitudes():
    """Irradiance made by known amplitudes per (cosine lobe, light lobe): the fit returns
    them (the ridge toward the environment amplitudes fades with the point count), the
    errors are the weighted rel-L2 norms computed by hand."""
    rng = np.random.default_rng(7)
    S, M, J = 400, 3, 2
    T = rng.uniform(0.0, 1.0, (S, M, J))
    truth = rng.uniform(0.2, 2.0, (M, J, 3))
    E = np.einsum("smj,mjc->sc", T, truth)
    W = rng.uniform(0.5, 2.0, S)
    env = rng.uniform(0.2, 2.0, (J, 3))
    got, before, after = scene.fit_scene_lobes(T, E, W, env)
    np.testing.assert_allclose(got, truth, rtol=2e-3)
    sw = np.sqrt(W)[:, None]
    want_before = (np.linalg.norm((np.einsum("smj,jc->sc", T, env) - E) * sw)
                   / np.linalg.norm(E * sw))
    assert np.isclose(before, want_before, rtol=1e-10) and after < 1e-3


def test_scene_fit_on_an_occluded_plane():
    """A grid under a square occluder, lit by an SG mixture: the scene fit keeps the lobes,
    returns (M, J, 3) amplitudes whose weighted error against REFERENCE's irradiance at
    the fitted points is the 'after' it reports, below the environment fit's."""
    N = 16
    cube = directions.cubemap(N)
    g = mesh.grid(2.0, 6)
    pts = mesh.shading_points(g)
    q = np.array([[-0.3, -0.3, 0.4], [0.3, -0.3, 0.4], [0.3, 0.3, 0.4], [-0.3, 0.3, 0.4]])
    occ = np.concatenate([g.triangle_positions, [[q[0], q[1], q[2]], [q[0], q[2], q[3]]]])
    bits = visibility.trace_visibility(visibility.build_occluder_scene(occ), pts.positions,
                                       pts.normals, cube, 1e-4, threads=1)
    basis, coeffs = ssdf.ssdf_pca(bits, pts.normals, cube, ssdf.SSDFGrid(16), 0.05)
    field = ssdf_sg.PCAField(basis.mean, basis.eigen, coeffs, 16)
    axes, lam = _unit([[0.2, 0.1, 0.9], [0.0, 0.0, 1.0]]), np.array([40.0, 2.0])
    mu = np.array([[5.0, 4.0, 3.0], [0.4, 0.4, 0.5]])
    world = envmap.WorldLighting(image=ssdf_sg.equirect_from_sgs(64, axes, lam, mu),
                                 strength=2.0)
    lighting = world.to_cubemap(N)
    weights = scene.diffuse_point_weights(g, pts, np.array([True]))
    (o, rows, w), = scene.fit_points([weights])
    fit = (axes, lam, mu, 0.0)
    cos = ssdf_sg.COSINE_SG7
    got = scene.scene_fit(fit, cos, [(field, rows, pts.normals[rows], bits[rows], w)], world,
                          cube, lighting)
    assert got[0] is axes and got[1] is lam and got[2].shape == (7, 2, 3)
    before, after, count = got[4]
    assert count == pts.count and after < before
    T = ssdf_sg.diffuse_lobe_transfer(field, rows, pts.normals[rows], axes, lam, cosine=cos,
                                      per_cosine=True)
    E = reference.diffuse_irradiance(bits[rows], pts.normals[rows], cube, lighting) / 2.0
    sw = np.sqrt(w)[:, None]
    drawn = np.einsum("smj,mjc->sc", T, got[2])
    assert np.isclose(after, np.linalg.norm((drawn - E) * sw) / np.linalg.norm(E * sw),
                      rtol=1e-9)


def test_fit_environment_is_in_texture_space():
    """Neither the world's rotation nor its strength changes the fit or the pyramid."""
    axes, lam = _unit([[0.2, 0.1, 0.9]]), np.array([10.0])
    img = ssdf_sg.equirect_from_sgs(32, axes, lam, np.array([[2.0, 1.0, 0.5]]))
    a = scene.fit_environment(envmap.WorldLighting(image=img), 8, 2, fit_resolution=16)
    b = scene.fit_environment(envmap.WorldLighting(image=img, strength=3.0, rotation=ROTATION),
                              8, 2, fit_resolution=16)
    # two runs of the fit: equal within what another BLAS's order of sums could move
    for x, y in zip(a[0][:3], b[0][:3]):
        np.testing.assert_allclose(x, y, rtol=1e-5, atol=1e-7 * np.abs(x).max())
    np.testing.assert_allclose(a[1].atlas(), b[1].atlas(), rtol=1e-5,
                               atol=1e-7 * np.abs(a[1].atlas()).max())
    # an SG environment is fitted closely: the lobe comes back near its axis
    assert float(np.max(a[0][0] @ axes[0])) > 0.99


def test_flat_triangles():
    g = mesh.grid(2.0, 3)
    assert scene.flat_triangles(g, mesh.shading_points(g)).all()
    # a tent: two faces meeting at a ridge with smooth (averaged) normals are not flat
    pos = np.array([[-1.0, 0.0, 0.0], [0.0, -1.0, 0.5], [0.0, 1.0, 0.5], [1.0, 0.0, 0.0]])
    tris = np.array([[0, 1, 2], [2, 1, 3]])
    vn = _unit([[-0.5, 0.0, 1.0], [0.0, 0.0, 1.0], [0.0, 0.0, 1.0], [0.5, 0.0, 1.0]])
    tent = mesh.MeshArrays(pos, tris.reshape(-1), vn[tris.reshape(-1)],
                           np.arange(6).reshape(2, 3))
    assert not scene.flat_triangles(tent, mesh.shading_points(tent)).any()


@pytest.mark.parametrize("glossy", [False, True])
def test_is_glossy(glossy):
    m = materials.principled_material(metallic=1.0) if glossy else materials.Material()
    assert scene.is_glossy(sg_brdf.sg_material_from_brdf(m)) == glossy
