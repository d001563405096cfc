"""SG lighting (core/sg/lighting.py, Wang et al. 2009, §6) against brute force and quadrature."""

import math

import numpy as np
import pytest

from prt_relight.core.sphere import envmap
from prt_relight.core.sg import algebra as sg, lighting as sg_lighting
from prt_relight.core.sg import prefilter
from prt_relight.core.sg import lamp_lobes
from prt_relight.core.sphere.directions import cubemap, fibonacci_sphere


def _smooth_env(cube):
    d = np.asarray(cube.directions)
    L = np.zeros((cube.size, 3)) + [0.05, 0.07, 0.1]
    L += sg.evaluate(d, np.array([0.3, 0.2, 0.93]) / np.linalg.norm([0.3, 0.2, 0.93]), 40.0, 3.0)[:, None] * [1, 0.8, 0.6]
    L += sg.evaluate(d, np.array([-0.6, 0.5, 0.6]) / np.linalg.norm([-0.6, 0.5, 0.6]), 5.0, 0.5)[:, None] * [0.3, 0.5, 1]
    L += np.maximum(d[:, 2:3], 0) * [0.2, 0.3, 0.5]           # sky gradient
    return L


def _sun_env(cube, radiance=2e4):
    L = _smooth_env(cube) * 0.3
    k = cube.texel_index(np.array([0.5, -0.5, 0.707]))
    L[k] += radiance
    return L


def _random_dirs(n, seed):
    p = np.random.default_rng(seed).normal(size=(n, 3))
    return p / np.linalg.norm(p, axis=1, keepdims=True)


# --------------------------------------------------------------------------- diffuse SG fit

@pytest.mark.parametrize("envname", ["smooth", "sun"])
def test_environment_sg_fit_keeps_irradiance(envname):
    cube = cubemap(32)
    L = _smooth_env(cube) if envname == "smooth" else _sun_env(cube)
    axes, lam, mu, rel = sg_lighting.fit_environment_sgs(L, cube, max_lobes=8, tol=0.03)
    assert 1 <= len(lam) <= 8 and np.all(lam > 0) and np.all(mu >= 0)
    assert np.allclose(np.linalg.norm(axes, axis=1), 1.0)
    # independent check: irradiance of the SG mixture by a dense Fibonacci quadrature
    # against the exact cube sum, at normals not used by the fit
    normals = _random_dirs(60, 7)
    dirs = fibonacci_sphere(100_000)
    Lsg = sg_lighting.sg_mixture_radiance(dirs, axes, lam, mu)
    E_sg = (np.maximum(normals @ dirs.T, 0) @ Lsg) * (4 * math.pi / len(dirs))
    E = sg_lighting.environment_irradiance(L, cube, normals)
    err = np.linalg.norm(E_sg - E) / np.linalg.norm(E)
    print(f"env SG fit ({envname}): {len(lam)} lobes, reported {rel:.4f}, independent {err:.4f}")
    assert rel <= 0.03 or len(lam) == 8
    assert err <= 0.04


def test_environment_sg_fit_black_world_and_bad_input():
    cube = cubemap(8)
    axes, lam, mu, rel = sg_lighting.fit_environment_sgs(np.zeros((cube.size, 3)), cube)
    assert len(lam) == 0 and rel == 0.0
    bad = np.ones((cube.size, 3))
    bad[3, 1] = np.nan
    with pytest.raises(ValueError):
        sg_lighting.fit_environment_sgs(bad, cube)


def test_environment_sg_fit_gives_a_small_sun_a_sharp_lobe():
    """A 1-texel sun on a 6x128^2 cube: the first lobe sits on it with a sharpness the
    32-cube could not resolve (so eq. 30 casts a sharp shadow), and the fit keeps the
    irradiance; the bundled-HDRI failure this replaced (a diverging refinement) is
    covered by the irradiance bound."""
    cube = cubemap(128)
    sun_dir = np.array([0.5, -0.5, 0.707]) / np.linalg.norm([0.5, -0.5, 0.707])
    L = _smooth_env(cube) * 0.3
    L[cube.texel_index(sun_dir)] += 5e4
    axes, lam, mu, rel = sg_lighting.fit_environment_sgs(L, cube, max_lobes=8, tol=0.03)
    j = int(np.argmax(mu @ sg_lighting.LUMINANCE * sg.integral(lam, 1.0)))
    assert lam[j] >= 1000.0 and float(axes[j] @ sun_dir) > math.cos(math.radians(1.0))
    assert rel <= 0.03 or len(lam) == 8
    normals = _random_dirs(60, 3)
    dirs = fibonacci_sphere(400_000)
    Lsg = sg_lighting.sg_mixture_radiance(dirs, axes, lam, mu)
    E_sg = (np.maximum(normals @ dirs.T, 0) @ Lsg) * (4 * math.pi / len(dirs))
    E = sg_lighting.environment_irradiance(L, cube, normals)
    assert np.linalg.norm(E_sg - E) / np.linalg.norm(E) <= 0.05


