"""The scene and helpers the AUTO tests share: Suzanne on a ground under a sky with a sun,
a frame state synced for it, fewer candidates to measure (faster), what is stored."""

from __future__ import annotations

import json

import bpy
import numpy as np

from prt_relight.addon.frame import state as runtime
from prt_relight.addon.methods.auto import measure
from prt_relight.addon.methods.auto import measure as auto_measure
from prt_relight.bench import scenes


def auto_sky(width=64, height=32):
    """A small environment: a sky gradient and a soft bright lobe (cheap to resample,
    so relit timings in the selection stay fast)."""
    v = (np.arange(height) + 0.5) / height
    u = (np.arange(width) + 0.5) / width
    theta, phi = np.meshgrid(np.pi * v, 2 * np.pi * (0.5 - u), indexing="ij")
    d = np.stack([np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi), np.cos(theta)], -1)
    lobe = np.exp((d @ np.array([0.48, -0.36, 0.8]) - 1.0) / 0.05)
    sky = 0.2 + 0.4 * np.clip(d[..., 2], 0, 1)
    rgb = sky[..., None] * np.array([0.6, 0.8, 1.0]) + 8.0 * lobe[..., None]
    return rgb.astype(np.float32)


def auto_scene(method="REFERENCE", rotation_z=0.0):
    """Ground and Suzanne under :func:`auto_sky`, precomputed with ``method``."""
    scenes.reset()
    scenes.add_world(image=scenes.float_image("sky", auto_sky()), rotation_z=rotation_z)
    scenes.add_ground(size=6.0, cuts=8)
    scenes.add_suzanne(subdiv=0, location=(0.0, 0.0, 1.0))
    diffuse = scenes.bsdf_material("Diffuse", "ShaderNodeBsdfDiffuse", Color=(0.7, 0.6, 0.5, 1.0))
    for ob in bpy.data.objects:
        if ob.type == "MESH":
            ob.data.materials.append(diffuse)
    scenes.add_camera(location=(0.0, -6.0, 3.0), rotation=(1.15, 0.0, 0.0), resolution=None)
    scenes.set_resolution(64, 48)
    bpy.context.scene.prt.method = method
    assert bpy.ops.prt.precompute() == {"FINISHED"}


def synced_state(method, **settings):
    """A frame state of the scene drawn with ``method`` and its ``settings``."""
    scene = bpy.context.scene
    scene.prt.method = method
    for k, v in settings.items():
        setattr(scene.prt, k, v)
    state = runtime.FrameState()
    state.sync(bpy.context.evaluated_depsgraph_get())
    return state


def fewer_candidates(monkeypatch):
    """SH and WAVELET budgets only: the selection logic is the same, the test faster."""
    every = measure.candidates
    monkeypatch.setattr(auto_measure, "candidates",
        lambda: [c for c in every() if c[0].id in ("SH", "WAVELET")])


def stored_choice():
    """AUTO's choice as stored in the scene."""
    return json.loads(bpy.context.scene.prt.auto_choice)
