"""AUTO: per object, the cheapest registered representation such that the frame meets
the scene's error target against REFERENCE (issue 6), measured on a sample of its
shading points (issue 20).

Measurement (once per object, lighting content and target; cached, so only what changed
is measured again; turning the same environment keeps it): REFERENCE and every other
per-vertex method × every value of its budget are run on a *sample* of the object's
shading points at a few probe views around it; each gives the squared error norm of its
radiance against REFERENCE's (worst probe; points weighted by the surface area they
stand for, as pixels are) and a model of its *relit* shading time on the whole object
(the lighting turned to an angle not used before, as in the report's per-frame timing).

Sample (:mod:`core.auto_choice`): :data:`SAMPLE_POINTS` (512) draws per object with
probability proportional to area, one per stratum of equal area along a Morton curve
(fixed seed :data:`SEED`: a function of the geometry); an object with fewer points is
measured whole, exactly as before.  The methods shade the drawn points only (the object
restricted to them: :func:`_restricted`), so a choice costs about the same at 5k and
500k points.  Each error is an estimate ``Ê`` with a standard error ``σ`` (of ``Ê - R̂ B̂``
against the reference norm ``B̂`` of the same draws); every decision uses ``Ê + z σ``
(``z`` = :data:`core.auto_choice.MARGIN_Z` = 2), and the stored choice reports the
estimate and that margin per object.

Time: with the lighting turned to an angle not used before, a candidate's frame of one
sampled point (it does the lighting's shared work: resampling, tables), then of the
sample and of every eighth drawn point (:data:`SLOPE_POINTS`), which find that work
cached: their slope is the per-point part ``s`` (per-lighting and per-view work), the
first frame the fixed part ``F``, so a relit frame of the whole object is modelled as
``t(P) = F + s P`` (:func:`core.auto_choice.relit_time`; an object measured whole is
timed whole).  The whole frame's time of an assignment is
modelled from those (:func:`core.auto_choice.assignment_seconds`: objects sharing a
method pay its fixed part once), not timed on the whole scene.  A candidate slower than
REFERENCE on the sample (with the lighting cached) cannot be the fastest at any error
and is not measured further.

A diffuse-only object's error is view independent and kept per sampled point; a glossy
object is judged per probe on what that probe's image shows (points weighted by the
pixels they cover from it, :func:`_probe_pixel_weights`): the worst probe's squared
error over the dimmest probe's norm.

Camera: when the engine draws a frame it sets ``state.camera``; the per-point errors and
reference norms are then weighed by the pixels each sampled point covers in that image
(:func:`core.screen.corner_pixel_weights` of the triangles around the sampled points), so
the frame's estimate is the image's rel-L2 (measured a little above it, never below)
and an object out of view costs nothing (:meth:`AutoMethod._on_camera`; margin
:data:`SAFETY_CAMERA`).

Sizing: integer budgets are sized to the target between the listed values.  When a
method's first value meeting the object's limit is not its first one, AUTO bisects
between the previous (missing) value and it with :meth:`Method.budget_between` (RSL
light count: midpoint; wavelet terms: geometric mean; at most :data:`BETWEEN_STEPS`
steps), each value measured like a listed one (error at the probes with the early
reject, relit time) and kept as an option.  Objects so differ in the values they have
measured.  SH orders are consecutive; BLOCKS and SSDF_SG only try their listed values.

Assignment: the frame's rel-L2 is ``sqrt(Σ_i ‖e_i‖² / Σ_i ‖b_i‖²)`` over the objects, so
the cheapest assignment under ``Σ ‖e_i‖² ≤ (s·t)² Σ ‖b_i‖²`` (target ``t``, safety ``s``)
is found by Lagrangian relaxation (:func:`core.auto_choice.mix`): each object takes the
option minimising ``time + λ‖e‖²`` with λ bisected to the smallest that fits; the
relaxation only reaches options on each object's lower convex hull of (error, time), so
the slack it leaves is then spent greedily on cheaper options off the hull (a budget
sized between two listed values often is).  An object that carries little of the image
may so take a coarser method than a large one.  A method shared by several objects pays
its per-lighting work once, so the mix is then compared (modelled frame time) with the
few single candidates that also fit (budget values every object measured), and the
faster assignment wins.  ``s`` leaves room for the camera's own view of glossy objects
(:data:`SAFETY`) and for pixels weighting corners by screen area (:data:`SAFETY_DIFFUSE`
for diffuse-only scenes).

Shortcuts that make the measurement cheap:

* diffuse-only objects (no glossy lobe, no dielectric layer) are view independent: one
  probe instead of :data:`PROBES` (and no candidate evaluates a BRDF table for them);
* a candidate :data:`REJECT` × the target off at a probe is not run at the others;
* a method's budget values are listed cheapest first (SH order, wavelet terms, RSL
  count, PCA error budget, BLOCKS tolerance), so values after the first one that meets
  the target on the object are not measured, nor are those after one slower than
  REFERENCE on the sample;
* objects with no occluders and low-frequency lighting are where the cheapest
  candidates (SH) pass; the reason column says so.

Per-pixel methods (``draw_objects``) cannot be mixed per object and are left out of the
candidates.  The choice per object is shown as a note in the panels/status bar, in the
AUTO box of the settings and in the report (:meth:`AutoMethod.last_choices`).

Progress and cancelling: the measurement is a generator of steps (one candidate on one
object each, :meth:`AutoMethod.choice_steps`); ``prt.auto_choose`` runs one step per timer
event in the UI (progress bar, ESC cancels, nothing written), ``execute`` and ``-b`` run
them all; a live choice inside F12 reports through the frame's progress hook and stops
on ESC (:meth:`runtime.FrameState.tick`).

Stored choice: the measurement times shading, so two processes choose differently.  The
choice is therefore made by an explicit step on the main thread -- the precompute's commit
when the method is AUTO (:meth:`AutoMethod.store`) and the *Choose* operator
(``prt.auto_choose``) -- with the scene camera's image at the render size (the probes when
the scene has none), and stored in ``scene.prt.auto_choice`` (JSON) with the key of what it
depends on (:func:`choice_key`: geometry, directions, materials, lighting content without
its rotation, target, the candidates' other settings; not the camera, so a stored choice
does not flip as the view moves).  A frame whose key matches shades the stored assignment
and times nothing, so it is a function of the file; otherwise it falls back to the live
choice above, noted as out of date, and nothing is written (frames may be drawn off the
main thread).
"""

