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

Sample (:mod:`core.methods.auto.choice`): :data:`SAMPLE_POINTS` (512) draws per object with
probability proportional to area, one per stratum of equal area along a Morton curve
(fixed seed :data:`SEED`: a function of the geometry); an object with fewer points is
measured whole, exactly as before.  The methods shade the drawn points only (the object
restricted to them: :func:`_restricted`), so a choice costs about the same at 5k and
500k points.  Each error is an estimate ``Ê`` with a standard error ``σ`` (of ``Ê - R̂ B̂``
against the reference norm ``B̂`` of the same draws); every decision uses ``Ê + z σ``
(``z`` = :data:`core.methods.auto.choice.MARGIN_Z` = 2), and the stored choice reports the
estimate and that margin per object.

Time: with the lighting turned to an angle not used before, a candidate's frame of one
sampled point (it does the lighting's shared work: resampling, tables), then of the
sample and of every eighth drawn point (:data:`SLOPE_POINTS`), which find that work
cached: their slope is the per-point part ``s`` (per-lighting and per-view work), the
first frame the fixed part ``F``, so a relit frame of the whole object is modelled as
``t(P) = F + s P`` (:func:`core.methods.auto.choice.relit_time`; an object measured whole is
timed whole).  The whole frame's time of an assignment is
modelled from those (:func:`core.methods.auto.choice.assignment_seconds`: objects sharing a
method pay its fixed part once), not timed on the whole scene.  A candidate slower than
REFERENCE on the sample (with the lighting cached) cannot be the fastest at any error
and is not measured further.

A diffuse-only object's error is view independent and kept per sampled point; a glossy
object is judged per probe on what that probe's image shows (points weighted by the
pixels they cover from it, :func:`_probe_pixel_weights`): the worst probe's squared
error over the dimmest probe's norm.

