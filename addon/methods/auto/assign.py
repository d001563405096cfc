"""AUTO's assignment: per object the method and budget that meets the scene's error budget at
the least modelled frame time (a mix of candidates against every single one), weighted by
what the frame's camera sees."""

from __future__ import annotations

import numpy as np

from ....core.methods.auto import choice as auto_choice
from ....core.scene import visibility
from ...frame.keys import cache, held
from .measure import SAFETY, candidate_label, point_pixel_weights, weighted_sum, rel_error

#: The same for diffuse-only objects when the frame's camera is known: their per-vertex
#: errors are then weighed by the pixels each corner covers in that image
#: (:func:`core.methods.auto.screen.corner_pixel_weights`), which leaves only interpolation inside
#: triangles and antialiased edges between the estimate and the image's rel-L2.
SAFETY_CAMERA = 0.95


#: Single methods compared with the mix on the whole scene (the fastest by estimate).
UNIFORM_TRIED = 3


# Embree scene of the frame's triangles for the camera weights, per the objects' mesh
# fingerprints (made again for other geometry).
_OCCLUDERS = cache(1)


def camera_weighted(state, measured, target):
    """``measured`` weighed for the frame's camera (``state.camera``, set by the
    engine): each sampled point's squared error and reference norm count by the pixels
    it covers in this image (:func:`core.methods.auto.screen.corner_pixel_weights`; hidden,
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
    weights = point_pixel_weights(
        [st.arrays for st in state.objects], [st.points for st in state.objects],
        [m["sample"].rows for m in measured], camera["clip"], camera["width"],
        camera["height"], eye=camera["eye"], view_dir=camera["view_dir"],
        occluders=occluders)
    out = []
    for m, wp in zip(measured, weights):
        sample = m["sample"]
        ref2 = weighted_sum(sample, wp, m["point_ref2"])
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


def assign(state, measured, target):
    """The frame's assignment: the Lagrangian per-object mix
    (:func:`core.methods.auto.choice.mix`) against the whole scene's rel-L2 budget (in the
    frame camera's image when known, else at the probes; errors with their sampling
    margin), compared with each single candidate that also fits the budget by the
    modelled time of a relit frame of the whole scene
    (:func:`core.methods.auto.choice.assignment_seconds`); the fastest wins."""
    measured, on_camera = camera_weighted(state, measured, target)
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
                                candidate_label(*cand), cand))
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
    scene_rel = rel_error(sum(o[3] for o in chosen), total_ref2)
    margin = rel_error(sum(o[2] for o in chosen), total_ref2) - scene_rel
    where = "in the camera's image" if on_camera else "at the probes"
    sampled = f" ± {margin:.2%} sampled" if margin > 0 else ""
    if best == "mix":
        why = (f"fastest mix within {limit:.2%} of the whole scene {where} "
               f"({scene_rel:.2%}{sampled})")
        if timed:
            why += (f"; {timed['mix'] * 1e3:.2f} ms per relit frame (modelled), faster "
                    "than " + ", ".join(f"{candidate_label(*k)} {v * 1e3:.2f} ms"
                                        for k, v in timed.items() if k != "mix"))
    else:
        why = (f"one method for the whole scene is fastest ({timed[best] * 1e3:.2f} ms "
               f"per relit frame (modelled), {scene_rel:.2%}{sampled} {where}; the "
               f"per-object mix {timed['mix'] * 1e3:.2f} ms)")
    out = []
    for m, o in zip(measured, chosen):
        a = o[0]
        error = rel_error(o[3], m["ref_norm2"])
        out.append(dict(object=m["object"], method=a[0], setting=a[1], value=a[2],
                        choice=candidate_label(*a), error=error,
                        margin=max(rel_error(o[2], m["ref_norm2"]) - error, 0.0),
                        seconds=o[1], points=m["points"], sampled=m["sample"].size,
                        reason="; ".join(m["notes"] + [why])))
    return out
