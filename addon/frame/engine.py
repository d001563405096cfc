"""The ``PRT_RELIGHT`` render engine: Rendered viewport and F12 from one drawing routine."""

from __future__ import annotations

import copy
import threading

import bpy
import gpu
import numpy as np
from gpu_extras.presets import draw_texture_2d
from mathutils import Matrix

from ...core.scene import mesh as core_mesh
from ...core.sphere import envmap
from ...core.common.parallel import Cancelled
from ...core.pipeline import frame_status
from ..gpu import drawing, lights, sharp
from . import passes
from .state import FrameState, TexturedRadiance


def monotonic_progress(update):
    """``update(fraction)`` called only when the fraction grows (F12's progress bar:
    parts of a frame report in their own spans, and a span may tick back)."""
    last = [0.0]

    def report(fraction):
        if fraction > last[0]:
            last[0] = fraction
            update(float(fraction))
    return report


def _background(state: FrameState):
    """(texture, rotation, strength) for drawing the world, cached on the state."""
    world = state.full_world if state.full_world is not None else state.world
    cached = state.background
    # the texture holds the pixels (rotation and strength are drawn as uniforms): a turned
    # World (FrameState.relit) shares the exported pixel array
    if cached is not None and (cached[0] is world or (
            world.image is not None and cached[0].image is world.image)):
        tex = cached[1]
    else:
        if world.image is not None:
            img = envmap.display_equirect(world.image)     # at most 8k wide on the GPU
            rgba = np.ones(img.shape[:2] + (4,), dtype=np.float32)
            rgba[:, :, :3] = img
        else:
            rgba = np.ones((1, 1, 4), dtype=np.float32)
            rgba[0, 0, :3] = world.color
        tex = drawing.float_texture(rgba)
        state.background = (world, tex)
    R = Matrix([[float(v) for v in row] for row in world.rotation])
    return tex, R, world.strength


def _batches(state: FrameState, radiance_per_object):
    """(plain batches, draw callables of textured objects) of per-corner radiance."""
    batches, draws = [], []
    shared = {}
    for st, rad in zip(state.objects, radiance_per_object):
        if isinstance(rad, TexturedRadiance):
            positions = st.arrays.positions[st.arrays.corner_verts]
            draws += drawing.textured_draws(positions, rad, st.arrays.triangles,
                                            st.closed_side, st.textures,
                                            st.arrays.corner_materials)
        else:
            batches.append(_plain_batch(st, rad, shared))
    return batches, draws


def _plain_batch(st, radiance, shared):
    """The surface batch of ``st``'s per-corner ``radiance``: one vertex per shading point
    where every corner has its point's radiance (the per-vertex methods' radiance: the same
    positions, triangles and values, a quarter of the vertices on a smooth mesh), else one
    per corner.  ``shared``: the frame's index buffers per pair of index arrays (instances
    share their source's: one buffer, not one per instance)."""
    rows = core_mesh.per_point(st.points, radiance)
    if rows is not None:
        poc, tri = st.points.point_of_corner, st.arrays.triangles
        key = (id(poc), id(tri))
        if key not in shared:        # the arrays held with it: their ids stay theirs
            shared[key] = (poc, tri, drawing.index_buffer(poc[tri]))
        return drawing.surface_batch(st.points.positions, rows, shared[key][2],
                                     st.closed_side)
    return drawing.surface_batch(st.arrays.positions[st.arrays.corner_verts], radiance,
                                 st.arrays.triangles, st.closed_side)


def _bounce_draws(state: FrameState, eye, view_dir):
    """A per-pixel method's bounced light, per corner, added onto its frame (a per-vertex
    method's is in its radiance already: ``FrameState.shade``)."""
    draws = []
    for st, (rad, unit, spec) in zip(state.objects, state.bounced_radiance(eye, view_dir)):
        if rad is None:
            continue
        positions = st.arrays.positions[st.arrays.corner_verts]
        draws += drawing.textured_draws(
            positions, TexturedRadiance.of(rad, unit, spec), st.arrays.triangles,
            st.closed_side, st.textures, st.arrays.corner_materials, added=True)
    return draws


def _eye(view_matrix, is_perspective: bool):
    """(eye, None) for a perspective view, (None, unit direction toward the viewer) for
    an orthographic one: the view's +Z axis in world space."""
    inv = np.linalg.inv(np.array(view_matrix, dtype=np.float64))
    if is_perspective:
        return inv[:3, 3].copy(), None
    forward = inv[:3, 2]
    return None, forward / max(float(np.linalg.norm(forward)), 1e-30)