from __future__ import annotations

import copy
import time

import numpy as np

from ...core import auto_choice, directions, screen, visibility
from ...core import mesh as core_mesh
from ...core.visibility import Cancelled
from .. import drawing, relit, runtime
from ..keys import cache, env_key, held
from . import REGISTRY, Method, register
from .auto_store import (CHOICE_EXTRA, CHOICE_FIELDS, CHOICE_VERSION, STORED_STATUS,  # noqa: F401
                         _materials_key, _plain, choice_key, parse_choice, stored_status,
                         write_choice)

#: Fraction of the target a candidate must reach at the probes: view-dependent objects
#: (the camera sees other highlights than the probes) and diffuse-only ones (the probe
#: error is the drawn per-corner error; pixels weight corners by screen area).
SAFETY = 0.75
SAFETY_DIFFUSE = 0.9
#: The same for diffuse-only objects when the frame's camera is known: their per-vertex
#: errors are then weighed by the pixels each corner covers in that image
#: (:func:`core.screen.corner_pixel_weights`), which leaves only interpolation inside
#: triangles and antialiased edges between the estimate and the image's rel-L2.
SAFETY_CAMERA = 0.95
#: A candidate this many times the target off at a probe is not measured further.
REJECT = 4.0
#: Single methods compared with the mix on the whole scene (the fastest by estimate).
UNIFORM_TRIED = 3
#: Shading points drawn per object (by area; an object with fewer is measured whole).
SAMPLE_POINTS = 512
#: Points of the smaller sample (every eighth drawn point) a candidate's per-point time
#: is taken against.
SLOPE_POINTS = SAMPLE_POINTS // 8
#: Seed of the samples (the draw is a function of the geometry and this).
SEED = 0
#: Probe views of a view-dependent object (a diffuse-only one has one).
PROBES = 4
#: Bisection steps between a method's last budget value missing the target on an object
#: and its first one meeting it (:meth:`Method.budget_between`: RSL light count, wavelet
#: terms); each step is one more measured option.
BETWEEN_STEPS = 3
#: Relit shading passes timed per candidate (the fastest counts; each one resamples
#: the environment for cubemap-based methods, the dominant cost of a selection).
TIMED_FRAMES = 1
# angle of the last turned lighting a timed frame used (each timing turns it anew)
_ANGLE = [0.0]
# Per-object selections: (name, id(bits), lighting content, target, materials, candidates);
# the same environment turned (Mapping rotation) keeps the choice.
_CHOICE_CACHE = cache(256)
# The scene-level assignment for the newest tuple of per-object keys (and camera).
_SCENE_CACHE = cache(1)
# Embree scene of the frame's triangles for the camera weights, per the objects' mesh
# fingerprints (made again for other geometry).
_OCCLUDERS = cache(1)
#: The newest per-object choices (what the panel and the report show).
LAST_CHOICES: list = []
#: Number of selections run (tests check that unchanged objects are not re-selected).
SELECTIONS = [0]


def _is_view_independent(st) -> bool:
    return all(m.is_diffuse_only and m.fresnel != "DIELECTRIC" for m in st.materials) \
        if st.materials else True


def _probe_eyes(p, count: int):
    """Camera positions around the bounding box of points ``p`` (3 × its radius away)."""
    lo, hi = p.min(axis=0), p.max(axis=0)
    centre = (lo + hi) / 2
    radius = max(float(np.linalg.norm(hi - lo)) / 2, 1e-3)
    # three views from 27° above around the object, then one from 3° above (a glossy
    # object's highlights and grazing reflections differ most there)
    dirs = np.array([[0.0, -1.0, 0.5], [0.87, 0.5, 0.5], [-0.87, 0.5, 0.5],
                     [0.0, 1.0, 0.05]])[:count]
    dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
    return [centre + 3.0 * radius * d for d in dirs]


def _substate(state, objects, method_id, setting=None, value=None, quiet=False):
    """A copy of ``state`` shading ``objects`` with one method (and budget value); ``quiet``:
    it reports no progress (AUTO's measurements; ESC still stops it)."""
    sub = copy.copy(state)              # shares world, warnings, background
    if quiet:
        sub.progress = None
    sub.objects = list(objects)
    sub.method = method_id
    if setting is not None:
        sub.settings = dict(state.settings, **{setting: value})
    return sub


def _label(method_id, setting, value) -> str:
    return method_id + ("" if setting is None else f" {setting}={value}")


