"""GPU drawing shared by the viewport and final renders.

:func:`draw_frame` draws one frame into the bound framebuffer: the world as
background (unless the film is transparent), then every object's triangles
with per-vertex linear radiance.  The viewport and F12 call the same function;
only the matrices and the target differ.
"""

from __future__ import annotations

import contextlib

import bpy  # noqa: F401  (Blender's ``gpu`` module is importable once bpy is)
import gpu
import numpy as np
from gpu_extras.batch import batch_for_shader

from ...core.common.cache import Cache, clear_all
from ...core.shading import pixel_filter
from . import shaders

#: width of the data textures whose texels run on across rows (a shading point's stored
#: visibility, SSDF_SG's coefficients and pair table): texel i is (i % ROW_TEXELS, i // ROW_TEXELS)
ROW_TEXELS = 4096


def gpu_cache(initial: dict | None = None, limit: int = 64, name: str = "") -> Cache:
    """A cache of GPU objects (shaders, batches, textures; ``addon.frame.keys``' policy: at most
    ``limit`` entries, least recently used dropped), emptied by :func:`free_gpu_resources`
    (``initial``: entries to start with)."""
    import sys
    cache = Cache(limit, name, gpu=True, module=sys._getframe(1).f_globals.get("__name__", ""))
    cache.update(initial or {})
    return cache


def free_gpu_resources():
    """Drop every cached GPU object while Blender's GPU context still exists: on
    unregister, and at interpreter exit before Blender's own exit handler frees the
    context (Python collecting a texture or shader after that crashes)."""
    clear_all(gpu=True)
    import gc
    gc.collect()


#: the background's quad
_QUAD = gpu_cache({}, limit=1)


# whether the gpu module has been readied in -b (:func:`ensure_gpu`)
_GPU_READY = False


def ensure_gpu(scene):
    """In ``-b`` the gpu module needs one Workbench render before offscreen drawing."""
    if _GPU_READY or not bpy.app.background:
        return
    with temporary_camera(scene):
        r = scene.render
        saved = (r.engine, r.resolution_x, r.resolution_y, r.resolution_percentage)
        try:
            _workbench_render(scene)
        finally:
            r.engine, r.resolution_x, r.resolution_y, r.resolution_percentage = saved


@contextlib.contextmanager
def temporary_camera(scene):
    """A render needs a camera: without one, a temporary camera in ``scene`` while the
    block runs, removed afterwards with its data (nothing else changes)."""
    if scene.camera is not None:
        yield
        return
    cam_data = bpy.data.cameras.new("PRT temporary camera")
    cam = bpy.data.objects.new("PRT temporary camera", cam_data)
    scene.collection.objects.link(cam)
    scene.camera = cam
    try:
        yield
    finally:
        scene.camera = None
        bpy.data.objects.remove(cam)
        bpy.data.cameras.remove(cam_data)


def _workbench_render(scene):
    global _GPU_READY
    r = scene.render
    r.engine = "BLENDER_WORKBENCH"
    r.resolution_x = r.resolution_y = 8
    r.resolution_percentage = 100
    with bpy.context.temp_override(scene=scene):
        bpy.ops.render.render()
    _GPU_READY = True


def redraw_viewports(self=None, context=None):
    """Property update callback: redraw every 3D viewport."""
    wm = bpy.context.window_manager if context is None else context.window_manager
    for window in getattr(wm, "windows", []):
        for area in window.screen.areas:
            if area.type == "VIEW_3D":
                area.tag_redraw()


def surface_shader(added: bool = False):
    """Per-vertex radiance (shaders/passes/surface_*.glsl); ``added``: its variant drawn
    onto a frame (alpha 0)."""
    return shaders.shader("surface", ("ADDED",) if added else ())


def data_shader():
    """Per-vertex values of a data render pass, unclamped (surface_frag.glsl's DATA)."""
    return shaders.shader("surface", ("DATA",))


def data_batch(positions: np.ndarray, values: np.ndarray, triangles: np.ndarray,
               closed_side: int = 0):
    """:func:`surface_batch` of per-corner data values (C, 3) for :func:`data_shader`."""
    return _corner_batch(data_shader(), positions, values, triangles, closed_side)


def textured_shader(added: bool = False):
    """Per-vertex radiance times a per-pixel colour (shaders/passes/surface_tex_*.glsl)."""
    return shaders.shader("surface_tex", ("ADDED",) if added else ())


# GPU textures of colour inputs, per image content (keys.image_key), and "white"
_ALBEDO_TEXTURES = gpu_cache({}, limit=16, name="albedo textures")