def test_scene_amplitudes_solve_weighted_nonnegative_least_squares():
    rng = np.random.default_rng(5)
    T = np.abs(rng.normal(size=(300, 6)))
    mu_true = np.abs(rng.normal(size=(6, 3)))
    mu_true[2] = 0.0
    E = T @ mu_true
    np.testing.assert_allclose(sg_lighting.fit_scene_amplitudes(T, E), mu_true, atol=1e-9)
    # a target no non-negative mix reaches: the optimum is non-negative and beats any
    # clipped unconstrained solution under the same weights
    E2 = E - 2.0 * T[:, 2:3] + rng.normal(scale=0.1, size=E.shape)
    w = rng.uniform(0.1, 3.0, size=300)
    mu = sg_lighting.fit_scene_amplitudes(T, E2, w)
    assert np.all(mu >= 0)
    ls = np.clip(np.linalg.lstsq(T * np.sqrt(w)[:, None], E2 * np.sqrt(w)[:, None], rcond=None)[0], 0, None)
    cost = lambda m: float(np.sum(w[:, None] * (T @ m - E2) ** 2))
    assert cost(mu) <= cost(ls) + 1e-9
    # the ridge: no weight changes nothing, a dominant one returns the prior, and with
    # fewer points than unknowns it decides what the points cannot
    prior = np.abs(rng.normal(size=(6, 3)))
    np.testing.assert_allclose(sg_lighting.fit_scene_amplitudes(T, E2, w, prior, 0.0), mu)
    np.testing.assert_allclose(sg_lighting.fit_scene_amplitudes(T, E2, w, prior, 1e9), prior,
                               rtol=1e-6)
    few = sg_lighting.fit_scene_amplitudes(T[:3], E[:3], prior=mu_true + 0.01, prior_weight=1e-3)
    assert np.abs(few - mu_true).max() < 0.1
    with pytest.raises(ValueError):
        sg_lighting.fit_scene_amplitudes(T, E, prior=prior, prior_weight=-1.0)
    with pytest.raises(ValueError):
        sg_lighting.fit_scene_amplitudes(T, E[:, :2])
    with pytest.raises(ValueError):
        sg_lighting.fit_scene_amplitudes(T, E, -w)
    bad = E.copy()
    bad[0, 0] = np.nan
    with pytest.raises(ValueError):
        sg_lighting.fit_scene_amplitudes(T, bad)


# --------------------------------------------------------------------------- prefiltered pyramid

def _brute_force_mean(L, cube, p, lam):
    G = np.exp(lam * (np.minimum(p @ np.asarray(cube.directions).T, 1.0) - 1.0)) * cube.solid_angles
    return (G @ L) / G.sum(axis=1, keepdims=True)


@pytest.fixture(scope="module")
def smooth_prefiltered():
    cube = cubemap(32)
    L = _smooth_env(cube)
    return cube, L, prefilter.PrefilteredEnvironment(L, cube)


@pytest.mark.parametrize("lam,max_err", [(1e-3, 1e-3), (0.2, 0.005), (3.0, 0.01), (17.0, 0.02),
                                         (60.0, 0.03), (1e4, 0.05), (1e5, 0.05)])