class _Restricted:
    """An object restricted to some of its shading points (:func:`_restricted`)."""

    def __init__(self, obj, rows, per_point):
        self.obj = obj              # what the methods shade (an ObjectState)
        self.rows = rows            # the object's points it holds, in its order
        self._per_point = per_point

    def values(self, radiance) -> np.ndarray:
        """Per-point (n, 3) float64 of the methods' per-corner radiance of ``obj``."""
        return np.asarray(self._per_point(radiance), dtype=np.float64)


#: st.data entries that are per point but not arrays (dropped: made again from the bits)
_PER_POINT_OBJECTS = ("blocks_dv", "blocks_stream_bytes", "ssdf_sg")


def _restricted(st, rows, tag: str) -> _Restricted:
    """``st`` restricted to its shading points ``rows`` (sorted): one corner per point,
    their visibility rows and per-point stored data (RSL's tables; BLOCKS' differential
    visibility is made again from the rows' bits, which it was derived from), named apart
    so that the methods' caches keep the whole object's entries apart.  Every point:
    ``st`` itself (its caches are shared with the frames)."""
    pts = st.points
    if len(rows) == pts.count:
        first = np.zeros(pts.count, dtype=np.int64)
        first[pts.point_of_corner] = np.arange(len(pts.point_of_corner))   # corners agree
        return _Restricted(st, rows, lambda rad: np.asarray(rad)[first])
    rows = np.asarray(rows, dtype=np.int64)
    n = len(rows)
    sub = copy.copy(st)
    sub.name = f"{st.name}\x1fAUTO {tag} {n}"
    sub.points = core_mesh.ShadingPoints(np.arange(n, dtype=np.int64), pts.positions[rows],
                                         pts.normals[rows], pts.materials[rows])
    sub.arrays = core_mesh.MeshArrays(pts.positions[rows], np.arange(n), pts.normals[rows],
                                      np.zeros((0, 3), np.int64), pts.materials[rows])
    sub.bits = np.ascontiguousarray(st.bits[rows])
    data = {}
    for k, v in st.data.items():
        if k in _PER_POINT_OBJECTS:
            continue
        if k == "rsl" and "rsl_rows" in st.data:
            data[k] = v                              # indexed through the rows below
        elif isinstance(v, np.ndarray) and v.ndim and len(v) == pts.count:
            data[k] = v[rows]
        else:
            data[k] = v
    sub.data = data
    return _Restricted(sub, rows, lambda rad: rad)


def _sum(sample, weights, values) -> float:
    """``Σ_p w_p f_p`` estimated from per-row ``values`` (``weights`` None: area)."""
    w = sample.area if weights is None else weights
    return float((sample.scale * w) @ np.asarray(values, np.float64))


def _norm2(x) -> np.ndarray:
    return np.sum(np.square(np.asarray(x, np.float64)), axis=-1)


def _point_pixel_weights(meshes, points, rows, clip, width, height, eye=None, view_dir=None,
                         occluders=None) -> list:
    """Per object, the pixels each of its points ``rows`` covers in the image of ``clip``
    (:func:`core.screen.corner_pixel_weights` of the triangles around those points only;
    ``occluders`` hide them)."""
    only = []
    for arrays, pts, r in zip(meshes, points, rows):
        mark = np.zeros(pts.count, dtype=bool)
        mark[r] = True
        only.append(mark[pts.point_of_corner[arrays.triangles]].any(axis=1))
    corner = screen.corner_pixel_weights(meshes, clip, width, height, eye=eye,
                                         view_dir=view_dir, occluders=occluders, only=only)
    return [np.bincount(pts.point_of_corner, weights=wc, minlength=pts.count)[r]
            for pts, wc, r in zip(points, corner, rows)]


def _probe_pixel_weights(st, rows, eye, occluders, size: int = 128) -> np.ndarray:
    """Per point ``rows``, the pixels it covers in a ``size``² image from probe ``eye``
    looking at the object's centre (the object alone: ``occluders`` is the Embree scene of
    its triangles; see :func:`core.screen.corner_pixel_weights`)."""
    p = st.points.positions
    centre = (p.min(axis=0) + p.max(axis=0)) / 2
    dist = max(float(np.linalg.norm(np.asarray(eye) - centre)), 1e-9)
    radius = max(float(np.linalg.norm(p.max(axis=0) - p.min(axis=0))) / 2, 1e-9)
    fov = 2.0 * np.arctan(min(1.2 * radius / dist, 10.0))
    clip = screen.look_at_clip(eye, centre, fov, near=dist * 1e-3, far=dist * 10.0)
    return _point_pixel_weights([st.arrays], [st.points], [rows], clip, size, size, eye=eye,
                                occluders=occluders)[0]


def drive(steps, tick=None):
    """Run a generator of progress fractions to its end (``tick(fraction)`` after each
    step: it may raise ``Cancelled``); returns the generator's value."""
    while True:
        try:
            fraction = next(steps)
        except StopIteration as stop:
            return stop.value
        if tick is not None:
            tick(fraction)


def _depsgraph(scene):
    """The evaluated depsgraph of ``scene`` (the context's when it is the context scene)."""
    import bpy
    ctx = bpy.context
    if ctx.scene == scene:
        return ctx.evaluated_depsgraph_get()
    with ctx.temp_override(scene=scene, view_layer=scene.view_layers[0]):
        return ctx.evaluated_depsgraph_get()


_rel = auto_choice.rel_error


