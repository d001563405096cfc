"""AUTO: per object, the cheapest registered representation that meets the scene's error
target against REFERENCE (issue 6).

Selection (once per object, lighting content and target; cached, so only what changed
is recomputed; turning the same environment keeps the choice): every other per-vertex method × every value of its budget is run on the
object alone at a few probe views around it, timed, and its per-corner radiance compared
with REFERENCE's (rel-L2 over the object's corners, worst probe).  The fastest candidate
whose error is at most ``SAFETY × auto_error_target`` wins; REFERENCE when none does.
The cost of a candidate is its relit shading time on the object (the lighting turned
to a new angle, as in the report's per-frame timing).  A method shared by several objects
pays its per-lighting work once, so the per-object mix is then timed, on the whole scene,
against each single candidate that meets the target on every object; the faster wins.
Per-object rel-L2 ≤ t for every object implies rel-L2 ≤ t for their union, so the whole
frame meets the target where the camera sees what the probes saw; ``SAFETY`` leaves room
for the camera's own view of glossy objects and for the pixel-space measure.

Shortcuts that make the selection itself cheap:

* diffuse-only objects (no glossy lobe, no dielectric layer) are view independent: one
  probe instead of three (and no candidate evaluates a BRDF table for them);
* a candidate whose first probe already misses the target is not run at the others;
* objects with the fully open hemisphere (no occluders) and low-frequency lighting are
  where the cheapest candidates (SH) pass the measurement; the reason column says so.

Per-pixel methods (``draw_objects``) cannot be mixed per object and are left out of the
candidates.  The choice per object is shown as a note in the panels/status bar, in the
AUTO box of the settings and in the report (:meth:`AutoMethod.last_choices`).
"""

from __future__ import annotations

import copy
import statistics
import time

import numpy as np

from ...core import directions
from .. import runtime
from . import REGISTRY, Method, register

#: Fraction of the target a candidate must reach at the probes: view-dependent objects
#: (the camera sees other highlights than the probes) and diffuse-only ones (the probe
#: error is the drawn per-corner error; pixels weight corners by screen area).
SAFETY = 0.75
SAFETY_DIFFUSE = 0.9
#: Relit shading passes timed per candidate (the fastest counts; each one resamples
#: the environment for cubemap-based methods, the dominant cost of a selection).
TIMED_FRAMES = 1
_ANGLE = [0.0]
# Per-object selections: (name, id(bits), lighting content, target, materials, candidates);
# the same environment turned (Mapping rotation) keeps the choice.
_CHOICE_CACHE: dict = {}
# The scene-level assignment for the newest tuple of per-object keys.
_SCENE_CACHE: dict = {}
#: The newest per-object choices (what the panel and the report show).
LAST_CHOICES: list = []
#: Number of selections run (tests check that unchanged objects are not re-selected).
SELECTIONS = [0]


def _is_view_independent(st) -> bool:
    return all(m.is_diffuse_only and m.fresnel != "DIELECTRIC" for m in st.materials) \
        if st.materials else True


def _probe_eyes(st, count: int):
    """Camera positions around the object's bounding box (3 × its radius away)."""
    p = st.points.positions
    lo, hi = p.min(axis=0), p.max(axis=0)
    centre = (lo + hi) / 2
    radius = max(float(np.linalg.norm(hi - lo)) / 2, 1e-3)
    dirs = np.array([[0.0, -1.0, 0.5], [0.87, 0.5, 0.5], [-0.87, 0.5, 0.5]])[:count]
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


def _rotated(world, angle: float):
    """``world`` turned about +Z: the same pixels under a new lighting key."""
    out = copy.copy(world)
    c, s = np.cos(angle), np.sin(angle)
    out.rotation = np.asarray(world.rotation) @ np.array([[c, -s, 0.0], [s, c, 0.0],
                                                           [0.0, 0.0, 1.0]])
    return out


def _rel_l2(a, b) -> float:
    a = np.asarray(a, np.float64)
    b = np.asarray(b, np.float64)
    if not (np.isfinite(a).all() and np.isfinite(b).all()):
        return float("inf")
    nb = float(np.linalg.norm(b))
    d = float(np.linalg.norm(a - b))
    return d / nb if nb > 0 else d