def test_prefiltered_lookup_matches_brute_force_convolution(smooth_prefiltered, lam, max_err):
    cube, L, pe = smooth_prefiltered
    assert pe.levels.shape == (pe.lambdas.size, 6, 32, 32, 3) and pe.levels.dtype == np.float32
    p = _random_dirs(200, 11)
    got = pe.lookup(p, np.full(len(p), lam))
    if lam >= 1e4:   # beyond the finest level: the kernel is inside one texel -> radiance itself
        ref = prefilter.face_bilinear(L.reshape(6, 32, 32, 3), *sg_lighting.face_coordinates(p))
        ref_exact = _smooth_env_at(p)
        print(f"lam {lam}: vs analytic radiance {np.linalg.norm(got - ref_exact) / np.linalg.norm(ref_exact):.4f}")
    else:
        ref = _brute_force_mean(L, cube, p, lam)
    err = np.linalg.norm(got - ref) / np.linalg.norm(ref)
    print(f"prefiltered lookup lam={lam}: rel L2 {err:.5f}")
    assert err <= max_err


def _smooth_env_at(p):
    class _C:
        directions = p
        size = len(p)
    return _smooth_env(_C)


def test_prefiltered_inner_product_eq35(smooth_prefiltered):
    """mu * Gamma_L(p, lam) vs the brute-force inner product sum_k G(w_k) L_k dw_k."""
    cube, L, pe = smooth_prefiltered
    p = _random_dirs(50, 5)
    lam = np.geomspace(0.01, 100.0, 50)
    mu = np.linspace(0.5, 2.0, 50)[:, None] * [1.0, 0.5, 0.25]
    got = pe.inner_product(p, lam, mu)
    G = np.exp(lam[:, None] * (np.minimum(p @ np.asarray(cube.directions).T, 1) - 1)) * cube.solid_angles
    ref = mu * (G @ L)
    assert np.linalg.norm(got - ref) / np.linalg.norm(ref) < 0.02


def test_rotated_lookup_equals_lookup_of_rotated_directions(smooth_prefiltered):
    cube, L, pe = smooth_prefiltered
    R = envmap.euler_xyz_matrix(0.3, -0.2, 1.1)
    p = _random_dirs(100, 3)
    lam = np.geomspace(0.05, 300, 100)
    assert np.allclose(pe.lookup(p, lam, rotation=R), pe.lookup(p @ R.T, lam))
    # a rotated world needs no refilter: the rotated lookup equals the brute-force
    # convolution of the rotated environment L(R d)
    rotated = _smooth_env_at(np.asarray(cube.directions) @ R.T)
    ref = _brute_force_mean(rotated, cube, p[:20], 17.0)
    got = pe.lookup(p[:20], np.full(20, 17.0), rotation=R)
    assert np.linalg.norm(got - ref) / np.linalg.norm(ref) < 0.01


def test_prefiltered_lookup_with_a_sun_reports_its_limit():
    """A one-texel sun (contrast 1e5): the pyramid can only be as sharp as the cube."""
    cube = cubemap(32)
    L = _sun_env(cube)
    pe = prefilter.PrefilteredEnvironment(L, cube)
    p = _random_dirs(200, 2)
    for lam, lim in ((0.5, 0.01), (5.0, 0.02), (30.0, 0.06)):
        got = pe.lookup(p, np.full(200, lam))
        ref = _brute_force_mean(L, cube, p, lam)
        err = np.linalg.norm(got - ref) / np.linalg.norm(ref)
        print(f"sun env, lam {lam}: rel L2 {err:.4f}")
        assert err <= lim


# --------------------------------------------------------------------------- lamps

def _sg_irradiance(axis, lam, mu, n):
    """int G max(0, n.i) di by quadrature on a cap around the axis (handles lam up to 1e5)."""
    t = np.cross(axis, [0.0, 0.0, 1.0] if abs(axis[2]) < 0.9 else [1.0, 0.0, 0.0])
    t /= np.linalg.norm(t)
    b = np.cross(axis, t)
    tmax = math.acos(max(1.0 - 40.0 / lam, -1.0))
    x, w = np.polynomial.legendre.leggauss(96)
    edges = np.linspace(0, tmax, 5)
    th = np.concatenate([(edges[i] + edges[i + 1]) / 2 + (edges[i + 1] - edges[i]) / 2 * x for i in range(4)])
    wt = np.concatenate([(edges[i + 1] - edges[i]) / 2 * w for i in range(4)]) * np.sin(th)
    ph = (np.arange(128) + 0.5) * 2 * math.pi / 128
    d = (np.sin(th)[:, None, None] * (np.cos(ph)[None, :, None] * t + np.sin(ph)[None, :, None] * b)
         + np.cos(th)[:, None, None] * axis)
    g = np.exp(-lam * 2 * np.sin(th / 2) ** 2)[:, None] * np.maximum(d @ n, 0)
    return mu * np.sum(g * wt[:, None]) * (2 * math.pi / 128)