def albedo_texture(pixels: np.ndarray):
    """The GPU texture of a core.scene.textures.ImageTexture's pixels (H, W, 4), row 0 at v = 0."""
    from ..frame.keys import image_key
    key = image_key(pixels)
    tex = _ALBEDO_TEXTURES.get(key)
    if tex is None:
        tex = _ALBEDO_TEXTURES[key] = float_texture(pixels)
    return tex


def source_uniforms(source) -> dict:
    """Push-constant values of a core.scene.textures.ColorSource (texture.glsl); None: a
    slot without one."""
    if source is None:
        return dict(texInfo=(0.0, 0.0, -1.0, 0.0), texMap0=(1.0, 0.0, 0.0),
                    texMap1=(0.0, 1.0, 0.0), mixColor=(0.0, 0.0, 0.0, 0.0))
    tex = source.texture
    interp = ext = 0.0
    map0, map1 = (1.0, 0.0, 0.0), (0.0, 1.0, 0.0)
    if tex is not None:
        interp = {"CLOSEST": 0.0, "LINEAR": 1.0, "CUBIC": 2.0}[tex.interpolation]
        ext = {"REPEAT": 0.0, "EXTEND": 1.0, "CLIP": 2.0, "MIRROR": 3.0}[tex.extension]
        map0, map1 = (tuple(map(float, tex.transform[0])), tuple(map(float, tex.transform[1])))
    mode, mix_colour = 0.0, (0.0, 0.0, 0.0, 0.0)
    if source.mix is not None:
        kind, f, other, first = source.mix
        mode = (1.0 if kind == "MIX" else 2.0) + (0.0 if first else 2.0)
        mix_colour = (*(float(c) for c in other[:3]), float(f))
    return dict(texInfo=(interp, ext, 0.0 if tex is not None else 1.0, mode), texMap0=map0,
                texMap1=map1, mixColor=mix_colour)


def white_texture():
    """A 1x1 white RGBA texture (the colour of a slot without one)."""
    tex = _ALBEDO_TEXTURES.get("white")
    if tex is None:
        tex = _ALBEDO_TEXTURES["white"] = float_texture(np.ones((1, 1, 4), np.float32))
    return tex


def textured_draws(positions, radiance, triangles, closed_side, textures, corner_slots,
                   added: bool = False):
    """Draw callables of an object whose radiance is an ``addon.frame.state.TexturedRadiance``:
    per textured slot a batch multiplying ``radiance.diffuse`` by the slot's colour per
    pixel (plus ``radiance.specular``); the other slots as plain radiance.  ``added``:
    drawn onto a frame already drawn (alpha 0; the caller sets the blending)."""
    tri_slot = corner_slots[triangles[:, 0]]
    draws = []
    rest = ~np.isin(tri_slot, list(textures))
    if rest.any():
        plain = surface_batch(positions, radiance, triangles[rest], closed_side)

        def draw_plain(view_projection, batch=plain):
            sh = surface_shader(added)
            sh.bind()
            sh.uniform_float("viewProjection", view_projection)
            batch.draw(sh)
        draws.append(draw_plain)
    for slot, (source, values) in textures.items():
        sel = triangles[tri_slot == slot]
        if not len(sel):
            continue
        corners = sel.reshape(-1)
        diffuse = np.empty((len(corners), 4), np.float32)
        diffuse[:, :3] = radiance.diffuse[corners]
        diffuse[:, 3] = float(closed_side)
        uv = np.zeros((len(corners), 2), np.float32)
        attr = np.ones((len(corners), 4), np.float32)
        if source.texture is not None:
            uv[:] = values[corners]
        else:
            attr[:] = values[corners]
        batch = batch_for_shader(textured_shader(), "TRIS", {
            "pos": np.ascontiguousarray(positions[corners], dtype=np.float32),
            "diffuse": diffuse,
            "specular": np.ascontiguousarray(radiance.specular[corners], dtype=np.float32),
            "uv": uv, "attr": attr})
        tex = albedo_texture(source.texture.pixels) if source.texture is not None \
            else white_texture()
        uniforms = source_uniforms(source)

        def draw_textured(view_projection, batch=batch, tex=tex, uniforms=uniforms):
            sh = textured_shader(added)
            sh.bind()
            sh.uniform_float("viewProjection", view_projection)
            for name, value in uniforms.items():
                sh.uniform_float(name, value)
            sh.uniform_sampler("albedoTex", tex)
            batch.draw(sh)
        draws.append(draw_textured)
    return draws


def background_shader():
    """The world behind the objects (shaders/passes/background_*.glsl)."""
    return shaders.shader("background")


