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
def test_glsl_pass_equals_numpy(registered_addon, kind):
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

    def passes(_depsgraph):
        """The GLSL pass of every material, inside a render (the gpu module's context in
        -b: drawing outside one may corrupt it for later passes)."""
        # textures of 7 points each: several batches, a table's texels cross rows
        batches = method.vis_textures(table, batch=7)
        assert len(batches) == -(-len(nrm) // 7)
        out = []
        for mat in mats:
            got = np.zeros((len(sel), 3))
            for a, e, tex in batches:
                part = np.nonzero((sel >= a) & (sel < e))[0]
                i = sel[part]
                got[part] = method.gpu_shade(ev.centres, ev.half[0], ev.energy,
                                             rsl.brdf_tables(mat), nrm[i], views[i],
                                             rsl.point_weights(mat, nrm[i], views[i]),
                                             kind, tex, 32, i - a)
            out.append(got)
        return out

    for mat, got in zip(mats, in_render(bpy.context.scene, passes)):
        tables = rsl.brdf_tables(mat)
        V, C = ev.diffuse_factors(nrm, kind, table, tables)
        want = ev.shade(mat, tables, nrm, views, V, C)
        assert np.isfinite(got).all()
        # float32 textures and arithmetic against float64: SAT differences keep ~1e-4
        np.testing.assert_allclose(got, want[sel], rtol=1e-3, atol=1e-4 * np.abs(want).max())
