"""AUTO's measurement of one object: every candidate method and budget shaded on a sample of
the object's points from probe views, its error against REFERENCE (with the sample's margin)
and its time per frame."""

from __future__ import annotations

import copy
import time

import numpy as np

from ....core.common.parallel import Cancelled
from ....core.methods.auto import choice as auto_choice
from ....core.methods.auto import screen
from ....core.scene import mesh as core_mesh
from ....core.scene import visibility
from ....core.sphere import directions
from ...frame import relit
from ...frame import state as runtime
from .. import REGISTRY
from ..contract import Shading

#: Fraction of the target a candidate must reach at the probes: view-dependent objects
#: (the camera sees other highlights than the probes) and diffuse-only ones (the probe
#: error is the drawn per-corner error; pixels weight corners by screen area).
SAFETY = 0.75


SAFETY_DIFFUSE = 0.9


#: A candidate this many times the target off at a probe is not measured further.
REJECT = 4.0


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


#: Number of selections run (tests check that unchanged objects are not re-selected).
SELECTIONS = [0]


def is_view_independent(st) -> bool:
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


def substate(state, objects, method_id, setting=None, value=None, quiet=False):
    """A copy of ``state`` shading ``objects`` with one method (and budget value); ``quiet``:
    it reports no progress (AUTO's measurements; ESC still stops it)."""
    sub = copy.copy(state)              # shares world, warnings, background
    if quiet:
        sub.progress = None
        sub.visible_only = False          # a measurement shades every point it asks for
    sub.objects = list(objects)
    sub.method = method_id
    if setting is not None:
        sub.settings = dict(state.settings, **{setting: value})
    return sub


def candidate_label(method_id, setting, value) -> str:
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


def weighted_sum(sample, weights, values) -> float:
    """``Σ_p w_p f_p`` estimated from per-row ``values`` (``weights`` None: area)."""
    w = sample.area if weights is None else weights
    return float((sample.scale * w) @ np.asarray(values, np.float64))


def _norm2(x) -> np.ndarray:
    return np.sum(np.square(np.asarray(x, np.float64)), axis=-1)


def point_pixel_weights(meshes, points, rows, clip, width, height, eye=None, view_dir=None,
                         occluders=None) -> list:
    """Per object, the pixels each of its points ``rows`` covers in the image of ``clip``
    (:func:`core.methods.auto.screen.corner_pixel_weights` of the triangles around those points only;
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
    its triangles; see :func:`core.methods.auto.screen.corner_pixel_weights`)."""
    p = st.points.positions
    centre = (p.min(axis=0) + p.max(axis=0)) / 2
    dist = max(float(np.linalg.norm(np.asarray(eye) - centre)), 1e-9)
    radius = max(float(np.linalg.norm(p.max(axis=0) - p.min(axis=0))) / 2, 1e-9)
    fov = 2.0 * np.arctan(min(1.2 * radius / dist, 10.0))
    clip = screen.look_at_clip(eye, centre, fov, near=dist * 1e-3, far=dist * 10.0)
    return point_pixel_weights([st.arrays], [st.points], [rows], clip, size, size, eye=eye,
                                occluders=occluders)[0]


rel_error = auto_choice.rel_error


def candidates():
    """(method, budget property or None, value) of every other per-vertex method."""
    out = []
    for m in REGISTRY.values():
        if m.id in ("AUTO", "REFERENCE"):
            continue
        if type(m.shading).draw_objects is not Shading.draw_objects:
            continue
        prop, values = m.bench.budget if m.bench.budget else (None, [None])
        out += [(m, prop, v) for v in values]
    return out


def measure_steps(state, st, target):
    """Per-object measurements on a sample of its points (a generator: yields after
    every frame it shades, returns the measurement): for each candidate
    (and REFERENCE, and budget values sized between a method's listed ones) the
    estimated squared error norm against REFERENCE at the probes (worst probe, with its
    sampling margin), the modelled relit shading time on the whole object, plus the
    reference's squared norm (smallest probe)."""
    SELECTIONS[0] += 1
    ref = REGISTRY["REFERENCE"]
    pts = st.points
    view_free = is_view_independent(st)
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
        rad = ref.shading.shade(substate(state, [one.obj], "REFERENCE", quiet=True), eye, None)
        if k:
            ref_warm = min(ref_warm, time.perf_counter() - t0)
        truth.append(one.values(rad[0]))
        yield
    ref2 = [_norm2(t) for t in truth]
    ref_norm2 = min(weighted_sum(sample, None, b) for b in ref2)
    # a view-dependent object is judged per probe on what that probe's image shows
    # (its back faces and self-hidden parts count nothing), by relative error
    if view_free:
        probe_w = [None]
    else:
        occluders = (visibility.build_occluder_scene(st.arrays.triangle_positions)
                     if visibility.have_embree() else None)
        probe_w = [_probe_pixel_weights(st, sample.rows, eye, occluders) for eye in eyes]
        del occluders
    probe_ref2_min = min(weighted_sum(sample, pw, b) for pw, b in zip(probe_w, ref2))
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
        m.shading.shade(sub, eyes[0], None)
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
        sub = substate(state, [one.obj], m.id, prop, value, quiet=True)
        n_a = one.obj.points.count
        if few is None:                     # measured whole: timed whole
            whole = relit_seconds(m, sub)
            return auto_choice.linear_time(n_a, whole, n_a, whole, pts.count)
        small = substate(state, [few.obj], m.id, prop, value, quiet=True)
        first = substate(state, [point.obj], m.id, prop, value, quiet=True)
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
        sub = substate(state, [one.obj], m.id, prop, value, quiet=True)
        # the worst probe's squared error over the dimmest probe's norm (a glossy
        # object's highlights move between views: the camera's may be the worst
        # error where the least light is); absolute against black
        worst, worst_up, warm = 0.0, 0.0, None
        if m is not ref:
            for k, (eye, expected, b2, pw) in enumerate(zip(eyes, truth, ref2, probe_w)):
                state.tick()
                t0 = time.perf_counter()
                rad = m.shading.shade(sub, eye, None)
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
        return finite and rel_error(err2_up, ref_norm2) <= limit

    met = set()         # methods whose cheaper budget already meets the target here
    below: dict = {}    # per method: its last measured value that does not meet it
    for m, prop, value in [(ref, None, None)] + candidates():
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
                    mid = m.bench.budget_between(lo, hi)
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