class AutoMethod(Method):
    id = "AUTO"
    label = "Auto"
    description = ("Per object, the cheapest method and budget that meets the error target "
                   "against REFERENCE (chosen at Precompute or Choose, stored with the scene)")
    budget = None

    def scene_properties(self):
        from bpy.props import FloatProperty, StringProperty
        return {
            "auto_error_target": FloatProperty(
                name="Error Target", default=0.02, min=0.0, max=1.0, precision=3,
                subtype="FACTOR", update=drawing.redraw_viewports,
                description="AUTO: largest rel-L2 error against REFERENCE allowed per object "
                            "(0.02 = 2 %)"),
            "auto_choice": StringProperty(
                name="Stored Choice", default="", options={"HIDDEN"},
                update=drawing.redraw_viewports,
                description="AUTO: the method and budget per object chosen by Precompute or "
                            "Choose (JSON), with the key of what it depends on")}

    def draw_settings(self, layout, prt):
        layout.prop(prt, "auto_error_target")
        box = layout.box()
        record = parse_choice(prt.auto_choice)
        why = stored_status(prt)
        if record is None:
            box.label(text="No stored choice: press Choose (or Precompute)", icon="INFO")
        else:
            if why:
                box.label(text=f"{why}: press Choose (or Precompute)", icon="ERROR")
            else:
                current = STORED_STATUS[0] == prt.auto_choice
                box.label(text="Stored choice" + (", current" if current else ""),
                          icon="CHECKMARK" if current else "INFO")
            box.label(text=f"Chosen for camera '{record['camera']}' at "
                           f"{record['size'][0]}×{record['size'][1]}" if record.get("camera")
                      else "Chosen at probe views (the scene had no camera)", icon="CAMERA_DATA")
            self._draw_choices(box, record["objects"])
        if LAST_CHOICES and (record is None or why):
            box.label(text="Drawn now with a live choice (not saved):")
            self._draw_choices(box, LAST_CHOICES)
        box.operator("prt.auto_choose", icon="FILE_REFRESH")

    @staticmethod
    def _draw_choices(layout, choices):
        for c in choices[:8]:
            margin = c.get("margin")
            err = "" if c["error"] is None else (
                f" ({100 * c['error']:.2f} ± {100 * margin:.2f} %)" if margin
                else f" ({100 * c['error']:.2f} %)")
            layout.label(text=f"{c['object']}: {c['choice']}{err}", icon="OBJECT_DATA")

    # ------------------------------------------------------------ candidates
    @staticmethod
    def candidates():
        """(method, budget property or None, value) of every other per-vertex method."""
        out = []
        for m in REGISTRY.values():
            if m.id in ("AUTO", "REFERENCE"):
                continue
            if type(m).draw_objects is not Method.draw_objects:
                continue
            prop, values = m.budget if m.budget else (None, [None])
            out += [(m, prop, v) for v in values]
        return out

    def view_dependent(self, state) -> bool:
        return not all(_is_view_independent(st) for st in state.objects)

    def derive(self, job):
        out = {}
        derived = [m for m in dict.fromkeys(m for m, _, _ in self.candidates())
                   if type(m).derive is not Method.derive]
        for m in derived:
            job.stage = f"deriving {m.label}"
            out[m.id] = m.derive(job)
        return out

    def store(self, scene, job, derived):
        """The candidates' data, then the choice made on it (:meth:`choose`) -- unless the
        job defers it (``job.defer_choice``: the modal precompute runs
        :meth:`choice_steps` itself, one step per timer event)."""
        for m, _, _ in self.candidates():
            if derived and m.id in derived:
                m.store(scene, job, derived.pop(m.id))
        if getattr(job, "defer_choice", False):
            return
        try:
            self.choose(scene)
        except RuntimeError as exc:
            job.warnings.append(f"AUTO could not choose: {exc}")

    def choose(self, scene, depsgraph=None) -> dict:
        """Choose per object for the scene as it is now and store the choice in
        ``scene.prt.auto_choice`` with its :func:`choice_key` (main thread: an operator or
        the precompute's commit).  Errors are weighed in the image of the scene camera at
        the render size, the view F12 draws (at the probes when there is no camera).
        Returns the stored record; raises RuntimeError when the scene cannot be drawn.
        In ``-b`` the candidates run inside a render of our engine (:func:`.engine.in_render`):
        only there does the gpu module have a context of its own for their GPU passes."""
        import bpy
        from ..engine import in_render
        if scene.camera is not None:
            record = in_render(scene, lambda dg: drive(self.choice_steps(scene, dg)))
        elif bpy.app.background:
            # the GPU passes need a render's context, a render a camera: a temporary one,
            # not used for the choice (it is made at the probe views)
            with drawing.temporary_camera(scene):
                record = in_render(scene, lambda dg: drive(
                    self.choice_steps(scene, dg, probes_only=True)))
        else:
            record = drive(self.choice_steps(scene, depsgraph or _depsgraph(scene)))
        write_choice(scene, record)
        return record

    def choice_steps(self, scene, depsgraph, probes_only=False):
        """The choice for ``scene`` as :meth:`choose` stores it, in steps: a generator
        that yields its progress (0..1) after each measured candidate and returns the
        record (it writes nothing; :func:`write_choice` does); ``probes_only``: at the
        probe views, whatever the camera.  Raises RuntimeError when the scene cannot be
        drawn."""
        from ..engine import render_camera
        state = runtime.FrameState()
        state.sync(depsgraph)
        if state.error:
            raise RuntimeError(state.error)
        if state.method != self.id:
            state.method = self.id
            self.sync(state)        # the candidates' stored data (sync loaded the scene method's)
        state.camera = None if probes_only else render_camera(scene, depsgraph)
        camera_name = scene.camera.name if state.camera is not None else None
        yield 0.0
        choices = (yield from self._selection_steps(state))[0]
        return dict(version=CHOICE_VERSION, key=choice_key(state, self.candidates()), camera=camera_name,
                    size=None if state.camera is None else [state.camera["width"],
                                                            state.camera["height"]],
                    sample=dict(points=SAMPLE_POINTS, slope_points=SLOPE_POINTS, seed=SEED,
                                probes=PROBES, z=auto_choice.MARGIN_Z),
                    objects=[{f: _plain(c[f]) for f in CHOICE_FIELDS + CHOICE_EXTRA if f in c}
                             for c in choices])

    def sync(self, state):
        done = set()
        for m, _, _ in self.candidates():
            if m.id not in done and type(m).sync is not Method.sync:
                done.add(m.id)
                m.sync(state)

    # ------------------------------------------------------------ selection
    def _steps_per_object(self, st) -> int:
        """About how many steps :meth:`_measure_steps` takes on ``st`` (the progress bar's
        scale: a step per frame it shades)."""
        probes = 1 if _is_view_independent(st) else PROBES
        return 2 + (len(self.candidates()) + BETWEEN_STEPS) * (probes + 3)

    def _measure_steps(self, state, st, target):
        """Per-object measurements on a sample of its points (a generator: yields after
        every frame it shades, returns the measurement): for each candidate
        (and REFERENCE, and budget values sized between a method's listed ones) the
        estimated squared error norm against REFERENCE at the probes (worst probe, with its
        sampling margin), the modelled relit shading time on the whole object, plus the
        reference's squared norm (smallest probe)."""
        SELECTIONS[0] += 1
        ref = REGISTRY["REFERENCE"]
        pts = st.points
        view_free = _is_view_independent(st)
        eyes = _probe_eyes(pts.positions, 1 if view_free else PROBES)
        areas = core_mesh.point_areas(st.arrays, pts)
        sample = auto_choice.area_sample(areas, pts.positions, SAMPLE_POINTS, SEED)
        one = _restricted(st, sample.rows, "sample")
        # every eighth drawn point: the per-point time is the slope between the two; and
        # one point, whose relit frame does the lighting's shared work
        few = point = None
        if not sample.exact:
            few = _restricted(st, sample.rows[::max(1, sample.size // SLOPE_POINTS)], "slope")
            point = _restricted(st, sample.rows[:1], "point")
        truth, ref_warm = [], float("inf")
        for k, eye in enumerate(eyes):
            t0 = time.perf_counter()
            rad = ref.shade(_substate(state, [one.obj], "REFERENCE", quiet=True), eye, None)
            if k:
                ref_warm = min(ref_warm, time.perf_counter() - t0)
            truth.append(one.values(rad[0]))
            yield
        ref2 = [_norm2(t) for t in truth]
        ref_norm2 = min(_sum(sample, None, b) for b in ref2)
        # a view-dependent object is judged per probe on what that probe's image shows
        # (its back faces and self-hidden parts count nothing), by relative error
        if view_free:
            probe_w = [None]
        else:
            occluders = (visibility.build_occluder_scene(st.arrays.triangle_positions)
                         if visibility.have_embree() else None)
            probe_w = [_probe_pixel_weights(st, sample.rows, eye, occluders) for eye in eyes]
            del occluders
        probe_ref2_min = min(_sum(sample, pw, b) for pw, b in zip(probe_w, ref2))
        point_err2 = {}     # per option: per sampled point squared error (view independent)
        cube = directions.cubemap(state.resolution)
        # (on the sampled points: the whole object's check is a (P, 6N^2) product)
        open_sky = bool(np.array_equal(one.obj.bits, runtime.open_visibility(
            one.obj.points.normals, cube)))
        limit = (SAFETY_DIFFUSE if view_free else SAFETY) * target
        options, models = [], {}
        slower = set()      # methods slower than REFERENCE on the sample
        yield

        def shade_seconds(m, sub, world=None):
            """Seconds of one frame of ``sub`` (with ``world`` instead of its lighting)."""
            sub.world = state.world if world is None else world
            t0 = time.perf_counter()
            m.shade(sub, eyes[0], None)
            seconds = time.perf_counter() - t0
            sub.world = state.world
            return seconds

        def relit_seconds(m, sub):
            """The fastest of TIMED_FRAMES frames, each with the lighting turned anew."""
            times = []
            for _ in range(TIMED_FRAMES):
                _ANGLE[0] += 0.61
                times.append(shade_seconds(m, sub, relit.rotated_world(state.world,
                                                                       _ANGLE[0])))
            return min(times)

        def timing(m, prop, value):
            """(fixed, per point, seconds on the whole object) of a relit frame: frames
            with the lighting turned anew, of one point (the lighting's shared work), then
            of the sample and of every eighth drawn point (their per-point work).  A
            generator: yields between frames."""
            sub = _substate(state, [one.obj], m.id, prop, value, quiet=True)
            n_a = one.obj.points.count
            if few is None:                     # measured whole: timed whole
                whole = relit_seconds(m, sub)
                return auto_choice.linear_time(n_a, whole, n_a, whole, pts.count)
            small = _substate(state, [few.obj], m.id, prop, value, quiet=True)
            first = _substate(state, [point.obj], m.id, prop, value, quiet=True)
            shade_seconds(m, small)             # fills its per-visibility caches
            yield
            _ANGLE[0] += 0.61
            world = relit.rotated_world(state.world, _ANGLE[0])
            t_1 = shade_seconds(m, first, world)
            t_a = shade_seconds(m, sub, world)
            yield
            t_0 = shade_seconds(m, small, world)
            return auto_choice.relit_time(few.obj.points.count, t_0, n_a, t_a, t_1, pts.count)

        def measure(m, prop, value):
            """Adds the option ``(key, seconds, err² with margin, err²)`` of ``(m.id,
            prop, value)`` (error at the probes, modelled relit time unless it is far
            off); returns whether it meets ``limit`` with its margin.  A generator:
            yields after each frame it shades (one step of the modal choice)."""
            key = (m.id, prop, value)
            sub = _substate(state, [one.obj], m.id, prop, value, quiet=True)
            # the worst probe's squared error over the dimmest probe's norm (a glossy
            # object's highlights move between views: the camera's may be the worst
            # error where the least light is); absolute against black
            worst, worst_up, warm = 0.0, 0.0, None
            if m is not ref:
                for k, (eye, expected, b2, pw) in enumerate(zip(eyes, truth, ref2, probe_w)):
                    state.tick()
                    t0 = time.perf_counter()
                    rad = m.shade(sub, eye, None)
                    if k:                       # the first frame fills its caches
                        warm = min(warm or float("inf"), time.perf_counter() - t0)
                    got = None if rad is None else one.values(rad[0])
                    e2 = (np.full(len(expected), np.inf) if got is None
                          or not np.isfinite(got).all() else _norm2(got - expected))
                    est = auto_choice.estimate(sample, pw, e2, b2)
                    worst, worst_up = max(worst, est.err2), max(worst_up, est.err2_up())
                    rel2 = worst / probe_ref2_min if probe_ref2_min > 0 else worst
                    if warm is not None and warm > ref_warm:
                        # slower than REFERENCE: so are its dearer budgets
                        slower.add(m.id)
                    if rel2 > (REJECT * target) ** 2 or m.id in slower:
                        # far off here, or slower than REFERENCE: skip the others
                        worst = worst_up = float("inf")
                        break
                    if view_free:
                        point_err2[key] = e2
                    yield
            to_object = ref_norm2 / probe_ref2_min if probe_ref2_min > 0 else 1.0
            err2, err2_up = worst * to_object, worst_up * to_object
            finite = bool(np.isfinite(err2))
            seconds = float("inf")
            if finite:
                fixed, per_point, seconds = yield from timing(m, prop, value)
                models[key] = (fixed, per_point, pts.count)
            options.append((key, seconds, err2_up, err2))
            return finite and _rel(err2_up, ref_norm2) <= limit

        met = set()         # methods whose cheaper budget already meets the target here
        below: dict = {}    # per method: its last measured value that does not meet it
        for m, prop, value in [(ref, None, None)] + self.candidates():
            try:
                if m.id in slower:
                    # slower than REFERENCE at a cheaper budget: not measured
                    options.append(((m.id, prop, value), float("inf"), float("inf"),
                                    float("inf")))
                elif m.id in met:
                    # budgets are listed cheapest first: a later one of a method that
                    # already met the target here is dearer at a smaller error only, so
                    # it is not measured (the cheaper one is the object's fastest)
                    continue
                elif not (yield from measure(m, prop, value)):
                    below[m.id] = value
                else:
                    met.add(m.id)
                    # size the budget to the target: bisect between the last value that
                    # misses and this one (Method.budget_between; integer counts)
                    lo, hi = below.get(m.id), value
                    for _ in range(BETWEEN_STEPS if lo is not None else 0):
                        mid = m.budget_between(lo, hi)
                        if mid is None:
                            break
                        if (yield from measure(m, prop, mid)):
                            hi = mid
                        else:
                            lo = mid
            except Cancelled:
                raise
            except Exception as exc:            # a broken candidate is skipped, not fatal
                print(f"PRT AUTO: {m.id} failed on '{st.name}': {exc}")
            yield
        notes = ((["no occluders" + ("" if sample.exact else " at the sampled points")]
                  if open_sky else []) + (["diffuse only"] if view_free else []))
        if not sample.exact:
            notes.append(f"measured on {sample.size} of {pts.count} points")
        return dict(object=st.name, options=options, models=models, ref_norm2=ref_norm2,
                    limit=limit, notes=notes, view_free=view_free, sample=sample,
                    point_ref2=ref2[0], point_err2=point_err2, points=pts.count)

    def choices(self, state):
        """Per-object measurements (cached per object: only what changed is measured
        again), then the assignment for the frame."""
        return self._selection(state)[0]

    def _selection(self, state):
        """(choices, assignment, status note) of the frame, reporting progress and
        stopping on ESC through ``state.tick`` (F12); the per-frame work on a hit is the
        cache keys (the materials' repr is kept per synced object)."""
        return drive(self._selection_steps(state), state.tick)

    def _cached(self, state):
        """(per-object cache keys, their cached measurements or None)."""
        target = float(state.settings.get("auto_error_target", 0.02))
        key = env_key(state.world, state.resolution)
        env = (key[0], key[1], key[3])      # content and strength: a rotation keeps the choice
        names = tuple((m.id, prop, v) for m, prop, v in self.candidates())
        sampling = (SAMPLE_POINTS, SLOPE_POINTS, SEED, PROBES)
        keys, measured = [], []
        for st in state.objects:
            keys.append((st.name, id(st.bits), env, target, _materials_key(st), names,
                         sampling))
            entry = _CHOICE_CACHE.get(keys[-1])
            measured.append(entry[1] if entry is not None and entry[0][0] is st.bits
                            else None)
        return keys, measured

    def slow_frame(self, state) -> bool:
        """Whether the next frame would measure (no stored choice holds and some object's
        measurement is not cached): the viewport then shades it off the main thread."""
        if self._stored(state)[0] is not None:
            return False
        return any(m is None for m in self._cached(state)[1])

    def _selection_steps(self, state):
        """:meth:`_selection` as a generator of progress fractions (returns its result)."""
        target = float(state.settings.get("auto_error_target", 0.02))
        keys, measured = self._cached(state)
        todo = [i for i, m in enumerate(measured) if m is None]
        total = max(1, sum(self._steps_per_object(state.objects[i]) for i in todo))
        done = 0
        for i in todo:
            st = state.objects[i]
            steps = self._measure_steps(state, st, target)
            while True:
                try:
                    next(steps)
                except StopIteration as stop:
                    result = stop.value
                    break
                done += 1
                yield min(done / total, 0.99)
            measured[i] = held(_CHOICE_CACHE, keys[i], (st.bits,), lambda: result,
                               limit=256)
        camera = getattr(state, "camera", None)
        cam_key = None if camera is None else (
            np.round(np.asarray(camera["clip"], np.float64), 6).tobytes(),
            camera["width"], camera["height"])
        scene_key = (tuple(keys), cam_key)
        got = _SCENE_CACHE.get(scene_key)
        if got is None:
            out = self._assign(state, measured, target)
            note = ("AUTO: " + ", ".join(f"{c['object']} → {c['choice']}" for c in out)
                    if out else None)
            got = (out, [(c["method"], c["setting"], c["value"]) for c in out], note)
            _SCENE_CACHE.clear()
            _SCENE_CACHE[scene_key] = got
        LAST_CHOICES[:] = got[0]
        yield 1.0
        return got

    @staticmethod
    def _on_camera(state, measured, target):
        """``measured`` weighed for the frame's camera (``state.camera``, set by the
        engine): each sampled point's squared error and reference norm count by the pixels
        it covers in this image (:func:`core.screen.corner_pixel_weights`; hidden,
        off-screen and back-facing surface counts nothing), so the frame's estimate is
        the image's rel-L2 rather than the surface's.  Diffuse-only objects have their
        per-point errors (view independent); a glossy object's probe rel-L2 is scaled
        to its norm in the image.  Unchanged without a camera or when nothing shows."""
        camera = getattr(state, "camera", None)
        if camera is None or not measured:
            return measured, False
        # keyed on the geometry's fingerprints, not the arrays: every sync (each F12, each
        # viewport update) exports new arrays of the same meshes
        occluders = held(
            _OCCLUDERS, tuple((st.name, st.fingerprint) for st in state.objects), (),
            lambda: (visibility.build_occluder_scene(
                np.concatenate([st.arrays.triangle_positions for st in state.objects]))
                if visibility.have_embree() else None), limit=1)
        weights = _point_pixel_weights(
            [st.arrays for st in state.objects], [st.points for st in state.objects],
            [m["sample"].rows for m in measured], camera["clip"], camera["width"],
            camera["height"], eye=camera["eye"], view_dir=camera["view_dir"],
            occluders=occluders)
        out = []
        for m, wp in zip(measured, weights):
            sample = m["sample"]
            ref2 = _sum(sample, wp, m["point_ref2"])
            scale = ref2 / m["ref_norm2"] if m["ref_norm2"] > 0 else 1.0
            options = []
            for key, seconds, err2_up, err2 in m["options"]:
                per_point = m["point_err2"].get(key)
                if per_point is not None and np.isfinite(err2):
                    est = auto_choice.estimate(sample, wp, per_point, m["point_ref2"])
                    err2_up, err2 = est.err2_up(), est.err2
                elif np.isfinite(err2):
                    err2_up, err2 = err2_up * scale, err2 * scale
                options.append((key, seconds, err2_up, err2))
            out.append(dict(m, options=options, ref_norm2=ref2,
                            limit=(SAFETY_CAMERA if m["view_free"] else SAFETY) * target))
        if sum(m["ref_norm2"] for m in out) <= 0:
            return measured, False
        return out, True

    def _assign(self, state, measured, target):
        """The frame's assignment: the Lagrangian per-object mix
        (:func:`core.auto_choice.mix`) against the whole scene's rel-L2 budget (in the
        frame camera's image when known, else at the probes; errors with their sampling
        margin), compared with each single candidate that also fits the budget by the
        modelled time of a relit frame of the whole scene
        (:func:`core.auto_choice.assignment_seconds`); the fastest wins."""
        measured, on_camera = self._on_camera(state, measured, target)
        limit = min(m["limit"] for m in measured) if measured else target
        total_ref2 = sum(m["ref_norm2"] for m in measured)
        budget2 = (limit ** 2) * total_ref2
        mix = auto_choice.mix([[o[:3] for o in m["options"]] for m in measured], budget2)
        options = {"mix": [o[0] for o in mix]}
        by_key = [{o[0]: o for o in m["options"]} for m in measured]
        models = [m["models"] for m in measured]
        if len(measured) > 1:
            # a single candidate for every object: only budget values every object has
            # measured and timed (values sized between the listed ones differ between
            # objects)
            shared = set(by_key[0]).intersection(*by_key[1:])
            uniform = []
            for cand in shared:
                per = [k[cand] for k in by_key]
                if any(not (np.isfinite(o[1]) and np.isfinite(o[2])) for o in per):
                    continue
                if sum(o[2] for o in per) <= budget2:
                    uniform.append((auto_choice.assignment_seconds([cand] * len(measured),
                                                                   models),
                                    _label(*cand), cand))
            for _, _, cand in sorted(uniform)[:UNIFORM_TRIED]:
                if [cand] * len(measured) != options["mix"]:
                    options[cand] = [cand] * len(measured)
        timed = {}
        if len(options) > 1:
            timed = {name: auto_choice.assignment_seconds(a, models)
                     for name, a in options.items()}
        best = min(timed, key=lambda n: (timed[n], n != "mix")) if timed else "mix"
        assignment = options[best]
        chosen = [k[a] for k, a in zip(by_key, assignment)]
        scene_rel = _rel(sum(o[3] for o in chosen), total_ref2)
        margin = _rel(sum(o[2] for o in chosen), total_ref2) - scene_rel
        where = "in the camera's image" if on_camera else "at the probes"
        sampled = f" ± {margin:.2%} sampled" if margin > 0 else ""
        if best == "mix":
            why = (f"fastest mix within {limit:.2%} of the whole scene {where} "
                   f"({scene_rel:.2%}{sampled})")
            if timed:
                why += (f"; {timed['mix'] * 1e3:.2f} ms per relit frame (modelled), faster "
                        "than " + ", ".join(f"{_label(*k)} {v * 1e3:.2f} ms"
                                            for k, v in timed.items() if k != "mix"))
        else:
            why = (f"one method for the whole scene is fastest ({timed[best] * 1e3:.2f} ms "
                   f"per relit frame (modelled), {scene_rel:.2%}{sampled} {where}; the "
                   f"per-object mix {timed['mix'] * 1e3:.2f} ms)")
        out = []
        for m, o in zip(measured, chosen):
            a = o[0]
            error = _rel(o[3], m["ref_norm2"])
            out.append(dict(object=m["object"], method=a[0], setting=a[1], value=a[2],
                            choice=_label(*a), error=error,
                            margin=max(_rel(o[2], m["ref_norm2"]) - error, 0.0),
                            seconds=o[1], points=m["points"], sampled=m["sample"].size,
                            reason="; ".join(m["notes"] + [why])))
        return out

    def last_choices(self):
        return list(LAST_CHOICES)

    # ------------------------------------------------------------ shading
    @staticmethod
    def _shade_assigned(state, assignment, eye, view_dir):
        """Shade each group of objects sharing a (method, setting, value) in one call."""
        groups: dict = {}
        for i, a in enumerate(assignment):
            groups.setdefault(a, []).append(i)
        out = [None] * len(state.objects)
        done = 0
        for (mid, prop, value), idx in groups.items():
            sub = _substate(state, [state.objects[i] for i in idx], mid, prop, value)
            # progress: the group's share of the points
            share = sum(state.objects[i].points.count for i in idx)
            total = max(sum(st.points.count for st in state.objects), 1)
            with sub.span(done / total, (done + share) / total):
                for i, rad in zip(idx, REGISTRY[mid].shade(sub, eye, view_dir)):
                    out[i] = rad
            done += share
        return out

    def _stored(self, state):
        """``(assignment, choices)`` of the scene's stored choice when it holds for
        ``state``, else ``(None, why not)``."""
        record = parse_choice(state.settings.get("auto_choice", ""))
        if record is None:
            return None, "AUTO has no stored choice"
        changed = [part for part, value in choice_key(state, self.candidates()).items()
                   if record["key"].get(part) != value]
        if changed:
            return None, f"AUTO choice is out of date ({', '.join(changed)} changed)"
        by_name = {c["object"]: c for c in record["objects"]}
        chosen = [by_name.get(st.name) for st in state.objects]
        for c in chosen:
            m = REGISTRY.get(c["method"]) if c is not None else None
            if m is None or m is self or type(m).draw_objects is not Method.draw_objects or \
                    (c["setting"] is not None and c["setting"] not in state.settings):
                return None, ("AUTO choice is out of date (it names an object or method no "
                              "longer present)")
        return [(c["method"], c["setting"], c["value"]) for c in chosen], chosen

    def _frame_assignment(self, state):
        """The frame's assignment, notes and whether it was chosen live: the stored choice
        when it holds (nothing is timed), else the live one, noted as out of date (nothing
        is written here: frames may be drawn off the main thread)."""
        text = state.settings.get("auto_choice", "")
        assignment, got = self._stored(state)
        if assignment is not None:
            STORED_STATUS[:] = [text, ""]
            LAST_CHOICES[:] = got
            return assignment, ["AUTO (stored choice): " + ", ".join(
                f"{c['object']} → {c['choice']}" for c in got)], False
        STORED_STATUS[:] = [text, got]
        with state.span(0.0, 0.9):          # a live choice is most of such a frame
            _, assignment, note = self._selection(state)
        return assignment, [f"{got}: press Choose (or Precompute); this frame is chosen live",
                            note], True

    def shade(self, state, eye, view_dir):
        assignment, notes, live = self._frame_assignment(state)
        with state.span(0.9 if live else 0.0, 1.0):
            out = self._shade_assigned(state, assignment, eye, view_dir)
        for note in notes:
            if note:
                state.note(note)
        return out


register(AutoMethod())