def float_texture(rgba: np.ndarray):
    """A RGBA32F GPU texture from (H, W, 4) float32 (row 0 = texture t = 0)."""
    h, w, _ = rgba.shape
    flat = np.ascontiguousarray(rgba, dtype=np.float32).reshape(-1)
    buf = gpu.types.Buffer("FLOAT", flat.size, flat)
    return gpu.types.GPUTexture((w, h), format="RGBA32F", data=buf)


def surface_batch(positions: np.ndarray, radiance: np.ndarray, triangles,
                  closed_side: int = 0):
    """Batch of one object's corners: positions (C, 3), radiance (C, 3), triangles (T, 3)
    or a GPUIndexBuf of them (:func:`index_buffer`).  ``closed_side``
    (core.scene.mesh.closed_side) rides in the radiance's alpha: the shader draws a closed
    mesh's inner side black."""
    return _corner_batch(surface_shader(), positions, radiance, triangles, closed_side)


def index_buffer(triangles: np.ndarray):
    """A GPUIndexBuf of ``triangles`` (T, 3), for batches that share one
    (:func:`surface_batch`: instances of one source)."""
    return _index(triangles)


def _index(triangles):
    return gpu.types.GPUIndexBuf(type="TRIS",
                                 seq=np.ascontiguousarray(triangles, dtype=np.int32))


# vertex formats per attribute names and lengths (vertex_buffer)
_FORMATS = gpu_cache({}, limit=16, name="vertex formats")


def vertex_buffer(columns):
    """A GPUVertBuf of float attributes ``columns`` ((name, (N, n) values), ...), its format
    made once per names and lengths."""
    columns = [(name, np.ascontiguousarray(data, dtype=np.float32)) for name, data in columns]
    layout = tuple((name, data.shape[1]) for name, data in columns)
    fmt = _FORMATS.get(layout)
    if fmt is None:
        fmt = _FORMATS[layout] = gpu.types.GPUVertFormat()
        for name, n in layout:
            fmt.attr_add(id=name, comp_type="F32", len=n, fetch_mode="FLOAT")
    vbo = gpu.types.GPUVertBuf(fmt, len(columns[0][1]))
    for name, data in columns:
        vbo.attr_fill(name, data)
    return vbo


def _corner_batch(shader, positions, values, triangles, closed_side):
    rgba = np.empty((len(values), 4), dtype=np.float32)
    rgba[:, :3] = values
    rgba[:, 3] = float(closed_side)
    elem = triangles if isinstance(triangles, gpu.types.GPUIndexBuf) else _index(triangles)
    return gpu.types.GPUBatch(type="TRIS", buf=vertex_buffer((("pos", positions),
                                                              ("radiance", rgba))), elem=elem)


def _quad_batch():
    quad = _QUAD.get("quad")
    if quad is None:
        quad = _QUAD["quad"] = batch_for_shader(
            background_shader(), "TRIS", {"ndc": [(-1, -1), (1, -1), (1, 1), (-1, 1)]},
            indices=[(0, 1, 2), (0, 2, 3)])
    return quad


def draw_frame(batches, background, view_projection, transparent: bool, object_draws=(),
               added_draws=(), shader=None, keep=None):
    """Draw into the bound framebuffer.  ``background`` = (texture, rotation 4x4, strength);
    ``object_draws``: callables ``draw(view_projection)`` of a per-pixel method;
    ``added_draws``: callables whose output is added onto the surfaces already drawn
    (depth test equal, no depth writes: the per-pixel sharp lobes); ``shader``: what
    ``batches`` are drawn with (the per-vertex radiance shader unless given); ``keep``:
    adaptive anti-aliasing's (samples per axis, mask texture, pilot texture): the samples of
    every pixel the mask leaves out take the pilot's pixel, and nothing else is drawn there."""
    fb = gpu.state.active_framebuffer_get()
    fb.clear(color=(0.0, 0.0, 0.0, 0.0), depth=1.0)
    gpu.state.blend_set("NONE")
    gpu.state.face_culling_set("NONE")
    if keep is not None:
        _keep_pilot(keep, first=True)
    gpu.state.depth_test_set("LESS_EQUAL")
    gpu.state.depth_mask_set(True)
    sh = surface_shader() if shader is None else shader
    sh.bind()
    sh.uniform_float("viewProjection", view_projection)
    for batch in batches:
        batch.draw(sh)
    for draw in object_draws:
        draw(view_projection)
    if added_draws:
        gpu.state.depth_mask_set(False)
        gpu.state.blend_set("ADDITIVE_PREMULT")
        for draw in added_draws:
            draw(view_projection)
        gpu.state.blend_set("NONE")
    if not transparent and background is not None:
        # last, at the far plane: only the samples no surface covers read the world
        texture, rotation, strength = background
        gpu.state.depth_test_set("LESS_EQUAL")
        gpu.state.depth_mask_set(False)
        sh = background_shader()
        sh.bind()
        sh.uniform_float("invViewProjection", view_projection.inverted())
        sh.uniform_float("texRotation", rotation)
        sh.uniform_float("strength", float(strength))
        sh.uniform_sampler("envMap", texture)
        _quad_batch().draw(sh)
    if keep is not None:
        _keep_pilot(keep, first=False)
    gpu.state.depth_test_set("NONE")
    gpu.state.depth_mask_set(False)