def _panoramic(camera) -> bool:
    """Whether a scene camera is a panoramic one (not drawn: no rasterised projection)."""
    return camera.type == "CAMERA" and camera.data.type == "PANO"


def frame_camera(view: Matrix, projection: Matrix, width: int, height: int, eye,
                 view_dir) -> dict:
    """The camera a frame is drawn with, for methods that weigh errors by what the image
    shows (AUTO): world-to-clip matrix, size in pixels, eye (perspective) or direction
    toward an orthographic camera (as :func:`_eye` returns them)."""
    return dict(clip=np.array(projection @ view, dtype=np.float64), width=int(width),
                height=int(height), eye=eye, view_dir=view_dir)


def world_updates(depsgraph) -> list:
    """Per ID the viewport's update names: (its type name, whether it is the scene's World
    or the World's own node tree), what core.pipeline.frame_status.world_only reads."""
    world = depsgraph.scene.world
    mine = [] if world is None else [x for x in (world, world.node_tree) if x is not None]
    out = []
    for update in depsgraph.updates:
        ident = update.id
        original = getattr(ident, "original", ident)
        out.append((type(ident).__name__, any(original == x for x in mine)))
    return out


def render_view(scene, depsgraph):
    """F12's view of ``scene``: (view, projection, width, height, perspective) of its camera
    at the render size, or None when it has no camera."""
    camera = scene.camera
    if camera is None:
        return None
    r = scene.render
    width = max(1, int(r.resolution_x * r.resolution_percentage / 100))
    height = max(1, int(r.resolution_y * r.resolution_percentage / 100))
    cam_eval = camera.evaluated_get(depsgraph)
    projection = cam_eval.calc_matrix_camera(depsgraph, x=width, y=height,
                                             scale_x=r.pixel_aspect_x, scale_y=r.pixel_aspect_y)
    persp = not (cam_eval.type == "CAMERA" and cam_eval.data.type == "ORTHO")
    # the camera object's scale is no part of the view (Blender renders it so)
    return cam_eval.matrix_world.normalized().inverted(), projection, width, height, persp


def render_camera(scene, depsgraph) -> dict | None:
    """:func:`frame_camera` of F12's view (None without a camera): what AUTO's stored
    choice is weighed by."""
    got = render_view(scene, depsgraph)
    if got is None:
        return None
    view, projection, width, height, persp = got
    return frame_camera(view, projection, width, height, *_eye(view, persp))


#: the supersampling whose per-sample taps adaptive anti-aliasing's pilot frame takes
PILOT_SUPERSAMPLING = 2


def draw_pixels(state: FrameState, radiance, view: Matrix, projection: Matrix, width: int,
                height: int, transparent: bool, supersampling: int = 1,
                object_draws=None, filter_width: float = 0.0, eye=None,
                view_dir=None, adaptive: float = 0.0, release: bool = False) -> np.ndarray:
    """Draw per-corner ``radiance`` (or a per-pixel method's ``object_draws``) offscreen:
    linear RGBA (height, width, 4), bottom row first.

    With ``supersampling`` > 1 the samples are resolved with Cycles' Blackman-Harris pixel
    filter of ``filter_width`` pixels (the scene's Film *Filter Size*; 0 = each pixel's
    own samples averaged), so an F12 frame is filtered as Cycles filters its samples.
    ``eye`` / ``view_dir`` (as :func:`_eye` gives them) let the per-pixel sharp lobes
    (:mod:`.sharp`) be added; without either they are not drawn.  ``adaptive`` > 0: only the
    pixels a one-sample pilot frame finds differing from a neighbour by that contrast get
    every sample (drawing.render_offscreen; the scene's Adaptive Threshold).  ``release``:
    the ``radiance`` list is emptied once the batches hold its values (an F12 frame's
    largest arrays then do not live through the per-pixel passes)."""
    batches, textured = ([], []) if object_draws is not None else _batches(state, radiance)
    if release and radiance is not None:
        radiance.clear()
    s = max(1, int(supersampling))
    background = _background(state)
    seen = eye is not None or view_dir is not None
    lit, lit_pilot = lights.draws(state, eye, view_dir, s, PILOT_SUPERSAMPLING) if seen \
        else ([], [])
    added = (sharp.draws(state, eye, view_dir, background) + lit) if seen else []
    bounced = _bounce_draws(state, eye, view_dir) \
        if object_draws is not None and state.bounce is not None else []
    pilot = None
    if adaptive > 0.0 and s > 1 and added:
        # the pilot's one sample per pixel takes the shadow taps and glossy samples of a
        # 2×2-supersampled sample (half of one sample per pixel's): a pixel it keeps is smooth
        # by its own measure (three lamps: 0.07 % from the uniform 3×3, 0.06 % with every
        # tap, the frame 20 % faster; docs/measurements.md)
        pilot = sharp.draws(state, eye, view_dir, background) + lit_pilot + bounced
    return drawing.render_offscreen(batches, background, projection @ view, width, height,
                                    transparent, object_draws=list(object_draws or ()) + textured,
                                    added_draws=added + bounced, supersampling=s,
                                    filter_width=filter_width, adaptive=adaptive,
                                    pilot_draws=pilot)


