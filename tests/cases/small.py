"""The small scene the precompute, operator and engine tests share, and what it stores."""

from __future__ import annotations

import bpy

from prt_relight.addon.blender import storage
from prt_relight.bench import scenes


def stored():
    """(object, blob key) of every object's stored visibility: equal lists, same data."""
    return sorted((o.name, storage.key(o, storage.VISIBILITY)) for o in bpy.data.objects
                  if storage.has(o, storage.VISIBILITY))


def has_data(ob) -> bool:
    return storage.has(ob, storage.VISIBILITY)


def small_scene(hdri="sunset", cuts=16, subdiv=1):
    """Suzanne over a ground under ``hdri``, a 64 x 48 camera, 2 x 2 supersampling."""
    scenes.reset()
    scenes.add_world(hdri)
    scenes.add_ground(size=6.0, cuts=cuts)
    scenes.add_suzanne(subdiv=subdiv, location=(0.0, 0.0, 1.0))
    scenes.add_camera(location=(0.0, -6.0, 3.0), rotation=(1.15, 0.0, 0.0), resolution=None)
    scenes.set_resolution(64, 48)
    bpy.context.scene.prt.supersampling = 2


def save_every_method(path):
    """Precompute the scene, store every storing method's data on the same job (BLOCKS,
    RSL, SSDF_SG: each its derive/store) and save the .blend to ``path``."""
    from prt_relight.addon import methods
    from prt_relight.addon.blender import precompute
    scene = bpy.context.scene
    job = precompute.gather(bpy.context.evaluated_depsgraph_get(), scene.prt)
    job.run()
    precompute.commit(scene, job)
    for method_id in ("BLOCKS", "RSL", "SSDF_SG"):
        method = methods.get(method_id)
        job.method = method_id
        method.shading.store(scene, job, method.shading.derive(job))
    bpy.ops.wm.save_as_mainfile(filepath=str(path))
    return path

