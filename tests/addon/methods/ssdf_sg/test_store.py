"""addon.methods.ssdf_sg.store: what SSDF_SG stores and reads per object (needs the add-on's
modules, hence Blender)."""

from __future__ import annotations

import numpy as np

from prt_relight.addon.methods.ssdf_sg import shading as method, store as stored
from prt_relight.core.methods.ssdf_sg import ssdf
from prt_relight.core.sphere import directions


def _unit(v):
    v = np.asarray(v, dtype=np.float64)
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def test_open_field_equals_computed_open_ssdf():
    """Objects without visibility data get the closed-form open SSDF; it matches the SSDF
    computed from fully visible cubemap bits."""
    cube = directions.cubemap(16)
    normals = _unit([[0.2, 0.1, 1.0], [-1.0, 0.3, 0.0]])
    bits = np.packbits(np.ones((2, cube.size), bool), axis=1)
    computed = ssdf.compute_ssdf(bits, normals, cube, method.method_grid(8))
    field = stored.open_field(2, 8)
    assert np.allclose(field.numpy.images[0][None, :], computed, atol=1e-5)
