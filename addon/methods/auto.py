"""AUTO: per object, the cheapest registered representation such that the frame meets
the scene's error target against REFERENCE (issue 6).

Measurement (once per object, lighting content and target; cached, so only what changed
is measured again; turning the same environment keeps it): REFERENCE and every other
per-vertex method × every value of its budget are run on the object alone at a few
probe views around it; each gives the squared error norm of its per-corner radiance
against REFERENCE's (worst probe; corners weighted by the surface area they stand for,
as pixels are) and its *relit* shading time on the object (the
lighting turned to an angle not used before, as in the report's per-frame timing).

A diffuse-only object's error is view independent and kept per shading point; a glossy
object is judged per probe on what that probe's image shows (corners weighted by the
pixels they cover from it, :func:`_probe_pixel_weights`): the worst probe's squared
error over the dimmest probe's norm.

Camera: when the engine draws a frame it sets ``state.camera``; the per-point errors and
reference norms are then weighed by the pixels each point covers in that image
(:func:`core.screen.corner_pixel_weights`), so the frame's estimate is the image's rel-L2
(measured a little above it, never below) and an object out of view costs nothing
(:meth:`AutoMethod._on_camera`; margin :data:`SAFETY_CAMERA`).

Sizing: integer budgets are sized to the target between the listed values.  When a
method's first value meeting the object's limit is not its first one, AUTO bisects
between the previous (missing) value and it with :meth:`Method.budget_between` (RSL
light count: midpoint; wavelet terms: geometric mean; at most :data:`BETWEEN_STEPS`
steps), each value measured like a listed one (error at the probes with the early
reject, relit time) and kept as an option.  Objects so differ in the values they have
measured.  SH orders are consecutive; BLOCKS and SSDF_SG only try their listed values.

Assignment: the frame's rel-L2 is ``sqrt(Σ_i ‖e_i‖² / Σ_i ‖b_i‖²)`` over the objects, so
the cheapest assignment under ``Σ ‖e_i‖² ≤ (s·t)² Σ ‖b_i‖²`` (target ``t``, safety ``s``)
is found by Lagrangian relaxation: each object takes the option minimising
``time + λ‖e‖²`` with λ bisected to the smallest that fits; the relaxation only reaches
options on each object's lower convex hull of (error, time), so the slack it leaves is
then spent greedily on cheaper options off the hull (a budget sized between two listed
values often is).  An object that carries little of the image may so take a coarser
method than a large one.  A method shared by several objects pays its per-lighting work
once, so the mix is then timed on the whole scene against the few single candidates that
also fit (budget values every object measured), and the faster assignment wins.
``s`` leaves room for the camera's own view of glossy objects (:data:`SAFETY`) and for
pixels weighting corners by screen area (:data:`SAFETY_DIFFUSE` for diffuse-only scenes).

Shortcuts that make the measurement cheap:

* diffuse-only objects (no glossy lobe, no dielectric layer) are view independent: one
  probe instead of four (and no candidate evaluates a BRDF table for them);
* a candidate :data:`REJECT` × the target off at a probe is not run at the others;
* a method's budget values are listed cheapest first (SH order, wavelet terms, RSL
  count, PCA error budget, BLOCKS tolerance), so values after the first one that meets
  the target on the object are not timed;
* objects with no occluders and low-frequency lighting are where the cheapest
  candidates (SH) pass; the reason column says so.

Per-pixel methods (``draw_objects``) cannot be mixed per object and are left out of the
candidates.  The choice per object is shown as a note in the panels/status bar, in the
AUTO box of the settings and in the report (:meth:`AutoMethod.last_choices`).

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
import hashlib
import json
import math
import time

import numpy as np

from ...core import directions, screen, visibility
from ...core import mesh as core_mesh
from .. import drawing, relit, runtime
from ..keys import cache, env_key, held, per_visibility
from . import REGISTRY, Method, register

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
#: Single methods timed against the mix on the whole scene (the fastest by estimate).
UNIFORM_TRIED = 3
#: Bisection steps between a method's last budget value missing the target on an object
#: and its first one meeting it (:meth:`Method.budget_between`: RSL light count, wavelet
#: terms); each step is one more measured option.
BETWEEN_STEPS = 3
#: Relit shading passes timed per candidate (the fastest counts; each one resamples
#: the environment for cubemap-based methods, the dominant cost of a selection).
TIMED_FRAMES = 1
# Per-object selections: (name, id(bits), lighting content, target, materials, candidates);
# the same environment turned (Mapping rotation) keeps the choice.
_CHOICE_CACHE = cache(256)
# The scene-level assignment for the newest tuple of per-object keys (and camera).
_SCENE_CACHE = cache(1)
# Whole-scene relit times of assignments, per tuple of per-object keys ({assignment:
# seconds}, held with the objects' visibility arrays); a new camera picks among the same
# options, so it times only assignments not timed before.
_TIMED = cache(16)
# Embree scene of the frame's triangles for the camera weights, per the objects' mesh
# fingerprints (made again for other geometry).
_OCCLUDERS = cache(1)
#: The newest per-object choices (what the panel and the report show).
LAST_CHOICES: list = []
#: Number of selections run (tests check that unchanged objects are not re-selected).
SELECTIONS = [0]
#: Layout of the stored choice (a record of another version is out of date).
CHOICE_VERSION = 1
# Stored choices parsed per JSON text (frames read the scene property each time).
_PARSED = cache(8)
#: (stored JSON, why it is not used or "") as the newest AUTO frame found it: the panel
#: shows whether the scene's stored choice is current.
STORED_STATUS: list = ["", ""]


def _is_view_independent(st) -> bool:
    return all(m.is_diffuse_only and m.fresnel != "DIELECTRIC" for m in st.materials) \
        if st.materials else True


def _materials_key(st) -> str:
    """``repr`` of an object's materials, built once per synced object (its frames reuse
    it; part of the per-object cache key)."""
    got = st.data.get("auto_materials")
    if got is None or got[0] is not st.materials:
        got = st.data["auto_materials"] = (st.materials, repr(st.materials))
    return got[1]


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


def _substate(state, objects, method_id, setting=None, value=None):
    sub = copy.copy(state)              # shares world, warnings, background
    sub.objects = list(objects)
    sub.method = method_id
    if setting is not None:
        sub.settings = dict(state.settings, **{setting: value})
    return sub


def _label(method_id, setting, value) -> str:
    return method_id + ("" if setting is None else f" {setting}={value}")


def _point_norm2(st, x) -> np.ndarray:
    """Per shading point ``‖x‖²`` of per-corner values (corners of a point agree)."""
    pts = st.points
    c2 = np.sum(np.square(np.asarray(x, np.float64)), axis=-1)
    total = np.bincount(pts.point_of_corner, weights=c2, minlength=pts.count)
    count = np.bincount(pts.point_of_corner, minlength=pts.count)
    return (total / np.maximum(count, 1)).astype(np.float32)


def _probe_pixel_weights(st, eye, occluders, size: int = 128) -> np.ndarray:
    """Per corner, the pixels it covers in a ``size``² image from probe ``eye`` looking
    at the object's centre (the object alone: ``occluders`` is the Embree scene of its
    triangles; see :func:`core.screen.corner_pixel_weights`)."""
    p = st.points.positions
    centre = (p.min(axis=0) + p.max(axis=0)) / 2
    dist = max(float(np.linalg.norm(np.asarray(eye) - centre)), 1e-9)
    radius = max(float(np.linalg.norm(p.max(axis=0) - p.min(axis=0))) / 2, 1e-9)
    fov = 2.0 * np.arctan(min(1.2 * radius / dist, 10.0))
    clip = screen.look_at_clip(eye, centre, fov, near=dist * 1e-3, far=dist * 10.0)
    return screen.corner_pixel_weights([st.arrays], clip, size, size, eye=eye,
                                       occluders=occluders)[0]


def _weighted_norm2(x, w) -> float:
    return float(np.einsum("c,c->", w, np.sum(np.square(np.asarray(x, np.float64)), axis=-1)))


def _digest(*parts) -> str:
    return hashlib.sha1(repr(parts).encode("utf-8")).hexdigest()[:16]


# Names of the candidates' settings other than their budgets, per tuple of candidate ids.
_SETTING_NAMES = cache(8)


def _candidate_settings(state, candidates):
    """``(name, value)`` of the candidates' settings other than their budget properties
    (the assignment sets those), as the frame reads them."""
    ids = tuple(sorted({m.id for m, _, _ in candidates}))
    names = _SETTING_NAMES.get(ids)
    if names is None:
        budgets = {m.budget[0] for m, _, _ in candidates if m.budget}
        names = _SETTING_NAMES[ids] = sorted(
            {n for m, _, _ in candidates for n in m.scene_properties()} - budgets)
    return [(n, state.settings.get(n)) for n in names]


def choice_key(state) -> dict:
    """What a stored choice depends on, per part: the objects' names and geometry, the
    directions of their visibility, their materials, the lighting's content and strength,
    the error target, the candidates' other settings.  The world's rotation is left out
    (the same environment turned keeps the choice, as the measurement cache does) and so
    is the camera (a stored choice does not flip as the view moves; Choose re-chooses)."""
    env = env_key(state.world, state.resolution)
    return dict(
        geometry=_digest(sorted((st.name, st.fingerprint) for st in state.objects)),
        directions=int(state.resolution),
        materials=_digest(sorted((st.name, _materials_key(st)) for st in state.objects)),
        lighting=_digest(env[0], env[1]),
        target=float(state.settings.get("auto_error_target", 0.02)),
        settings=_digest(_candidate_settings(state, AutoMethod.candidates())))


#: Fields of a stored per-object choice (those of :meth:`AutoMethod.last_choices`).
CHOICE_FIELDS = ("object", "method", "setting", "value", "choice", "error", "seconds",
                 "reason")


def _plain(x):
    """A JSON value: numpy scalars as Python ones, non-finite numbers as None."""
    if isinstance(x, np.generic):
        x = x.item()
    if isinstance(x, float) and not math.isfinite(x):
        return None
    return x


def parse_choice(text: str):
    """The stored choice in ``text`` (``scene.prt.auto_choice``) as a dict, or None when
    there is none, it is unreadable or of another :data:`CHOICE_VERSION`.  Shared between
    callers: not to be modified."""
    if not text:
        return None
    if text not in _PARSED:
        try:
            rec = json.loads(text)
            ok = (isinstance(rec, dict) and rec.get("version") == CHOICE_VERSION
                  and isinstance(rec.get("key"), dict) and isinstance(rec.get("objects"), list)
                  and all(isinstance(c, dict) and set(CHOICE_FIELDS) <= set(c)
                          for c in rec["objects"]))
        except ValueError:
            ok = False
        if len(_PARSED) >= 8:
            _PARSED.pop(next(iter(_PARSED)))
        _PARSED[text] = rec if ok else None
    return _PARSED[text]


def stored_status(prt) -> str:
    """Why ``prt``'s stored choice is out of date ("" when it is not known to be): the
    target is compared here, the rest as the newest AUTO frame found it."""
    record = parse_choice(prt.auto_choice)
    if record is None:
        return ""
    if record["key"].get("target") != float(prt.auto_error_target):
        return "AUTO choice is out of date (target changed)"
    return STORED_STATUS[1] if STORED_STATUS[0] == prt.auto_choice else ""


def _depsgraph(scene):
    """The evaluated depsgraph of ``scene`` (the context's when it is the context scene)."""
    import bpy
    ctx = bpy.context
    if ctx.scene == scene:
        return ctx.evaluated_depsgraph_get()
    with ctx.temp_override(scene=scene, view_layer=scene.view_layers[0]):
        return ctx.evaluated_depsgraph_get()


def _rel(err2: float, ref2: float) -> float:
    """rel-L2 from squared norms (the error itself against a black reference)."""
    if not np.isfinite(err2):
        return float("inf")
    return float(np.sqrt(err2 / ref2)) if ref2 > 0 else float(np.sqrt(err2))


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
            err = "" if c["error"] is None else f" ({100 * c['error']:.2f} %)"
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
        for m, _, _ in self.candidates():
            if type(m).derive is not Method.derive and m.id not in out:
                out[m.id] = m.derive(job)
        return out

    def store(self, scene, job, derived):
        """The candidates' data, then the choice made on it (:meth:`choose`)."""
        for m, _, _ in self.candidates():
            if derived and m.id in derived:
                m.store(scene, job, derived.pop(m.id))
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
        from ..engine import in_render
        if scene.camera is not None:
            record = in_render(scene, lambda dg: self._record(scene, dg))
        else:
            record = self._record(scene, depsgraph or _depsgraph(scene))
        scene.prt.auto_choice = json.dumps(record, sort_keys=True)
        return record

    def _record(self, scene, depsgraph) -> dict:
        """The choice for ``scene`` as :meth:`choose` stores it (writes nothing)."""
        from ..engine import render_camera
        from ..drawing import ensure_gpu
        if scene.camera is None:
            ensure_gpu(scene)       # in -b: candidates' GPU passes are timed as frames run them
        state = runtime.FrameState()
        state.sync(depsgraph)
        if state.error:
            raise RuntimeError(state.error)
        if state.method != self.id:
            state.method = self.id
            self.sync(state)        # the candidates' stored data (sync loaded the scene method's)
        state.camera = render_camera(scene, depsgraph)
        choices = self._selection(state)[0]
        return dict(version=CHOICE_VERSION, key=choice_key(state),
                    camera=scene.camera.name if state.camera is not None else None,
                    size=None if state.camera is None else [state.camera["width"],
                                                            state.camera["height"]],
                    objects=[{f: _plain(c[f]) for f in CHOICE_FIELDS} for c in choices])

    def sync(self, state):
        done = set()
        for m, _, _ in self.candidates():
            if m.id not in done and type(m).sync is not Method.sync:
                done.add(m.id)
                m.sync(state)

    # ------------------------------------------------------------ selection
    def _measure(self, state, st, target):
        """Per-object measurements: for each candidate (and REFERENCE, and budget values
        sized between a method's listed ones) the area-weighted squared error norm against
        REFERENCE at the probes (worst probe), the relit shading time on this object, plus
        the reference's squared norm (smallest probe)."""
        SELECTIONS[0] += 1
        ref = REGISTRY["REFERENCE"]
        view_free = _is_view_independent(st)
        eyes = _probe_eyes(st.points.positions, 1 if view_free else 4)
        one = [st]
        truth = [ref.shade(_substate(state, one, "REFERENCE"), eye, None)[0] for eye in eyes]
        w = core_mesh.corner_areas(st.arrays)
        ref_norm2 = min(_weighted_norm2(t, w) for t in truth)
        # a view-dependent object is judged per probe on what that probe's image shows
        # (its back faces and self-hidden parts count nothing), by relative error
        if view_free:
            probe_w = [w]
        else:
            occluders = (visibility.build_occluder_scene(st.arrays.triangle_positions)
                         if visibility.have_embree() else None)
            probe_w = [_probe_pixel_weights(st, eye, occluders) for eye in eyes]
        probe_ref2_min = min(_weighted_norm2(t, pw) for t, pw in zip(truth, probe_w))
        point_ref2 = _point_norm2(st, truth[0])
        point_err2 = {}     # per option: per-point squared error (view-independent objects)
        cube = directions.cubemap(state.resolution)
        open_sky = bool(np.array_equal(st.bits, runtime.open_visibility(st.points.normals,
                                                                        cube)))
        limit = (SAFETY_DIFFUSE if view_free else SAFETY) * target
        options = []

        def relit_seconds(m, sub):
            return min(relit.relit_times([sub], lambda s: m.shade(s, eyes[0], None),
                                         TIMED_FRAMES, warmup=False,
                                         clock=time.perf_counter)[0])

        def measure(m, prop, value, timed=True) -> bool:
            """Adds the option ``(m.id, prop, value)`` (error at the probes, relit time
            unless ``timed`` is false or it is far off); whether it meets ``limit``."""
            sub = _substate(state, one, m.id, prop, value)
            # the worst probe's squared error over the dimmest probe's norm (a glossy
            # object's highlights move between views: the camera's may be the worst
            # error where the least light is); absolute against black
            worst_e2, rel2 = 0.0, 0.0
            if m is not ref:
                for eye, expected, pw in zip(eyes, truth, probe_w):
                    rad = m.shade(sub, eye, None)
                    e2 = (float("inf") if rad is None or not np.isfinite(rad[0]).all()
                          else _weighted_norm2(rad[0] - expected, pw))
                    worst_e2 = max(worst_e2, e2)
                    rel2 = worst_e2 / probe_ref2_min if probe_ref2_min > 0 else worst_e2
                    if rel2 > (REJECT * target) ** 2:
                        rel2 = float("inf")     # far off at this probe: skip the others
                        break
                    if view_free:
                        point_err2[(m.id, prop, value)] = _point_norm2(st, rad[0] - expected)
            err2 = rel2 * ref_norm2 if ref_norm2 > 0 else rel2
            finite = bool(np.isfinite(err2))
            seconds = relit_seconds(m, sub) if timed and finite else float("inf")
            options.append(((m.id, prop, value), seconds, err2))
            return finite and _rel(err2, ref_norm2) <= limit

        met = set()         # methods whose cheaper budget already meets the target here
        below: dict = {}    # per method: its last measured value that does not meet it
        for m, prop, value in [(ref, None, None)] + self.candidates():
            try:
                if m.id in met:
                    # budgets are listed cheapest first: a later one of a method that
                    # already met the target here is not timed (it is not its fastest)
                    measure(m, prop, value, timed=False)
                elif not measure(m, prop, value):
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
                        if measure(m, prop, mid):
                            hi = mid
                        else:
                            lo = mid
            except Exception as exc:            # a broken candidate is skipped, not fatal
                print(f"PRT AUTO: {m.id} failed on '{st.name}': {exc}")
        notes = (["no occluders"] if open_sky else []) + (["diffuse only"] if view_free else [])
        return dict(object=st.name, options=options, ref_norm2=ref_norm2, limit=limit,
                    notes=notes, view_free=view_free, point_ref2=point_ref2,
                    point_err2=point_err2)

    def choices(self, state):
        """Per-object measurements (cached per object: only what changed is measured
        again), then the assignment for the frame."""
        return self._selection(state)[0]

    def _selection(self, state):
        """(choices, assignment, status note) of the frame; the per-frame work on a hit is
        the cache keys (the materials' repr is kept per synced object)."""
        target = float(state.settings.get("auto_error_target", 0.02))
        key = env_key(state.world, state.resolution)
        env = (key[0], key[1], key[3])      # content and strength: a rotation keeps the choice
        names = tuple((m.id, prop, v) for m, prop, v in self.candidates())
        measured, keys = [], []
        for st in state.objects:
            key = (st.name, id(st.bits), env, target, _materials_key(st), names)
            keys.append(key)
            measured.append(per_visibility(
                _CHOICE_CACHE, key, st.bits, lambda st=st: self._measure(state, st, target),
                limit=256))
        camera = getattr(state, "camera", None)
        cam_key = None if camera is None else (
            np.round(np.asarray(camera["clip"], np.float64), 6).tobytes(),
            camera["width"], camera["height"])
        scene_key = (tuple(keys), cam_key)
        got = _SCENE_CACHE.get(scene_key)
        if got is None:
            out = self._assign(state, measured, target, tuple(keys))
            note = ("AUTO: " + ", ".join(f"{c['object']} → {c['choice']}" for c in out)
                    if out else None)
            got = (out, [(c["method"], c["setting"], c["value"]) for c in out], note)
            _SCENE_CACHE.clear()
            _SCENE_CACHE[scene_key] = got
        LAST_CHOICES[:] = got[0]
        return got

    @staticmethod
    def _mix(measured, budget2):
        """Fastest per-object options with Σ err² ≤ ``budget2`` (Lagrangian relaxation:
        each object minimises time + λ·err², λ bisected to the smallest that fits; then
        the slack left is spent on cheaper options the relaxation cannot reach)."""
        usable = [[o for o in m["options"] if np.isfinite(o[1]) and np.isfinite(o[2])]
                  for m in measured]

        def pick(lam):
            return [min(ok, key=lambda o: (o[1] + lam * o[2], o[2])) for ok in usable]

        def spend_slack(chosen):
            """The relaxation only reaches each object's lower convex hull of (err², time)
            (e.g. a light count sized between two listed ones is often off it): swap in
            the cheaper option that saves the most time while Σ err² still fits."""
            chosen = list(chosen)
            while True:
                slack = budget2 - sum(o[2] for o in chosen)
                swaps = [(c[1] - o[1], i, o) for i, (ok, c) in enumerate(zip(usable, chosen))
                         for o in ok if o[1] < c[1] and o[2] - c[2] <= slack]
                if not swaps:
                    return chosen
                _, i, o = max(swaps, key=lambda x: x[0])
                chosen[i] = o

        if sum(o[2] for o in pick(0.0)) <= budget2:
            return pick(0.0)
        lo, hi = 0.0, 1.0
        while sum(o[2] for o in pick(hi)) > budget2 and hi < 1e30:
            lo, hi = hi, hi * 10.0
        for _ in range(60):
            mid = (lo + hi) / 2
            if sum(o[2] for o in pick(mid)) <= budget2:
                hi = mid
            else:
                lo = mid
        best = pick(hi)
        return spend_slack(best) if sum(o[2] for o in best) <= budget2 else best

    @staticmethod
    def _on_camera(state, measured, target):
        """``measured`` weighed for the frame's camera (``state.camera``, set by the
        engine): each point's squared error and reference norm count by the pixels its
        corners cover in this image (:func:`core.screen.corner_pixel_weights`; hidden,
        off-screen and back-facing surface counts nothing), so the frame's estimate is
        the image's rel-L2 rather than the surface's.  Diffuse-only objects have their
        per-point errors (view independent); a glossy object's probe rel-L2 is scaled
        to its norm in the image.  Unchanged without a camera or when nothing shows."""
        camera = getattr(state, "camera", None)
        if camera is None or not measured:
            return measured, False
        arrays = [st.arrays for st in state.objects]
        # keyed on the geometry's fingerprints, not the arrays: every sync (each F12, each
        # viewport update) exports new arrays of the same meshes
        occluders = held(
            _OCCLUDERS, tuple((st.name, st.fingerprint) for st in state.objects), (),
            lambda: (visibility.build_occluder_scene(
                np.concatenate([a.triangle_positions for a in arrays]))
                if visibility.have_embree() else None), limit=1)
        weights = screen.corner_pixel_weights(
            arrays, camera["clip"], camera["width"],
            camera["height"], eye=camera["eye"], view_dir=camera["view_dir"],
            occluders=occluders)
        out = []
        for st, m, wc in zip(state.objects, measured, weights):
            wp = np.bincount(st.points.point_of_corner, weights=wc, minlength=st.points.count)
            ref2 = float(wp @ m["point_ref2"])
            scale = ref2 / m["ref_norm2"] if m["ref_norm2"] > 0 else 1.0
            options = []
            for key, seconds, err2 in m["options"]:
                per_point = m["point_err2"].get(key)
                if per_point is not None and np.isfinite(err2):
                    err2 = float(wp @ per_point)
                elif np.isfinite(err2):
                    err2 = err2 * scale
                options.append((key, seconds, err2))
            out.append(dict(m, options=options, ref_norm2=ref2,
                            limit=(SAFETY_CAMERA if m["view_free"] else SAFETY) * target))
        if sum(m["ref_norm2"] for m in out) <= 0:
            return measured, False
        return out, True

    def _assign(self, state, measured, target, objects_key):
        """The frame's assignment: the Lagrangian per-object mix against the whole scene's
        rel-L2 budget (in the frame camera's image when known, else at the probes),
        timed (relit frames of the whole scene) against each single candidate that also
        fits the budget; the fastest wins.  Timings are kept per assignment, so a new
        camera times only assignments not seen before."""
        measured, on_camera = self._on_camera(state, measured, target)
        limit = min(m["limit"] for m in measured) if measured else target
        total_ref2 = sum(m["ref_norm2"] for m in measured)
        budget2 = (limit ** 2) * total_ref2
        mix = self._mix(measured, budget2)
        options = {"mix": [o[0] for o in mix]}
        by_key = [{o[0]: o for o in m["options"]} for m in measured]
        if len(measured) > 1:
            def estimate(m, o):
                """Time of an option; one not timed (a later budget of a method that
                already met the target) is at least its method's timed ones."""
                if np.isfinite(o[1]):
                    return o[1]
                same = [x[1] for x in m["options"] if x[0][0] == o[0][0] and np.isfinite(x[1])]
                return max(same) if same else float("inf")

            # a single candidate for every object: only budget values every object has
            # measured (values sized between the listed ones differ between objects)
            shared = set(by_key[0]).intersection(*by_key[1:])
            uniform = []
            for cand in shared:
                per = [k[cand] for k in by_key]
                if any(not np.isfinite(o[2]) for o in per):
                    continue
                est = sum(estimate(m, o) for m, o in zip(measured, per))
                if sum(o[2] for o in per) <= budget2 and np.isfinite(est):
                    uniform.append((est, _label(*cand), cand))
            for _, _, cand in sorted(uniform)[:UNIFORM_TRIED]:
                if [cand] * len(measured) != options["mix"]:
                    options[cand] = [cand] * len(measured)
        timed = {}
        if len(options) > 1:
            eye = _probe_eyes(np.concatenate([st.points.positions for st in state.objects]),
                              1)[0]
            # the timings of this scene's objects (their visibility arrays held with
            # them, so an id in the key is never another object's)
            seen = held(_TIMED, objects_key, [st.bits for st in state.objects], dict,
                                limit=16)
            for name, assignment in options.items():
                tkey = tuple(assignment)
                if tkey not in seen:
                    seen[tkey] = min(relit.relit_times(
                        [copy.copy(state)],
                        lambda s: self._shade_assigned(s, assignment, eye, None),
                        TIMED_FRAMES + 1, warmup=False, clock=time.perf_counter)[0])
                timed[name] = seen[tkey]
        best = min(timed, key=timed.get) if timed else "mix"
        assignment = options[best]
        scene_rel = _rel(sum(k[a][2] for k, a in zip(by_key, assignment)), total_ref2)
        where = "in the camera's image" if on_camera else "at the probes"
        if best == "mix":
            why = (f"fastest mix within {limit:.2%} of the whole scene {where} "
                   f"({scene_rel:.2%})")
            if timed:
                why += f"; {timed['mix'] * 1e3:.2f} ms per relit frame, faster than " + \
                    ", ".join(f"{_label(*k)} {v * 1e3:.2f} ms" for k, v in timed.items()
                              if k != "mix")
        else:
            why = (f"one method for the whole scene is fastest ({timed[best] * 1e3:.2f} ms "
                   f"per relit frame, {scene_rel:.2%} {where}; the per-object mix "
                   f"{timed['mix'] * 1e3:.2f} ms)")
        out = []
        for m, k, a in zip(measured, by_key, assignment):
            o = k[a]
            out.append(dict(object=m["object"], method=a[0], setting=a[1], value=a[2],
                            choice=_label(*a), error=_rel(o[2], m["ref_norm2"]),
                            seconds=o[1], reason="; ".join(m["notes"] + [why])))
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
        for (mid, prop, value), idx in groups.items():
            sub = _substate(state, [state.objects[i] for i in idx], mid, prop, value)
            for i, rad in zip(idx, REGISTRY[mid].shade(sub, eye, view_dir)):
                out[i] = rad
        return out

    def _stored(self, state):
        """``(assignment, choices)`` of the scene's stored choice when it holds for
        ``state``, else ``(None, why not)``."""
        record = parse_choice(state.settings.get("auto_choice", ""))
        if record is None:
            return None, "AUTO has no stored choice"
        changed = [part for part, value in choice_key(state).items()
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
        """The frame's assignment and notes: the stored choice when it holds (nothing is
        timed), else the live one, noted as out of date (nothing is written here: frames
        may be drawn off the main thread)."""
        text = state.settings.get("auto_choice", "")
        assignment, got = self._stored(state)
        if assignment is not None:
            STORED_STATUS[:] = [text, ""]
            LAST_CHOICES[:] = got
            return assignment, ["AUTO (stored choice): " + ", ".join(
                f"{c['object']} → {c['choice']}" for c in got)]
        STORED_STATUS[:] = [text, got]
        _, assignment, note = self._selection(state)
        return assignment, [f"{got}: press Choose (or Precompute); this frame is chosen live",
                            note]

    def shade(self, state, eye, view_dir):
        assignment, notes = self._frame_assignment(state)
        out = self._shade_assigned(state, assignment, eye, view_dir)
        for note in notes:
            if note:
                state.note(note)
        return out


register(AutoMethod())