def render_pixels(state: FrameState, view: Matrix, projection: Matrix, width: int, height: int,
                  transparent: bool, is_perspective: bool, supersampling: int = 1,
                  filter_width: float = 0.0, adaptive: float = 0.0) -> np.ndarray:
    """Shade for this view and draw: the engine's one drawing path (viewport and F12)."""
    eye, view_dir = _eye(view, is_perspective)
    state.camera = frame_camera(view, projection, width, height, eye, view_dir)
    # progress (F12: state.tick reports it and stops on ESC): shading, then drawing
    with state.span(0.0, 0.85):
        object_draws = state.draw_objects(eye, view_dir)
        state.visible_only = True
        try:
            radiance = None if object_draws is not None else state.shade(eye,
                                                                          view_dirs_for=view_dir)
        finally:
            state.visible_only = False
    state.tick(0.85)
    pixels = draw_pixels(state, radiance, view, projection, width, height, transparent,
                         supersampling, object_draws=object_draws, filter_width=filter_width,
                         eye=eye, view_dir=view_dir, adaptive=adaptive, release=True)
    state.tick(1.0)
    return pixels


class ViewportShading:
    """Per-vertex radiance for the viewport, recomputed off the main thread when it
    depends on the view and is slow (REFERENCE with glossy or layered materials).

    Meanwhile the geometry is redrawn at once with the newest radiance available, so
    the camera follows the mouse and highlights catch up when the worker finishes
    (a timer then asks Blender to redraw).  numpy releases the GIL, so the UI stays
    responsive.  A method whose per-view sums run on a hardware GPU (REFERENCE's pass,
    ``Shading.shades_on_gpu``) shades on the main thread at once instead.
    """

    def __init__(self):
        self.radiance = None         # newest finished result
        self.layout = None           # (object name, corner count) tuples it belongs to
        self.key = None              # (state id, eye/view key) it was computed for
        self.worker = None
        self.result = None
        self.version = 0             # bumped whenever ``radiance`` changes

    @staticmethod
    def layout_of(state: FrameState):
        return tuple((st.name, len(st.arrays.corner_verts)) for st in state.objects)

    def radiance_for(self, state: FrameState, eye, view_dir, on_done):
        key = (id(state), None if eye is None else tuple(np.round(eye, 6)),
               None if view_dir is None else tuple(np.round(view_dir, 6)))
        self._collect()
        if key == self.key:
            return self.radiance
        layout = self.layout_of(state)
        # AUTO about to measure (no stored choice holds): off the main thread from the
        # first frame, drawn meanwhile with what there is (unlit at first)
        slow = getattr(state.method_impl, "slow_frame", lambda s: False)(state)
        # a view-dependent method whose per-view sums run on a hardware GPU: at once
        if not slow and (not state.view_dependent or state.method_impl.shades_on_gpu(state)
                         or self.radiance is None or self.layout != layout):
            self.radiance = state.shade(eye, view_dirs_for=view_dir)
            self.layout, self.key = layout, key
            self.version += 1
            return self.radiance
        if self.radiance is None or self.layout != layout:
            self.radiance = [np.zeros((len(st.arrays.corner_verts), 3), np.float32)
                             for st in state.objects]
            self.layout = layout
        if self.worker is None:
            def work():
                try:
                    self.result = (state.shade(eye, view_dirs_for=view_dir), layout, key)
                except Exception as exc:           # shown as stale; never breaks drawing
                    self.result = (None, layout, key)
                    print("PRT Relight: viewport shading failed:", exc)
            self.worker = threading.Thread(target=work, name="prt-view-shading", daemon=True)
            self.worker.start()
            on_done(self.worker)
        return self.radiance

    def _collect(self):
        if self.worker is not None and not self.worker.is_alive():
            self.worker = None
            radiance, layout, key = self.result
            if radiance is not None:
                self.radiance, self.layout, self.key = radiance, layout, key
                self.version += 1