@pytest.mark.parametrize("lamp", [
    lamp_lobes.Lamp("POINT", color=(100.0, 80.0, 60.0), position=(0.5, -0.3, 3.0), radius=0.1),
    lamp_lobes.Lamp("POINT", color=(100.0, 100.0, 100.0), position=(0.0, 1.0, 2.0), radius=0.5),
    lamp_lobes.Lamp("POINT", color=(50.0, 50.0, 50.0), position=(0.0, 0.0, 4.0), radius=0.0),
    lamp_lobes.Lamp("SPOT", color=(200.0, 200.0, 200.0), position=(0.0, 0.0, 3.0),
                     direction=(0.0, 0.1, -1.0), radius=0.05, spot_size=math.radians(60)),
    lamp_lobes.Lamp("SUN", color=(3.0, 2.5, 2.0), direction=(-0.3, 0.2, -0.9), angle=math.radians(2.0)),
    lamp_lobes.Lamp("SUN", color=(3.0, 3.0, 3.0), direction=(0.0, 0.0, -1.0), angle=0.0),
])
def test_lamp_sg_gives_the_lamps_irradiance(lamp):
    x = np.array([[0.0, 0.0, 0.0], [0.3, 0.2, 0.0], [-0.5, 0.4, 0.1]])
    axes, lam, mu = lamp_lobes.lamp_sgs([lamp], x)
    ths = np.radians([0.0, 30.0, 60.0, 80.0])
    errs = []
    for p in range(len(x)):
        a = axes[p, 0]
        t = np.cross(a, [1.0, 0.0, 0.0])
        t /= np.linalg.norm(t)
        normals = np.cos(ths)[:, None] * a + np.sin(ths)[:, None] * t
        ref = lamp_lobes.lamp_irradiance(lamp, np.repeat(x[p:p + 1], len(ths), 0), normals)
        got = np.array([_sg_irradiance(a, lam[p, 0], mu[p, 0], nn) for nn in normals])
        errs.append(np.abs(got - ref) / np.maximum(ref[:, :1].max(), 1e-30))
    err = float(np.max(errs))
    print(f"{lamp.kind} r={lamp.radius} angle={lamp.angle}: lam {lam[:, 0].round(1)}, "
          f"max irradiance error / normal-incidence irradiance {err:.4f}")
    # measured 0.026 for a 0.5 m sphere 2 m away at 80 deg (the SG is not a disc), <1e-3 otherwise
    assert err <= 0.03


# --------------------------------------------------------------------------- Blender lamps

def _lamp_scene():
    import bpy

    from . import blender_scene as bs

    scene = bs.reset()
    world = bpy.data.worlds.new("Black")
    world.color = (0.0, 0.0, 0.0)
    for node in world.node_tree.nodes if world.node_tree else ():
        if node.type == "BACKGROUND":          # a new world has nodes in Blender 5
            node.inputs["Strength"].default_value = 0.0
    scene.world = world
    bpy.ops.mesh.primitive_plane_add(size=3.0)      # larger than the view: no partial edge pixels
    plane = bpy.context.object
    plane.data.materials.append(bs.bsdf_material("White", "ShaderNodeBsdfDiffuse",
                                                 Color=(0.8, 0.8, 0.8, 1.0)))
    cam = bs.add_camera(location=(0.0, 0.0, 5.0), rotation=(0.0, 0.0, 0.0))
    cam.data.type = "ORTHO"
    cam.data.ortho_scale = 2.0
    bs.set_resolution(16, 16)
    return scene


def _add_light(kind, location=(0.0, 0.0, 0.0), rotation=(0.0, 0.0, 0.0), **props):
    import bpy

    data = bpy.data.lights.new(kind, kind)
    for k, v in props.items():
        setattr(data, k, v)
    ob = bpy.data.objects.new(kind, data)
    ob.location = location
    ob.rotation_euler = rotation
    bpy.context.scene.collection.objects.link(ob)
    return ob


