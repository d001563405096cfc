"""Compact sources and lamps drawn per pixel (addon/gpu/lights.py): shadows against analytic
penumbrae, a point-like sun without acne, an overcast world drawn exactly as without the
split, point, spot and area lamps on a Lambert plane against their irradiance."""

from __future__ import annotations

import math

import bpy
import numpy as np
import pytest

from prt_relight.addon.frame import state as runtime
from prt_relight.bench import scenes

from ...cases.lights import area_lamp, black_world, local_lamp, plate_over_ground, sun_lamp


pytestmark = pytest.mark.usefixtures("registered_addon")


def _top_view(height, scale, width, rows):
    """An orthographic camera ``height`` over the origin looking down, ``scale`` wide, a frame
    of ``width`` × ``rows`` pixels at one sample per pixel; the scene."""
    cam = scenes.add_camera(location=(0.0, 0.0, height), rotation=(0.0, 0.0, 0.0),
                            resolution=None)
    cam.data.type = "ORTHO"
    cam.data.ortho_scale = scale
    scenes.set_resolution(width, rows)
    scene = bpy.context.scene
    scene.prt.supersampling = 1
    return scene


def _edge_profile(frame, scale, width):
    """The ground's radiance along x through the middle row, and the x of each column."""
    row = frame.shape[0] // 2
    xs = (np.arange(width) + 0.5) / width * scale - 0.5 * scale
    return xs, frame[row, :, 0]


@pytest.mark.parametrize("angle_deg", [4.0, 10.0])
def test_penumbra_of_a_straight_edge_matches_the_disc_it_comes_from(tmp_path, angle_deg):
    """A plate's edge 1 m above a Lambert ground under a sun straight above: across the
    edge, the fraction of the sun's disc (projected radius 1 m * tan(angle / 2)) that is
    not behind the plate is a circular segment's area.  The filtered shadow map follows
    it."""
    scenes.reset()
    black_world()
    plate_over_ground(1.0)
    sun_lamp(3.0, math.radians(angle_deg))
    # between the plate and the ground, looking down: the plate is behind the camera
    rho = math.tan(math.radians(angle_deg / 2.0))
    scale, width = 8.0 * rho, 128
    scene = _top_view(0.5, scale, width, 8)
    scene.render.filter_size = 0.0
    bpy.ops.prt.precompute()
    frame = scenes.render_exr(tmp_path / "edge.exr")
    xs, got = _edge_profile(frame, scale, width)
    full = 0.8 / math.pi * 3.0
    # the plate covers x < 0: the lit fraction of the disc centred at x (projected)
    t = np.clip(xs / rho, -1.0, 1.0)
    lit = 0.5 + (t * np.sqrt(1.0 - t * t) + np.arcsin(t)) / math.pi
    err = np.abs(got / full - lit)
    assert err.mean() < 0.04, (err.mean(), err.max())
    assert err.max() < 0.15

    def width_between(profile, lo=0.25, hi=0.75):
        return xs[np.argmax(profile >= hi)] - xs[np.argmax(profile >= lo)]

    assert width_between(got / full) == pytest.approx(width_between(lit), rel=0.3)


def test_a_point_like_sun_casts_a_sharp_shadow_without_acne(tmp_path):
    scenes.reset()
    black_world()
    plate_over_ground(1.0)
    sun_lamp(3.0, 0.0)
    scene = _top_view(0.5, 2.0, 64, 8)
    scene.render.filter_size = 0.0
    bpy.ops.prt.precompute()
    frame = scenes.render_exr(tmp_path / "sharp.exr")
    xs, got = _edge_profile(frame, 2.0, 64)
    full = 0.8 / math.pi * 3.0
    np.testing.assert_allclose(got[xs < -0.05], 0.0, atol=1e-6)          # in the shadow
    np.testing.assert_allclose(got[xs > 0.05], full, rtol=1e-4)          # lit: no acne


