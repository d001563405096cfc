"""RSL's GLSL pass (shaders/rsl_vertex_*.glsl) against core.methods.rsl.shading in numpy."""

from __future__ import annotations

import numpy as np
import pytest

from prt_relight.core.shading import materials
from prt_relight.core.sphere import directions, envmap
from prt_relight.core.methods.rsl import shading as rsl
from prt_relight.core.scene import distance_tables
from prt_relight.core.methods.rsl import square_lights  # noqa: E402

from ..core.methods.rsl.scenes import occluded_grid as _scene, sky_with_sun as _sky_with_sun  # noqa: E402


bpy = pytest.importorskip("bpy")

from ..viewport import gpu_context  # noqa: E402

CUBE = directions.cubemap(32)


@pytest.mark.slow
@pytest.mark.parametrize("kind", ["VDT", "SAT"])
def test_glsl_pass_equals_numpy(registered_addon, kind, monkeypatch):
    from prt_relight.addon.methods.rsl import shading as method
    gpu_context()
    pos, nrm, bits = _scene(8)
    maps = distance_tables.visibility_maps(bits, nrm, CUBE, 32)
    table = distance_tables.visibility_distance_table(maps) if kind == "VDT" else distance_tables.visibility_sat(maps)
    table = table.astype(method.held_dtype(kind))      # as drawn: a VDT in half floats
    lighting = envmap.WorldLighting(image=_sky_with_sun()).to_cubemap(32)
    R = envmap.euler_xyz_matrix(0.1, 0.2, 0.7)
    ev = rsl.Evaluator(square_lights.decompose(lighting, CUBE, 40), R)
    eye = np.array([2.0, -3.0, 2.0])
    views = eye[None, :] - pos
    views /= np.linalg.norm(views, axis=1, keepdims=True)
    from prt_relight.addon.frame.engine import in_render
    sel = np.arange(1, len(nrm), 2)                      # a subset: tables by index
    mats = (materials.Material(), materials.principled_material(metallic=0.3, roughness=0.4),
            materials.Material(specular_color=(0.9, 0.5, 0.2), roughness=0.3,
                          distribution="BECKMANN", fresnel="SCHLICK"))

    tables = [rsl.brdf_tables(mat) for mat in mats]
    which = np.arange(len(sel)) % len(mats)              # every material in one pass
    weights = [rsl.point_weights(mat, nrm[sel], views[sel]) for mat in mats]
    stacked = np.zeros((len(sel), max(map(len, weights)), 3))
    for m, w in enumerate(weights):
        stacked[which == m, :len(w)] = np.stack(w, axis=1)[which == m]

    def passes(_depsgraph):
        """The GLSL pass, inside a render (the gpu module's context in -b: drawing outside
        one may corrupt it for later passes)."""
        # textures of 7 points each: several batches, a table's texels cross rows
        batches = method.vis_textures(table, batch=7)
        assert len(batches) == -(-len(nrm) // 7)
        got = np.zeros((len(sel), 3))
        for a, e, tex in batches:
            part = np.nonzero((sel >= a) & (sel < e))[0]
            i = sel[part]
            got[part] = method.gpu_shade(ev.centres, ev.half[0], ev.energy, tables,
                                         which[part], nrm[i], views[i], stacked[part], kind,
                                         tex, 32, i - a)
        return got

    # five blocks to a row of the tables' texture: the materials' blocks wrap across rows
    monkeypatch.setattr(method, "_max_texture_size", lambda: 5 * (tables[0].resolution + 2))
    got = in_render(bpy.context.scene, passes)
    for m, mat in enumerate(mats):
        V, C = ev.diffuse_factors(nrm, kind, table, tables[m])
        want = ev.shade(mat, tables[m], nrm, views, V, C)[sel][which == m]
        assert np.isfinite(got).all()
        # float32 textures and arithmetic against float64: SAT differences keep ~1e-4
        np.testing.assert_allclose(got[which == m], want, rtol=1e-3,
                                   atol=1e-4 * np.abs(want).max())