def _keep_pilot(keep, first: bool):
    """Adaptive anti-aliasing's quad (shaders/passes/adaptive_frag.glsl): ``first``, the
    near-plane depth alone over the kept pixels' samples (no later draw reaches them); then
    their colour, the pilot's pixel (depth test equal)."""
    samples, mask_tex, pilot_tex = keep
    sh = shaders.shader("adaptive")
    if first:
        gpu.state.depth_test_set("ALWAYS")
        gpu.state.depth_mask_set(True)
        gpu.state.color_mask_set(False, False, False, False)
    else:
        gpu.state.depth_test_set("EQUAL")
        gpu.state.depth_mask_set(False)
        gpu.state.blend_set("NONE")
    sh.bind()
    sh.uniform_int("samples", int(samples))
    sh.uniform_sampler("maskTex", mask_tex)
    sh.uniform_sampler("pilotTex", pilot_tex)
    batch_for_shader(sh, "TRIS", {"ndc": [(-1, -1), (1, -1), (1, 1), (-1, 1)]},
                     indices=[(0, 1, 2), (0, 2, 3)]).draw(sh)
    if first:
        gpu.state.color_mask_set(True, True, True, True)


def render_offscreen(batches, background, view_projection, width, height, transparent,
                     object_draws=(), added_draws=(), shader=None, supersampling: int = 1,
                     filter_width: float = 0.0, adaptive: float = 0.0, pilot_draws=None):
    """Draw a frame offscreen (:func:`draw_frame`); return linear RGBA (height, width, 4),
    bottom row first.  With ``supersampling`` s > 1 the frame is drawn at s times the size
    per axis and resolved on the GPU with the pixel filter of ``filter_width`` pixels
    (:func:`resolve`), so only its pixels are read back.  ``adaptive`` > 0: a pilot frame of
    one sample per pixel first (``pilot_draws``: its added draws, else ``added_draws``), and
    only the pixels core.shading.pixel_filter.refine_mask picks at that threshold, and those
    no surface covers, are drawn with every sample; the others' samples are the pilot's pixel."""
    s = max(1, int(supersampling))
    keep = None
    if s > 1 and adaptive > 0.0:
        pilot = _pilot(batches, view_projection, width, height, object_draws,
                       added_draws if pilot_draws is None else pilot_draws, shader)
        # the sky between the objects is cheap: every sample, as without the pilot (a kept
        # pixel is covered: its neighbours' coverage is the same as its own)
        mask = pixel_filter.refine_mask(pilot, adaptive) | (pilot[..., 3] < 0.5)
        if not mask.all():
            rgba = np.zeros(pilot.shape, np.float32)
            rgba[..., 0] = mask
            keep = (s, float_texture(rgba), float_texture(pilot))
    offscreen = gpu.types.GPUOffScreen(width * s, height * s, format="RGBA32F")
    try:
        with offscreen.bind():
            draw_frame(batches, background, view_projection, transparent, object_draws,
                       added_draws, shader, keep)
            if s == 1:
                return _read(gpu.state.active_framebuffer_get(), width, height)
        return resolve(offscreen.texture_color, width, height, s, filter_width)
    finally:
        offscreen.free()


def _pilot(batches, view_projection, width, height, object_draws, added_draws, shader):
    """Adaptive anti-aliasing's pilot: the frame at one sample per pixel without the sky,
    (height, width, 4): its alpha is the surfaces' coverage."""
    offscreen = gpu.types.GPUOffScreen(width, height, format="RGBA32F")
    try:
        with offscreen.bind():
            draw_frame(batches, None, view_projection, True, object_draws, added_draws, shader)
            return _read(gpu.state.active_framebuffer_get(), width, height)
    finally:
        offscreen.free()