def test_an_overcast_world_draws_exactly_as_without_extraction(tmp_path):
    """No pixel over the threshold: no source, the same frame as with extraction off."""
    scenes.reset()
    h, w = 64, 128
    theta = (np.arange(h) + 0.5) / h * math.pi
    sky = np.repeat((0.3 + 0.7 * np.clip(np.cos(theta), 0, 1))[:, None, None]
                    * np.ones((1, w, 3)), 1, axis=0).astype(np.float32)
    scenes.add_world(image=scenes.float_image("overcast", np.broadcast_to(sky, (h, w, 3)).copy()))
    scenes.add_ground(size=4.0, cuts=12)
    scenes.add_suzanne(subdiv=1, location=(0.0, 0.0, 1.0))
    scenes.add_camera(location=(0.0, -6.0, 3.0), rotation=(1.15, 0.0, 0.0), resolution=None)
    scenes.set_resolution(48, 36)
    bpy.ops.prt.precompute()
    state = runtime.FrameState()
    state.sync(bpy.context.evaluated_depsgraph_get())
    assert state.sources == [] and state.world is state.full_world
    with_split = scenes.render_exr(tmp_path / "a.exr")
    bpy.context.scene.prt.light_sources = 0
    without = scenes.render_exr(tmp_path / "b.exr")
    np.testing.assert_allclose(with_split, without, rtol=1e-6, atol=1e-7)


@pytest.mark.parametrize("method", ["REFERENCE", "SH"])
def test_point_and_spot_lamps_light_every_method_per_pixel(tmp_path, method):
    """A point lamp 2 m above a Lambert plane gives albedo / pi * Phi / (4 pi d^2) * cos
    (Cycles' point light); a spot pointing down keeps that inside its cone and nothing
    outside; a plate between the lamp and the plane casts a shadow."""
    scenes.reset()
    black_world()
    ground = scenes.add_ground(size=8.0, cuts=8)
    ground.data.materials.append(scenes.bsdf_material("Lambert", "ShaderNodeBsdfDiffuse",
                                                  Color=(0.8, 0.8, 0.8, 1.0)))
    lamp = local_lamp("POINT", 500.0, (0.0, 0.0, 2.0), radius=0.01)
    scene = _top_view(1.0, 6.0, 30, 30)
    scene.prt.method = method
    scene.render.filter_size = 0.0
    bpy.ops.prt.precompute()
    frame = scenes.render_exr(tmp_path / "point.exr")[::-1]          # row 0 at y = -3
    xs = (np.arange(30) + 0.5) / 30 * 6.0 - 3.0
    X, Y = np.meshgrid(xs, xs, indexing="xy")
    d2 = X * X + Y * Y + 4.0
    expected = 0.8 / math.pi * 500.0 / (4 * math.pi * d2) * (2.0 / np.sqrt(d2))
    np.testing.assert_allclose(frame[..., 0], expected, rtol=0.01)
    bpy.data.objects.remove(lamp)
    local_lamp("SPOT", 500.0, (0.0, 0.0, 2.0), radius=0.01, size=math.radians(60),
                blend=0.0)
    frame = scenes.render_exr(tmp_path / "spot.exr")[::-1]
    inside = np.arctan(np.sqrt(X * X + Y * Y) / 2.0) < math.radians(27)
    outside = np.arctan(np.sqrt(X * X + Y * Y) / 2.0) > math.radians(33)
    np.testing.assert_allclose(frame[..., 0][inside], expected[inside], rtol=0.01)
    assert frame[..., 0][outside].max() == 0.0
    bpy.ops.mesh.primitive_plane_add(size=1.0, location=(1.5, 0.0, 1.5))
    bpy.ops.prt.precompute()
    frame = scenes.render_exr(tmp_path / "shadow.exr")[::-1]
    # the plate at x 1..2 (1.5 m up) shades the ground from x = 1.33 to 2.67 (the lamp at
    # x = 0, 2 m up): inside the shadow but within the cone
    col = int((2.0 + 3.0) / 6.0 * 30)
    assert frame[15, col, 0] < 0.02 * expected[15, col]