def data_passes(state, layer, frame) -> dict:
    """The view layer's data passes, Ambient Occlusion and Environment (passes.py)."""
    view, projection, width, height, _, _, s, filter_width, _ = frame
    out = {}
    for attr, name, _, _, _ in passes.DATA_PASSES:
        if not getattr(layer, attr, False):
            continue
        state.tick()
        if name == "Environment":     # the World seen directly, the objects black
            black = [np.zeros((len(st.arrays.corner_verts), 3), np.float32)
                     for st in state.objects]
            out[name] = draw_pixels(state, black, view, projection, width, height, False,
                                    s, filter_width=filter_width)[..., :3]
        else:
            out[name] = passes.data_pass(state, name, view, projection, width, height, s,
                                         filter_width)
    return out


def light_passes(state, frame) -> dict:
    """Diffuse / Glossy Direct, Indirect and Color (passes.LIGHT_PASSES): the frame drawn
    again without bounced light with its own base colours and with black ones (glossy),
    the bounced light alone, and the base colours; each light pass is its part over its
    colour pass (Cycles' division).  The bounced light's glossy part (FrameState.
    bounced_radiance) is Glossy Indirect."""
    # every sample everywhere: each pass is divided by another, drawn with its own pilot
    view, projection, width, height, _, persp, s, filter_width, _ = frame
    drawn = (view, projection, width, height, True, persp, s, filter_width)
    direct = render_pixels(_without_bounce(state), *drawn)
    glossy = render_pixels(passes.with_base(state, 0.0), *drawn)
    colour = draw_pixels(state, passes.base_colours(state), view, projection, width, height,
                         True, s, filter_width=filter_width)
    bounced = glossy_bounced = np.zeros_like(colour)
    if state.bounce is not None:
        diffuse, shiny = [], []
        for st, (b, w, g) in zip(state.objects, state.bounced_radiance(*_eye(view, persp))):
            if b is None:
                b = w = g = np.zeros((len(st.arrays.corner_verts), 3), np.float32)
            d = np.asarray(b) - np.asarray(g)           # the diffuse base's, coloured
            diffuse.append(TexturedRadiance.of(d, w, np.zeros_like(d)) if st.textures else d)
            shiny.append(np.asarray(g))
        bounced = draw_pixels(state, diffuse, view, projection, width, height, True, s,
                              filter_width=filter_width)
        glossy_bounced = draw_pixels(state, shiny, view, projection, width, height, True, s,
                                     filter_width=filter_width)
    cover = np.repeat(colour[..., 3:4], 3, axis=2)
    return {"Diffuse Direct": passes.divided(direct[..., :3] - glossy[..., :3],
                                             colour[..., :3]),
            "Diffuse Indirect": passes.divided(bounced[..., :3], colour[..., :3]),
            "Diffuse Color": colour[..., :3],
            "Glossy Direct": passes.divided(glossy[..., :3], cover),
            "Glossy Indirect": passes.divided(glossy_bounced[..., :3], cover),
            "Glossy Color": cover}


def _without_bounce(state):
    sub = copy.copy(state)
    sub.bounce = None
    return sub


#: a function to run inside the next render() instead of drawing (:func:`in_render`)
_RENDER_TASK: list = []


def in_render(scene, task):
    """``task(depsgraph)`` run where the gpu module has a context: in ``-b`` inside a render
    of our engine (the render draws nothing then; ``scene`` needs a camera), elsewhere
    (the UI's main thread, or already inside a render) directly.  Returns its result."""
    if not bpy.app.background or _RENDER_TASK:
        with bpy.context.temp_override(scene=scene):
            return task(bpy.context.evaluated_depsgraph_get())
    box = {}
    _RENDER_TASK.append((task, box))
    saved = scene.render.engine
    try:
        scene.render.engine = PRTRenderEngine.bl_idname
        with bpy.context.temp_override(scene=scene):
            bpy.ops.render.render()
    finally:
        scene.render.engine = saved
        _RENDER_TASK.clear()
    if "error" in box:
        raise box["error"]
    if "result" not in box:
        raise RuntimeError("the render that was to run it did not start")
    return box["result"]


