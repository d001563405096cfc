"""AUTO's stored choice: what it depends on (:func:`choice_key`), its JSON record in
``scene.prt.auto_choice`` (written by :func:`write_choice`, read by :func:`parse_choice`)
and whether it is current (:func:`stored_status`).  The measurement is
``addon/methods/auto/shading.py``; its numerics ``core/methods/auto/choice.py``."""

from __future__ import annotations

import hashlib
import json
import math

import numpy as np

from ...frame.keys import cache, env_key

#: Layout of the stored choice (a record of another version is out of date).
CHOICE_VERSION = 1
# Stored choices parsed per JSON text (frames read the scene property each time).
_PARSED = cache(8)
#: (stored JSON, why it is not used or "") as the newest AUTO frame found it: the panel
#: shows whether the scene's stored choice is current.
STORED_STATUS: list = ["", ""]


def materials_key(st) -> str:
    """``repr`` of an object's materials, built once per synced object (its frames reuse
    it; part of the per-object cache key)."""
    got = st.data.get("auto_materials")
    if got is None or got[0] is not st.materials:
        got = st.data["auto_materials"] = (st.materials, repr(st.materials))
    return got[1]


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
        budgets = {m.bench.budget[0] for m, _, _ in candidates if m.bench.budget}
        names = _SETTING_NAMES[ids] = sorted(
            {n for m, _, _ in candidates for n in m.settings.scene_properties()} - budgets)
    return [(n, state.settings.get(n)) for n in names]


def choice_key(state, candidates) -> dict:
    """What a stored choice depends on, per part: the objects' names and geometry (a
    dynamic object's up to its motion: a choice holds over an animation), the
    directions of their visibility, their materials, the lighting's content and strength,
    the error target, the candidates' other settings.  The world's rotation is left out
    (the same environment turned keeps the choice, as the measurement cache does) and so
    is the camera (a stored choice does not flip as the view moves; Choose re-chooses).
    ``candidates``: :func:`.shading.candidates`."""
    env = env_key(state.world, state.resolution)
    return dict(
        geometry=_digest(sorted((st.name, st.shape) for st in state.objects)),
        directions=int(state.resolution),
        materials=_digest(sorted((st.name, materials_key(st)) for st in state.objects)),
        lighting=_digest(env[0], env[1]),
        target=float(state.settings.get("auto_error_target", 0.02)),
        settings=_digest(_candidate_settings(state, candidates)))


#: Fields of a stored per-object choice (those of ``AutoMethod.last_choices``).
CHOICE_FIELDS = ("object", "method", "setting", "value", "choice", "error", "seconds",
                 "reason")
#: Stored too when known: the error's sampling margin, the object's points, how many
#: were measured.
CHOICE_EXTRA = ("margin", "points", "sampled")


def write_choice(scene, record):
    """Store ``record`` (:meth:`AutoMethod.choice_steps`) as the scene's choice."""
    scene.prt.auto_choice = json.dumps(record, sort_keys=True)


def plain(x):
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