Camera: when the engine draws a frame it sets ``state.camera``; the per-point errors and
reference norms are then weighed by the pixels each sampled point covers in that image
(:func:`core.methods.auto.screen.corner_pixel_weights` of the triangles around the sampled points), so
the frame's estimate is the image's rel-L2 (measured a little above it, never below)
and an object out of view costs nothing (:func:`.assign.camera_weighted`; margin
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
is found by Lagrangian relaxation (:func:`core.methods.auto.choice.mix`): each object takes the
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
AUTO box of the settings and in the report (:meth:`AutoShading.last_choices`).

Progress and cancelling: the measurement is a generator of steps (one candidate on one
object each, :meth:`AutoShading.choice_steps`); ``prt.auto_choose`` runs one step per timer
event in the UI (progress bar, ESC cancels, nothing written), ``execute`` and ``-b`` run
them all; a live choice inside F12 reports through the frame's progress hook and stops
on ESC (:meth:`runtime.FrameState.tick`).

Stored choice: the measurement times shading, so two processes choose differently.  The
choice is therefore made by an explicit step on the main thread -- the precompute's commit
when the method is AUTO (:meth:`AutoShading.store`) and the *Choose* operator
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


import numpy as np

from ....core.methods.auto import choice as auto_choice
from ....core.pipeline import frame_status
from ...gpu import drawing
from ...frame import state as runtime
from ...frame.keys import cache, env_key, held
from .. import REGISTRY
from ..contract import Shading
from .store import CHOICE_EXTRA, CHOICE_FIELDS, CHOICE_VERSION, STORED_STATUS, materials_key, plain, choice_key, parse_choice, write_choice
from . import measure
from .measure import BETWEEN_STEPS, PROBES, SAMPLE_POINTS, SEED, SLOPE_POINTS, is_view_independent, substate, measure_steps
from .assign import assign

# Per-object selections: (name, id(bits), lighting content, target, materials, candidates);
# the same environment turned (Mapping rotation) keeps the choice.
CHOICE_CACHE = cache(256)
# The scene-level assignment for the newest tuple of per-object keys (and camera).
_SCENE_CACHE = cache(1)
#: The newest per-object choices (what the panel and the report show).
LAST_CHOICES: list = []


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


class AutoShading(Shading):


    def view_dependent(self, state) -> bool:
        return not all(is_view_independent(st) for st in state.objects)

    def derive(self, job):
        out = {}
        derived = [m for m in dict.fromkeys(m for m, _, _ in measure.candidates())
                   if m.derives]
        for m in derived:
            job.stage = f"deriving {m.label}"
            out[m.id] = m.shading.derive(job)
        return out

    def store(self, scene, job, derived):
        """The candidates' data, then the choice made on it (:meth:`choose`) -- unless the
        job defers it (``job.defer_choice``: the modal precompute runs
        :meth:`choice_steps` itself, one step per timer event)."""
        for m, _, _ in measure.candidates():
            if derived and m.id in derived:
                m.shading.store(scene, job, derived.pop(m.id))
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
        from ...frame.engine import in_render
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
        from ...frame.engine import render_camera
        state = runtime.FrameState()
        state.sync(depsgraph)
        if state.error:
            raise RuntimeError(state.error)
        if state.method != "AUTO":
            state.method = "AUTO"
            self.sync(state)        # the candidates' stored data (sync loaded the scene method's)
        state.camera = None if probes_only else render_camera(scene, depsgraph)
        camera_name = scene.camera.name if state.camera is not None else None
        yield 0.0
        choices = (yield from self._selection_steps(state))[0]
        return dict(version=CHOICE_VERSION, key=choice_key(state, measure.candidates()), camera=camera_name,
                    size=None if state.camera is None else [state.camera["width"],
                                                            state.camera["height"]],
                    sample=dict(points=SAMPLE_POINTS, slope_points=SLOPE_POINTS, seed=SEED,
                                probes=PROBES, z=auto_choice.MARGIN_Z),
                    objects=[{f: plain(c[f]) for f in CHOICE_FIELDS + CHOICE_EXTRA if f in c}
                             for c in choices])

    def sync(self, state):
        done = set()
        for m, _, _ in measure.candidates():
            if m.id not in done and type(m.shading).sync is not Shading.sync:
                done.add(m.id)
                m.shading.sync(state)

    # ------------------------------------------------------------ selection
    def _steps_per_object(self, st) -> int:
        """About how many steps :meth:`_measure_steps` takes on ``st`` (the progress bar's
        scale: a step per frame it shades)."""
        probes = 1 if is_view_independent(st) else PROBES
        return 2 + (len(measure.candidates()) + BETWEEN_STEPS) * (probes + 3)


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
        names = tuple((m.id, prop, v) for m, prop, v in measure.candidates())
        sampling = (SAMPLE_POINTS, SLOPE_POINTS, SEED, PROBES)
        keys, measured = [], []
        for st in state.objects:
            keys.append((st.name, id(st.bits), env, target, materials_key(st), names,
                         sampling))
            entry = CHOICE_CACHE.get(keys[-1])
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
            steps = measure_steps(state, st, target)
            while True:
                try:
                    next(steps)
                except StopIteration as stop:
                    result = stop.value
                    break
                done += 1
                yield min(done / total, 0.99)
            measured[i] = held(CHOICE_CACHE, keys[i], (st.bits,), lambda: result,
                               limit=256)
        camera = getattr(state, "camera", None)
        cam_key = None if camera is None else (
            np.round(np.asarray(camera["clip"], np.float64), 6).tobytes(),
            camera["width"], camera["height"])
        scene_key = (tuple(keys), cam_key)
        got = _SCENE_CACHE.get(scene_key)
        if got is None:
            out = assign(state, measured, target)
            note = ("AUTO: " + frame_status.listing(f"{c['object']} → {c['choice']}"
                                                    for c in out)
                    if out else None)
            got = (out, [(c["method"], c["setting"], c["value"]) for c in out], note)
            _SCENE_CACHE.clear()
            _SCENE_CACHE[scene_key] = got
        LAST_CHOICES[:] = got[0]
        yield 1.0
        return got


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
            sub = substate(state, [state.objects[i] for i in idx], mid, prop, value)
            # progress: the group's share of the points
            share = sum(state.objects[i].points.count for i in idx)
            total = max(sum(st.points.count for st in state.objects), 1)
            with sub.span(done / total, (done + share) / total):
                for i, rad in zip(idx, REGISTRY[mid].shading.shade(sub, eye, view_dir)):
                    out[i] = rad
            done += share
        return out

    def _stored(self, state):
        """``(assignment, choices)`` of the scene's stored choice when it holds for
        ``state``, else ``(None, why not)``."""
        record = parse_choice(state.settings.get("auto_choice", ""))
        if record is None:
            return None, "AUTO has no stored choice"
        # a part of the frame (FrameState.shade) holds the whole frame's choice
        whole = state.whole if state.whole is not None else state
        changed = [part for part, value in choice_key(whole, measure.candidates()).items()
                   if record["key"].get(part) != value]
        if changed:
            return None, f"AUTO choice is out of date ({', '.join(changed)} changed)"
        by_name = {c["object"]: c for c in record["objects"]}
        chosen = [by_name.get(st.name) for st in whole.objects]
        for c in chosen:
            m = REGISTRY.get(c["method"]) if c is not None else None
            if m is None or m.shading is self or \
                    type(m.shading).draw_objects is not Shading.draw_objects or \
                    (c["setting"] is not None and c["setting"] not in state.settings):
                return None, ("AUTO choice is out of date (it names an object or method no "
                              "longer present)")
        return [(c["method"], c["setting"], c["value"])
                for c in (by_name[st.name] for st in state.objects)], chosen

    def _frame_assignment(self, state):
        """The frame's assignment, notes and whether it was chosen live: the stored choice
        when it holds (nothing is timed), else the live one, noted as out of date (nothing
        is written here: frames may be drawn off the main thread)."""
        text = state.settings.get("auto_choice", "")
        assignment, got = self._stored(state)
        if assignment is not None:
            STORED_STATUS[:] = [text, ""]
            LAST_CHOICES[:] = got
            return assignment, ["AUTO (stored choice): " + frame_status.listing(
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