class PRTRenderEngine(bpy.types.RenderEngine):
    bl_idname = "PRT_RELIGHT"
    bl_label = "PRT Relight"
    bl_use_gpu_context = True
    bl_use_preview = False
    bl_use_shading_nodes_custom = False

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        self._state = None
        self._view_texture = None
        self._view_key = None
        self._shading = None

    # ------------------------------------------------------------- final render
    def render(self, depsgraph):
        if _RENDER_TASK and "started" not in _RENDER_TASK[-1][1]:
            task, box = _RENDER_TASK[-1]
            box["started"] = True
            try:
                box["result"] = task(depsgraph)
            except Exception as exc:             # handed back to in_render's caller
                box["error"] = exc
            return
        scene = depsgraph.scene
        r = scene.render
        got = render_view(scene, depsgraph)
        if got is None:
            self.report({"ERROR"}, "PRT Relight: the scene has no camera")
            return
        view, projection, width, height, persp = got
        if _panoramic(scene.camera):
            self.report({"ERROR"}, f"PRT Relight: camera '{scene.camera.name}' is panoramic; "
                        "only perspective and orthographic cameras are drawn: switch its Type "
                        "in the camera properties")
            return
        state = FrameState()
        # progress bar and ESC: every method ticks between objects (REFERENCE, SH and
        # WAVELET between blocks of points; AUTO between measured candidates)
        state.progress = monotonic_progress(self.update_progress)
        state.cancelled = self.test_break
        try:
            self.update_stats("PRT Relight", "Reading the scene")
            with state.span(0.0, 0.1):
                state.sync(depsgraph)
            if state.error:
                self.report({"ERROR"}, "PRT Relight: " + state.error)
            for w in state.warnings:
                self.report({"WARNING"}, "PRT Relight: " + w)
            layer = depsgraph.view_layer
            groups = passes.light_groups(state) if passes.groups_wanted(scene, layer) else []
            # light groups sum to Combined: every frame then takes every sample (each
            # would refine its own pixels)
            frame = (view, projection, width, height, r.film_transparent, persp,
                     scene.prt.supersampling, r.filter_size,
                     0.0 if groups else scene.prt.aa_threshold)
            # Combined, then each light group's frame (as costly as Combined each)
            share = 0.9 / (1 + len(groups))
            self.update_stats("PRT Relight", f"Shading ({state.method}; ESC stops)")
            with state.span(0.1, 0.1 + share):
                pixels = render_pixels(state, *frame)
            extra = {}
            for k, group in enumerate(groups):
                self.update_stats("PRT Relight", f"Light group {group} ({k + 1}/{len(groups)}; "
                                  "ESC stops)")
                with state.span(0.1 + share * (k + 1), 0.1 + share * (k + 2)):
                    extra[f"Combined_{group}"] = render_pixels(passes.muted(state, group),
                                                               *frame)[..., :3]
            extra.update(data_passes(state, layer, frame))
            wanted = {name for attr, name, *_ in passes.LIGHT_PASSES if getattr(layer, attr, False)}
            if wanted:
                self.update_stats("PRT Relight", "Diffuse and glossy passes (ESC stops)")
                extra.update({k: v for k, v in light_passes(state, frame).items()
                              if k in wanted})
        except Cancelled:
            self.update_stats("PRT Relight", "Stopped")
            self.report({"WARNING"}, "PRT Relight: render stopped (ESC); nothing was drawn")
            return
        channels = {name: (n, chan) for name, n, chan, _ in passes.wanted(scene, layer)}
        for name, px in extra.items():
            n = px.shape[-1]
            self.add_pass(name, n, channels.get(name, (n, "RGB" if n == 3 else "Z"))[1],
                          layer=layer.name)
        result = self.begin_result(0, 0, width, height, layer=layer.name)
        result.layers[0].passes["Combined"].rect.foreach_set(
            np.ascontiguousarray(pixels, dtype=np.float32).reshape(-1))
        for name, px in extra.items():
            result.layers[0].passes[name].rect.foreach_set(
                np.ascontiguousarray(px, dtype=np.float32).reshape(-1))
        self.end_result(result)

    def update_render_passes(self, scene=None, renderlayer=None):
        """The passes F12 writes, registered so the compositor's Render Layers node shows
        them (as Cycles registers its own)."""
        self.register_pass(scene, renderlayer, "Combined", 4, "RGBA", "COLOR")
        for name, n, chan, kind in passes.wanted(scene, renderlayer):
            self.register_pass(scene, renderlayer, name, n, chan, kind)

    # ------------------------------------------------------------- viewport
    def view_update(self, context, depsgraph):
        # A new state each time: a shading worker may still be reading the old one.  When
        # the World alone changed (an HDRI turned), the objects are kept: no mesh is read
        # again, only the World's lighting and sources.
        old = self._state
        if old is not None and frame_status.world_only(world_updates(depsgraph)):
            state = old.relit(depsgraph)
        else:
            state = FrameState()
            state.sync(depsgraph)
        self._state = state
        self._view_key = None
        rv3d = getattr(context, "region_data", None)
        camera = depsgraph.scene.camera
        if (rv3d is not None and getattr(rv3d, "view_perspective", "") == "CAMERA"
                and camera is not None and _panoramic(camera)):
            state.warnings.append(f"Camera '{camera.name}' is panoramic: the viewport draws it "
                                  "as a perspective view and F12 refuses it")
        messages = ([self._state.error] if self._state.error else []) + self._state.warnings
        self.update_stats("PRT Relight", " | ".join(messages) if messages else "")

    def view_draw(self, context, depsgraph):
        if self._state is None:
            self.view_update(context, depsgraph)
        if self._shading is None:
            self._shading = ViewportShading()
        state = self._state
        region, rv3d = context.region, context.region_data
        scene = depsgraph.scene
        width, height = region.width, region.height
        eye, view_dir = _eye(rv3d.view_matrix, rv3d.is_perspective)
        state.camera = frame_camera(rv3d.view_matrix, rv3d.window_matrix, width, height,
                                    eye, view_dir)
        object_draws = state.draw_objects(eye, view_dir)
        radiance = None
        if object_draws is None:
            radiance = self._shading.radiance_for(state, eye, view_dir, self._redraw_when_done)
        key = (tuple(map(tuple, rv3d.view_matrix)), tuple(map(tuple, rv3d.window_matrix)),
               width, height, scene.render.film_transparent, id(state), self._shading.version,
               object_draws is None)
        if key != self._view_key or self._view_texture is None:
            pixels = draw_pixels(state, radiance, rv3d.view_matrix, rv3d.window_matrix, width,
                                 height, scene.render.film_transparent,
                                 object_draws=object_draws, eye=eye, view_dir=view_dir)
            self._view_texture = drawing.float_texture(pixels)
            self._view_key = key
        gpu.state.blend_set("ALPHA_PREMULT")
        self.bind_display_space_shader(scene)
        draw_texture_2d(self._view_texture, (0, 0), width, height)
        self.unbind_display_space_shader()
        gpu.state.blend_set("NONE")

    def _redraw_when_done(self, worker):
        """Poll the shading worker from Blender's main loop; redraw when it is done."""
        def poll():
            if worker.is_alive():
                return 0.1
            try:
                self.tag_redraw()
            except ReferenceError:            # the viewport was closed meanwhile
                pass
            return None
        bpy.app.timers.register(poll, first_interval=0.1)


def get_panels():
    """Built-in panels that make sense with our engine (world, object, material, output)."""
    exclude = {"VIEWLAYER_PT_filter", "VIEWLAYER_PT_layer_passes"}
    panels = []
    for panel in bpy.types.Panel.__subclasses__():
        engines = getattr(panel, "COMPAT_ENGINES", None)
        if engines is not None and "BLENDER_RENDER" in engines and panel.__name__ not in exclude:
            panels.append(panel)
    return panels


def register():
    bpy.utils.register_class(PRTRenderEngine)
    for panel in get_panels():
        panel.COMPAT_ENGINES.add("PRT_RELIGHT")


def unregister():
    for panel in get_panels():
        panel.COMPAT_ENGINES.discard("PRT_RELIGHT")
    bpy.utils.unregister_class(PRTRenderEngine)
