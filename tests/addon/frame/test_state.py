"""The frame state (addon/frame/state.py) holds no decoded visibility: a stored object keeps
its compressed blob and decodes it through the bounded cache when read, so a scene of
more objects than the cache holds shades as one that fits (each read decodes again)."""

from __future__ import annotations

import bpy
import numpy as np
import pytest

from prt_relight.addon.frame import state as runtime
from prt_relight.bench import scenes


pytestmark = pytest.mark.usefixtures("registered_addon")

EYE = np.array([0.0, -6.0, 3.0])


def _shade():
    state = runtime.FrameState()
    state.sync(bpy.context.evaluated_depsgraph_get())
    return state, state.shade(EYE)


def test_a_frame_holds_no_decoded_visibility_and_shades_the_same_past_the_cache(monkeypatch):
    scenes.reset()
    scenes.add_world("city")
    scenes.add_ground(size=4.0, cuts=24)
    scenes.add_suzanne(subdiv=1, height=1.0, location=(-0.8, 0.0, 0.5))
    scenes.add_suzanne(subdiv=1, height=1.0, location=(0.8, 0.0, 0.5))
    bpy.context.scene.prt.method = "REFERENCE"
    assert bpy.ops.prt.precompute() == {"FINISHED"}
    state, fits = _shade()
    assert len(state.objects) == 3 and all(st.status == "ok" for st in state.objects)
    # what a state holds of a stored object is its blob, not the decoded bits
    assert all(st._bits is None and st._stored is not None for st in state.objects)
    runtime.VIS_CACHE.clear()
    monkeypatch.setattr(runtime.VIS_CACHE, "limit", 1)
    state, past = _shade()
    assert len(runtime.VIS_CACHE) <= 1
    for a, b in zip(fits, past):
        np.testing.assert_allclose(a, b, rtol=1e-6, atol=1e-9)