def texel_pass(shader, width: int, rows: int, ints=(), floats=(), samplers=()) -> np.ndarray:
    """Run a pass that writes one texel per item (RSL's and REFERENCE's per-point passes) into
    a (width, rows) RGBA32F target and read it back, (rows * width, 4) float32; ``ints``,
    ``floats``, ``samplers``: (name, value) pairs bound first."""
    offscreen = gpu.types.GPUOffScreen(width, rows, format="RGBA32F")
    try:
        with offscreen.bind():
            fb = gpu.state.active_framebuffer_get()
            fb.clear(color=(0.0, 0.0, 0.0, 0.0))
            gpu.state.depth_test_set("NONE")
            gpu.state.blend_set("NONE")
            shader.bind()
            for name, value in ints:
                shader.uniform_int(name, value)
            for name, value in floats:
                shader.uniform_float(name, value)
            for name, texture in samplers:
                shader.uniform_sampler(name, texture)
            batch_for_shader(shader, "TRIS", {"ndc": [(-1, -1), (1, -1), (1, 1), (-1, 1)]},
                             indices=[(0, 1, 2), (0, 2, 3)]).draw(shader)
            return _read(fb, width, rows).reshape(rows * width, 4)
    finally:
        offscreen.free()


def gpu_available() -> bool:
    """A GPU pass can run: the main thread of a Blender with a GPU context."""
    import threading
    if threading.current_thread() is not threading.main_thread():
        return False
    try:
        return gpu.platform.backend_type_get() != "NONE"
    except Exception:
        return False


def software_gpu() -> bool:
    """The GPU is a software rasterizer (Mesa's llvmpipe: ``gpu.platform.device_type_get()``
    SOFTWARE), where BLAS on the same cores beats a per-point loop over a dense sum."""
    try:
        return gpu.platform.device_type_get() == "SOFTWARE"
    except Exception:
        return True


def _read(fb, width, height):
    buf = fb.read_color(0, 0, width, height, 4, 0, "FLOAT")
    buf.dimensions = width * height * 4
    return np.array(buf, dtype=np.float32).reshape(height, width, 4)


def _taps_texture(pixels, s, filter_width):
    """(margin, tap count, R32F texture of the taps, a row per pixel)."""
    margin, weights = pixel_filter.resolve_taps(pixels, s, filter_width)
    flat = np.ascontiguousarray(weights, dtype=np.float32).reshape(-1)
    tex = gpu.types.GPUTexture((weights.shape[1], pixels), format="R32F",
                               data=gpu.types.Buffer("FLOAT", flat.size, flat))
    return margin, weights.shape[1], tex


def resolve(texture, width, height, s, filter_width):
    """A (width·s, height·s) frame texture resolved to (height, width, 4) pixels with the
    pixel filter (core.shading.pixel_filter.resolve_taps), x then y, on the GPU."""
    sh = shaders.shader("resolve")
    quad = batch_for_shader(sh, "TRIS", {"ndc": [(-1, -1), (1, -1), (1, 1), (-1, 1)]},
                            indices=[(0, 1, 2), (0, 2, 3)])
    across = gpu.types.GPUOffScreen(width, height * s, format="RGBA32F")
    out = gpu.types.GPUOffScreen(width, height, format="RGBA32F")
    try:
        for axis, source, target, pixels in ((0, texture, across, width),
                                             (1, None, out, height)):
            margin, taps, tap_tex = _taps_texture(pixels, s, filter_width)
            with target.bind():
                gpu.state.depth_test_set("NONE")
                gpu.state.blend_set("NONE")
                sh.bind()
                for name, value in (("axis", axis), ("samples", s), ("margin", margin),
                                    ("taps", taps)):
                    sh.uniform_int(name, value)
                sh.uniform_sampler("frameTex", source if source is not None
                                   else across.texture_color)
                sh.uniform_sampler("tapTex", tap_tex)
                quad.draw(sh)
                if axis == 1:
                    return _read(gpu.state.active_framebuffer_get(), width, height)
    finally:
        across.free()
        out.free()


def triangle_corners(st):
    """Per drawn corner (three per triangle, unshared) of a synced object: positions,
    normals, the shading point of each of its triangle's corners and its barycentric
    weights -- what the per-pixel passes interpolate stored per-point data with."""
    arrays, pts = st.arrays, st.points
    tri = arrays.triangles
    corner = tri.reshape(-1)
    pos = arrays.positions[arrays.corner_verts[corner]].astype(np.float32)
    nrm = arrays.corner_normals[corner].astype(np.float32)
    tri_points = np.repeat(pts.point_of_corner[tri].astype(np.float32), 3, axis=0)
    bary = np.tile(np.eye(3, dtype=np.float32), (len(tri), 1))
    return pos, nrm, tri_points, bary