def _area_irradiance(points, centre, half_x, half_y, facing, radiance, ellipse, n=300):
    """Irradiance of an upward-facing plane at ``points`` from a Lambertian emitter of
    ``radiance`` (midpoint quadrature over its area)."""
    u = (np.arange(n) + 0.5) / n * 2.0 - 1.0
    U, V = np.meshgrid(u, u, indexing="ij")
    keep = (U * U + V * V <= 1.0) if ellipse else np.ones_like(U, bool)
    q = centre + U[keep][:, None] * half_x + V[keep][:, None] * half_y      # (Q, 3)
    dA = 4.0 * np.linalg.norm(np.cross(half_x, half_y)) / (n * n)
    out = np.zeros(len(points))
    for k, p in enumerate(points):
        w = q - p
        d2 = (w * w).sum(1)
        cos_i = np.maximum(w[:, 2], 0.0) / np.sqrt(d2)
        cos_l = np.maximum(-(w @ facing), 0.0) / np.sqrt(d2)
        out[k] = radiance * (cos_i * cos_l / d2).sum() * dA
    return out


@pytest.mark.parametrize("shape, placement", [("RECTANGLE", "above"), ("DISK", "above"),
                                              ("RECTANGLE", "through"), ("DISK", "through")])
def test_area_lamp_lights_a_lambert_plane_as_its_area_integral(tmp_path, shape, placement):
    """An area lamp tilted over a Lambert plane (every method draws it per pixel): albedo
    / pi times the irradiance of a Lambertian emitter of Phi / (pi A) integrated over its
    area (numerical quadrature), dark behind it.  ``through``: the lamp stands nearly
    upright through the plane, so every lit point's horizon clips its polygon."""
    scenes.reset()
    black_world()
    ground = scenes.add_ground(size=8.0, cuts=8)
    ground.data.materials.append(scenes.bsdf_material("Lambert", "ShaderNodeBsdfDiffuse",
                                                  Color=(0.8, 0.8, 0.8, 1.0)))
    tilt, height = (0.5, 1.5) if placement == "above" else (1.3, 0.15)
    lamp = area_lamp(400.0, (0.3, -0.2, height), 1.2, 0.6, shape=shape,
                      rotation=(tilt, 0.0, 0.3))
    scene = _top_view(1.0, 6.0, 24, 24)
    scene.render.filter_size = 0.0
    bpy.ops.prt.precompute()
    frame = scenes.render_exr(tmp_path / "area.exr")[::-1]
    xs = (np.arange(24) + 0.5) / 24 * 6.0 - 3.0
    X, Y = np.meshgrid(xs, xs, indexing="xy")
    M = np.array(lamp.matrix_world)
    sy = 0.6 if shape == "RECTANGLE" else 1.2
    half_x, half_y, facing = 0.6 * M[:3, 0], 0.5 * sy * M[:3, 1], -M[:3, 2]
    area = 1.2 * sy * (math.pi / 4 if shape == "DISK" else 1.0)
    E = _area_irradiance(np.column_stack([X.ravel(), Y.ravel(), np.zeros(X.size)]), M[:3, 3],
                         half_x, half_y, facing, 400.0 / (math.pi * area), shape == "DISK")
    expected = (0.8 / math.pi * E).reshape(24, 24)
    # the midpoint quadrature needs a point farther from the lamp's plane than its spacing
    apart = np.abs((np.column_stack([X.ravel(), Y.ravel(), np.zeros(X.size)]) - M[:3, 3])
                   @ facing).reshape(24, 24) > 0.05
    lit = (expected > 0.02 * expected.max()) & apart
    err = np.abs(frame[..., 0] - expected)[lit] / expected[lit]
    assert np.median(err) < 0.01 and err.max() < 0.05, (np.median(err), err.max())
    assert frame[..., 0][~lit & apart].max() <= 0.05 * expected.max()


def _state():
    state = runtime.FrameState()
    state.sync(bpy.context.evaluated_depsgraph_get())
    return state