class AutoMethod(Method):
    id = "AUTO"
    label = "Auto"
    description = ("Per object, the cheapest method and budget that meets the error target "
                   "against REFERENCE (measured per object, cached per lighting)")
    budget = None

    def scene_properties(self):
        from bpy.props import FloatProperty
        return {"auto_error_target": FloatProperty(
            name="Error Target", default=0.02, min=0.0, max=1.0, precision=3,
            subtype="FACTOR", update=runtime.redraw_viewports,
            description="AUTO: largest rel-L2 error against REFERENCE allowed per object "
                        "(0.02 = 2 %)")}

    def draw_settings(self, layout, prt):
        layout.prop(prt, "auto_error_target")
        if LAST_CHOICES:
            box = layout.box()
            for c in LAST_CHOICES[:8]:
                err = "" if c["error"] is None else f" ({100 * c['error']:.2f} %)"
                box.label(text=f"{c['object']}: {c['choice']}{err}", icon="OBJECT_DATA")

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
        for m, _, _ in self.candidates():
            if derived and m.id in derived:
                m.store(scene, job, derived.pop(m.id))

    def sync(self, state):
        done = set()
        for m, _, _ in self.candidates():
            if m.id not in done and type(m).sync is not Method.sync:
                done.add(m.id)
                m.sync(state)

    # ------------------------------------------------------------ selection
    def _select(self, state, st, target):
        """Choice for one object: dict(method, setting, value, choice, error, reason)."""
        SELECTIONS[0] += 1
        ref = REGISTRY["REFERENCE"]
        view_free = _is_view_independent(st)
        eyes = _probe_eyes(st, 1 if view_free else 3)
        one = [st]
        truth = [ref.shade(_substate(state, one, "REFERENCE"), eye, None)[0] for eye in eyes]
        cube = directions.cubemap(state.resolution)
        open_sky = bool(np.array_equal(st.bits, runtime.open_visibility(st.points.normals,
                                                                        cube)))
        limit = (SAFETY_DIFFUSE if view_free else SAFETY) * target
        tried = []
        for m, prop, value in self.candidates():
            sub = _substate(state, one, m.id, prop, value)
            worst = 0.0
            try:
                for eye, expected in zip(eyes, truth):
                    rad = m.shade(sub, eye, None)
                    worst = float("inf") if rad is None else max(worst,
                                                                 _rel_l2(rad[0], expected))
                    if worst > limit:
                        break                   # missed at this probe: skip the others
                if worst > limit:
                    tried.append((m, prop, value, float("inf"), worst))
                    continue
                # Cost: relit shading of this object (the lighting turned to angles not
                # used before, as in the report's timing); geometry caches are warm now.
                times = []
                for _ in range(TIMED_FRAMES):
                    _ANGLE[0] += 0.61
                    sub.world = _rotated(state.world, _ANGLE[0])
                    t0 = time.perf_counter()
                    m.shade(sub, eyes[0], None)
                    times.append(time.perf_counter() - t0)
            except Exception as exc:            # a broken candidate is skipped, not fatal
                print(f"PRT AUTO: {m.id} failed on '{st.name}': {exc}")
                continue
            tried.append((m, prop, value, min(times), worst))
        meeting = [c for c in tried if c[4] <= limit]
        notes = []
        if open_sky:
            notes.append("no occluders")
        if view_free:
            notes.append("diffuse only")
        if meeting:
            m, prop, value, seconds, err = min(meeting, key=lambda c: c[3])
            why = (f"fastest of {len(meeting)}/{len(tried)} candidates within "
                   f"{limit:.2%} at the probes ({seconds * 1e3:.2f} ms per relit frame "
                   "on this object)")
            return dict(object=st.name, method=m.id, setting=prop, value=value,
                        choice=_label(m.id, prop, value), error=err, seconds=seconds,
                        reason="; ".join(notes + [why]),
                        meeting={(c[0].id, c[1], c[2]): c[4] for c in meeting})
        best = min(tried, key=lambda c: c[4]) if tried else None   # noqa: F841
        why = "no candidate meets the target: REFERENCE" + (
            f" (best {best[0].id} {best[2]}: {100 * best[4]:.2f} %)" if best else "")
        return dict(object=st.name, method="REFERENCE", setting=None, value=None,
                    choice="REFERENCE", error=0.0, seconds=None,
                    reason="; ".join(notes + [why]), meeting={})

    def choices(self, state):
        """Per-object choices (cached per object), then one scene-level check: a method
        that several objects share pays its per-lighting work once, so the fastest
        per-object mix is timed against every single candidate that meets the target on
        all objects (relit frames of the whole scene) and the faster assignment wins."""
        target = float(state.settings.get("auto_error_target", 0.02))
        key = runtime.env_key(state.world, state.resolution)
        env = (key[0], key[1], key[3])      # content and strength: a rotation keeps the choice
        names = tuple((m.id, prop, v) for m, prop, v in self.candidates())
        per_object, keys = [], []
        for st in state.objects:
            key = (st.name, id(st.bits), env, target, repr(st.materials), names)
            keys.append(key)
            per_object.append(runtime.per_visibility(
                _CHOICE_CACHE, key, st.bits, lambda st=st: self._select(state, st, target),
                limit=256))
        scene_key = tuple(keys)
        out = _SCENE_CACHE.get(scene_key)
        if out is None:
            out = self._scene_choice(state, per_object)
            _SCENE_CACHE.clear()
            _SCENE_CACHE[scene_key] = out
        LAST_CHOICES[:] = out
        return out

    def _scene_choice(self, state, per_object):
        mixed = [(c["method"], c["setting"], c["value"]) for c in per_object]
        common = set(per_object[0]["meeting"]) if per_object else set()
        for c in per_object[1:]:
            common &= set(c["meeting"])
        options = [mixed] + [[cand] * len(per_object) for cand in sorted(common, key=str)
                             if [cand] * len(per_object) != mixed]
        if len(options) == 1:
            return per_object
        timed = []
        for assignment in options:
            times = []
            for _ in range(TIMED_FRAMES):
                _ANGLE[0] += 0.61
                sub = copy.copy(state)
                sub.world = _rotated(state.world, _ANGLE[0])
                t0 = time.perf_counter()
                self._shade_assigned(sub, assignment, None, None)
                times.append(time.perf_counter() - t0)
            timed.append((min(times), assignment))
        seconds, best = min(timed, key=lambda t: t[0])
        if best == mixed:
            return per_object
        mid, prop, value = best[0]
        note = (f"one method for the whole scene is faster ({seconds * 1e3:.2f} ms per "
                f"relit frame vs {timed[0][0] * 1e3:.2f} ms for the per-object mix)")
        return [dict(c, method=mid, setting=prop, value=value, choice=_label(mid, prop, value),
                     error=c["meeting"][best[0]], reason=note) for c in per_object]

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

    def shade(self, state, eye, view_dir):
        chosen = self.choices(state)
        out = self._shade_assigned(state, [(c["method"], c["setting"], c["value"])
                                           for c in chosen], eye, view_dir)
        if chosen:
            state.note("AUTO: " + ", ".join(f"{c['object']} → {c['choice']}" for c in chosen))
        return out


register(AutoMethod())