@pytest.mark.usefixtures("registered_addon")
def test_export_lamps_reads_blender_lights():
    import bpy

    from prt_relight.addon.blender import scene_export

    _lamp_scene()
    _add_light("POINT", (1.0, 2.0, 3.0), energy=50.0, shadow_soft_size=0.2, color=(1.0, 0.5, 0.25))
    _add_light("SUN", rotation=(0.3, 0.0, 0.0), energy=4.0, angle=0.02)
    _add_light("SPOT", (0.0, 0.0, 4.0), energy=30.0, spot_size=1.0, spot_blend=0.3)
    _add_light("AREA", (0.0, 0.0, 4.0), energy=30.0, size=2.0)
    warnings = []
    lamps = scene_export.export_lamps(bpy.context.evaluated_depsgraph_get(), warnings)
    kinds = sorted(l.kind for l in lamps)
    assert kinds == ["AREA", "POINT", "SPOT", "SUN"] and warnings == []
    area = [l for l in lamps if l.kind == "AREA"][0]       # a 2 m square facing down
    assert np.isclose(area.area, 4.0) and np.allclose(area.direction, (0.0, 0.0, -1.0))
    assert np.allclose(area.position, (0.0, 0.0, 4.0))
    point = [l for l in lamps if l.kind == "POINT"][0]
    assert np.allclose(point.position, (1, 2, 3)) and np.isclose(point.radius, 0.2)
    assert np.allclose(point.color, (50.0, 25.0, 12.5))
    sun = [l for l in lamps if l.kind == "SUN"][0]
    assert np.allclose(sun.direction, [0.0, math.sin(0.3), -math.cos(0.3)], atol=1e-6)
    spot = [l for l in lamps if l.kind == "SPOT"][0]
    assert np.isclose(spot.spot_size, 1.0) and np.isclose(spot.spot_blend, 0.3)


@pytest.mark.slow
@pytest.mark.usefixtures("registered_addon")
@pytest.mark.parametrize("kind", ["POINT", "SUN", "SPOT"])
def test_lamp_sg_units_match_cycles(kind, tmp_path):
    """A white Lambert plane under one lamp: Cycles' pixels vs albedo/pi * (SG lamp (x)
    cosine), the cosine integral done by quadrature -- checks the power/strength units."""
    import bpy

    from prt_relight.addon.blender import scene_export

    from . import blender_scene as bs

    _lamp_scene()
    if kind == "POINT":
        _add_light("POINT", (0.4, -0.3, 1.5), energy=60.0, shadow_soft_size=0.05)
    elif kind == "SUN":
        _add_light("SUN", rotation=(0.5, 0.2, 0.0), energy=2.0, angle=0.05)
    else:
        _add_light("SPOT", (0.0, 0.0, 1.5), rotation=(0.2, 0.0, 0.0), energy=80.0,
                   spot_size=1.2, spot_blend=1.0, shadow_soft_size=0.05)  # edge wider than a pixel
    lamps = scene_export.export_lamps(bpy.context.evaluated_depsgraph_get())
    img = bs.render_exr(tmp_path / "lamp.exr", engine="CYCLES", samples=16)
    h, w = img.shape[:2]
    # pixel centres on the plane (top row first: +y at the top)
    xs = -1.0 + (np.arange(w) + 0.5) * 2.0 / w
    ys = 1.0 - (np.arange(h) + 0.5) * 2.0 / h
    X, Y = np.meshgrid(xs, ys)
    pos = np.stack([X.ravel(), Y.ravel(), 0 * X.ravel()], 1)
    axes, lam, mu = lamp_lobes.lamp_sgs(lamps, pos)
    n = np.array([0.0, 0.0, 1.0])
    E = np.array([_sg_irradiance(axes[p, 0], lam[p, 0], mu[p, 0, 0], n) for p in range(len(pos))])
    ours = (0.8 / math.pi * E).reshape(h, w)
    cyc = img[..., :3].mean(axis=2)
    err = np.linalg.norm(ours - cyc) / np.linalg.norm(cyc)
    print(f"{kind}: Cycles vs SG lamp on a Lambert plane: rel L2 {err:.4f}, "
          f"mean ratio {ours.mean() / cyc.mean():.4f}")
    assert err <= 0.04