@pytest.mark.slow
def test_sun_lamp_lights_an_open_plane_like_lambert_and_moves_live(tmp_path):
    """A Blender sun lamp is drawn per pixel by every method (addon/gpu/lights.py): an open
    Lambert plane under a black world shows albedo/pi * strength * cos(theta); turning the
    lamp needs no recompute."""
    scenes.reset()
    scenes.add_world(image=scenes.float_image("black", np.zeros((8, 16, 3), np.float32)))
    ground = scenes.add_ground(size=4.0, cuts=4)
    ground.data.materials.append(scenes.bsdf_material("Lambert", "ShaderNodeBsdfDiffuse",
                                                  Color=(0.8, 0.8, 0.8, 1.0)))
    sun = bpy.data.lights.new("Sun", "SUN")
    sun.energy, sun.angle = 3.0, 0.05
    lamp = bpy.data.objects.new("Sun", sun)
    bpy.context.scene.collection.objects.link(lamp)
    lamp.rotation_euler = (np.radians(30.0), 0.0, 0.0)          # 30 degrees from the zenith
    scenes.add_camera(location=(0.0, 0.0, 5.0), rotation=(0.0, 0.0, 0.0), resolution=None)
    scenes.set_resolution(16, 16)
    scene = bpy.context.scene
    assert bpy.ops.prt.precompute() == {"FINISHED"}
    pid = ground.prt.precompute_id
    for method in ("SSDF_SG", "REFERENCE"):
        scene.prt.method = method
        lamp.rotation_euler = (np.radians(30.0), 0.0, 0.0)
        frame = scenes.render_exr(tmp_path / f"{method}30.exr")
        np.testing.assert_allclose(frame[..., :3], 0.8 / np.pi * 3.0 * np.cos(np.radians(30.0)),
                                   rtol=0.01, err_msg=method)
        lamp.rotation_euler = (np.radians(60.0), 0.0, 0.0)
        frame = scenes.render_exr(tmp_path / f"{method}60.exr")
        np.testing.assert_allclose(frame[..., :3], 0.8 / np.pi * 3.0 * 0.5, rtol=0.01,
                                   err_msg=method)
        assert not _state().lamps and len(_state().drawn_lamps) == 1
    assert ground.prt.precompute_id == pid


