"""SG lighting (core/sg/lighting.py, Wang et al. 2009, §6) against brute force and quadrature."""

import math

import numpy as np
import pytest

from prt_relight.core.sg import algebra as sg
from prt_relight.core.sg import prefilter
from prt_relight.core.sg import lamp_lobes
from prt_relight.core.sphere.directions import cubemap


def _smooth_env(cube):
    d = np.asarray(cube.directions)
    L = np.zeros((cube.size, 3)) + [0.05, 0.07, 0.1]
    L += sg.evaluate(d, np.array([0.3, 0.2, 0.93]) / np.linalg.norm([0.3, 0.2, 0.93]), 40.0, 3.0)[:, None] * [1, 0.8, 0.6]
    L += sg.evaluate(d, np.array([-0.6, 0.5, 0.6]) / np.linalg.norm([-0.6, 0.5, 0.6]), 5.0, 0.5)[:, None] * [0.3, 0.5, 1]
    L += np.maximum(d[:, 2:3], 0) * [0.2, 0.3, 0.5]           # sky gradient
    return L


# --------------------------------------------------------------------------- diffuse SG fit


# --------------------------------------------------------------------------- prefiltered pyramid


@pytest.fixture(scope="module")
def smooth_prefiltered():
    cube = cubemap(32)
    L = _smooth_env(cube)
    return cube, L, prefilter.PrefilteredEnvironment(L, cube)


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