def test_every_lamp_is_drawn_with_its_shadow_past_the_old_cap_of_eight(tmp_path, monkeypatch):
    """Twelve point lamps 3 m over a Lambert ground, a plate 2 m up under the last one:
    every pixel is the sum of the lamps that see it, Phi / (4 pi d^2) cos each (the plate's
    shadow found segment by segment).  With the cube atlas's budget cut to one lamp, the
    other eleven are still drawn, unshadowed, and the render log names them."""
    scenes.reset()
    black_world()
    ground = scenes.add_ground(size=8.0, cuts=8)
    ground.data.materials.append(scenes.bsdf_material("Lambert", "ShaderNodeBsdfDiffuse",
                                                      Color=(0.8, 0.8, 0.8, 1.0)))
    lamps = np.array([(-2.25 + 1.5 * (k % 4), -1.5 + 1.5 * (k // 4), 3.0) for k in range(12)])
    for k, p in enumerate(lamps):
        local_lamp("POINT", 100.0 + 10.0 * k, tuple(p), radius=0.01).name = f"Lamp{k:02d}"
    plate = lamps[-1] - (0.0, 0.0, 1.0)
    bpy.ops.mesh.primitive_plane_add(size=0.6, location=tuple(plate))
    scene = _top_view(1.5, 6.0, 32, 32)
    scene.render.filter_size = 0.0
    bpy.ops.prt.precompute()
    xs = (np.arange(32) + 0.5) / 32 * 6.0 - 3.0
    X, Y = np.meshgrid(xs, xs, indexing="xy")
    P = np.stack([X, Y, np.zeros_like(X)], -1)                  # row 0 at y = -3
    w = lamps[None, None] - P[:, :, None]                       # (32, 32, 12, 3)
    d2 = (w * w).sum(-1)
    each = 0.8 / math.pi * (100.0 + 10.0 * np.arange(12)) / (4 * math.pi * d2) * \
        w[..., 2] / np.sqrt(d2)
    # where the segment to each lamp crosses the plate's height (1 m below the lamps)
    cross = lamps[None, None, :, :2] - w[..., :2] / 3.0
    inf = np.abs(cross - plate[:2]).max(-1)
    blocked = inf < 0.3
    clear = (np.abs(inf - 0.3) > 0.03).all(-1)                  # no pixel on a shadow's edge
    assert blocked[..., -1].sum() > 8                          # the last lamp's shadow

    frame = scenes.render_exr(tmp_path / "twelve.exr")[::-1, :, 0]
    expected = np.where(blocked, 0.0, each).sum(-1)
    np.testing.assert_allclose(frame[clear], expected[clear], rtol=0.01)
    assert any("12 local lamps draw 72 cube faces at 512²" in m for m in runtime.LAST_MESSAGES)

    from prt_relight.addon.frame import sources
    monkeypatch.setattr(sources, "CUBE_BUDGET", 6 * sources.CUBE_TILE_MIN ** 2)
    frame = scenes.render_exr(tmp_path / "budget.exr")[::-1, :, 0]
    expected = np.where(blocked & (np.arange(12) == 0), 0.0, each).sum(-1)
    np.testing.assert_allclose(frame[clear], expected[clear], rtol=0.01)
    named = [m for m in runtime.LAST_MESSAGES if "past the atlas's budget" in m]
    assert len(named) == 1 and "11 local lamps" in named[0] and "'Lamp" in named[0] \
        and "and 3 more" in named[0], runtime.LAST_MESSAGES


def test_light_tiles_draw_the_frame_every_light_loop_draws(tmp_path, monkeypatch):
    """An area lamp, ten narrow spots with a sun exported among them, and a point lamp (the
    pass holds the distant sources first, then the point and spot lamps, then the area
    lamps): the frame drawn through the light tiles is the frame drawn without them, so each
    tile's list names the lights of each group in the pass's own order."""
    scenes.reset()
    black_world()
    ground = scenes.add_ground(size=8.0, cuts=8)
    ground.data.materials.append(scenes.bsdf_material("Lambert", "ShaderNodeBsdfDiffuse",
                                                      Color=(0.8, 0.8, 0.8, 1.0)))
    area_lamp(60.0, (2.5, 2.5, 1.5), 1.0, rotation=(0.4, 0.0, 0.0))
    local_lamp("POINT", 80.0, (-2.5, 2.5, 1.5), radius=0.05)
    for k in range(10):
        if k == 5:
            sun_lamp(1.0, 0.05, tilt=0.3)
        local_lamp("SPOT", 300.0 + 40.0 * k, (-3.0 + 0.65 * k, 0.4 * (k % 3) - 0.4, 2.0),
                   radius=0.05, size=0.5)
    scene = _top_view(3.0, 7.5, 48, 48)
    bpy.ops.prt.precompute()
    from prt_relight.addon.gpu import light_tiles
    tiled = scenes.render_exr(tmp_path / "tiled.exr")[..., :3]
    monkeypatch.setattr(light_tiles, "TILED_FROM", 1000)
    every = scenes.render_exr(tmp_path / "every.exr")[..., :3]
    lit = every.max(-1) > 1.5 * every.min()              # the spots' pools on the sun's light
    assert 0.05 < lit.mean() < 0.8
    np.testing.assert_allclose(tiled, every, rtol=1e-4, atol=1e-6)


def test_instances_share_one_batch_per_source_and_draw_as_placed_copies(tmp_path, monkeypatch):
    """A herd of three collection instances (one turned and scaled unevenly) under a sun
    lamp and a point lamp: the lights pass keeps one set of their source's batches (the
    depth batch placed by each instance's world matrix in the shadow maps, the normals
    turned by its normal matrix), each instance only its positions; the surface pass draws
    every instance with its source's one index buffer; and the frame is the frame of
    per-instance world-space batches and index arrays."""
    from prt_relight.addon.blender import surfaces
    from prt_relight.addon.gpu import drawing, lights
    instancers = scenes.instanced_herd("COLLECTION", count=3, size=(48, 36))
    instancers[1].scale = (1.3, 0.8, 1.1)
    sun_lamp(3.0, math.radians(2.0), tilt=0.5)
    local_lamp("POINT", 300.0, (1.0, -1.0, 2.5), radius=0.05)
    scene = bpy.context.scene
    scene.prt.method = "SH"
    assert bpy.ops.prt.precompute() == {"FINISHED"}

    def kinds():
        keys = list(lights.BATCHES)
        return (sum(1 for k in keys if k[0] == "source"),
                sum(1 for k in keys if k[-1] == "placed"), len(keys))
    lights.BATCHES.clear()
    made, index_buffer = [], drawing.index_buffer
    monkeypatch.setattr(drawing, "index_buffer", lambda tri: made.append(1) or index_buffer(tri))
    shared = scenes.render_exr(tmp_path / "shared.exr")
    assert kinds() == (1, 3, 5)              # the source's, three instances', the ground's
    assert len(made) == 2                    # the surface pass's: the source's, the ground's
    # each instance its own index array, as before instances shared them
    monkeypatch.setattr(drawing, "index_buffer", lambda tri: tri)

    monkeypatch.setattr(surfaces.SharedArrays, "source", lambda self, surface, arrays: None)
    lights.BATCHES.clear()
    placed = scenes.render_exr(tmp_path / "placed.exr")
    assert kinds() == (0, 0, 4)              # each instance's own, the ground's
    assert np.abs(placed[..., :3]).max() > 0.0
    np.testing.assert_allclose(shared[..., :3], placed[..., :3], rtol=1e-4,
                               atol=1e-5 * np.abs(placed[..., :3]).max())

    # a flattened instance (its normals repaired per instance) keeps batches of its own
    monkeypatch.undo()
    instancers[2].scale = (1.0, 1.0, 0.0)
    lights.BATCHES.clear()
    flat = scenes.render_exr(tmp_path / "flat.exr")
    assert kinds() == (1, 2, 5)
    assert np.isfinite(flat).all() and flat[..., :3].min() >= 0.0


def test_a_slot_compiles_in_the_lobes_of_the_roughness_nodes_it_mixes():
    """slot_features: a textured Roughness mixes node rows 4k + 4 (lights_frag.glsl param), so
    their shared lobes are compiled in; a node whose lobe count differs leaves the count to
    the run time, and without a textured Roughness row 0 alone decides."""
    from prt_relight.addon.gpu import lights
    nodes = 3
    params = np.zeros((4 + 4 * nodes, 32, 4), np.float32)
    params[0, 1] = (0.25, 0.0, 2.0, 1.0)            # row 0: Beckmann, two lobes (not read)
    params[0, 11, 0] = nodes
    for k in range(nodes):
        params[4 + 4 * k, 1] = (0.1 + 0.2 * k, 1.0, 1.0, 1.0)    # GGX, one dielectric lobe
        params[4 + 4 * k, 2, 0] = 2.0
    got = lights.slot_features(params, None)
    assert "ROUGH_TEX" in got and "GLOSSY" in got
    assert {"LOBE_DIST 1", "LOBE_COUNT 1", "LOBE_KIND0 2"} <= set(got)
    params[8, 1, 2] = 0.0                            # one node without a lobe
    got = lights.slot_features(params, None)
    assert "LOBE_COUNT 1" not in got and "LOBE_DIST 1" in got
    params[0, 11, 0] = 0.0                           # no textured Roughness: row 0's lobes
    assert {"LOBE_DIST 0", "LOBE_COUNT 2"} <= set(lights.slot_features(params, None))

