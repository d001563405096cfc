"""SSDF_SG's stored data: one object's PCA SSDF as loaded or derived (:class:`StoredField`)
and its blob ``ssdf_sg`` in the .blend (:mod:`..storage`: mean, eigen-images, per-point
coefficients and the settings they were made with)."""

from __future__ import annotations

import numpy as np

from ....core.methods.ssdf_sg import ssdf, shading as ssdf_sg
from ...frame import keys
from ...blender import storage

#: name of the stored blob (addon.blender.storage): one object's PCA SSDF and how it was made
BLOB = "ssdf_sg"


class StoredField:
    """One object's PCA SSDF as loaded/derived: numpy evaluator + raw arrays for the GPU."""

    def __init__(self, basis_mean, eigen, coeffs, resolution, rms, precompute_id="",
                 occlusion_kept=1.0):
        self.mean = np.asarray(basis_mean, np.float32)
        self.eigen = np.asarray(eigen, np.float32)
        self.coefficients = np.asarray(coeffs, np.float32)
        self.resolution = int(resolution)
        self.rms = float(rms)
        self.occlusion_kept = float(occlusion_kept)   # see core.methods.ssdf_sg.ssdf.SSDFBasis
        self.precompute_id = precompute_id
        self.numpy = ssdf_sg.PCAField(self.mean, self.eigen, self.coefficients, self.resolution)

    @property
    def terms(self):
        return len(self.eigen)


def open_field(points, resolution):
    """The SSDF of a fully open hemisphere for every point (objects without visibility
    data): the elevation ``asin(z)`` of each texel (distance to the horizon), no PCA terms."""
    mean = np.arcsin(np.clip(ssdf.square_centres(resolution)[..., 2], 0.0, 1.0)).reshape(-1)
    D = resolution * resolution
    return StoredField(mean, np.zeros((4, D), np.float32), np.zeros((points, 4), np.float32),
                       resolution, 0.0)


def field_from(result):
    basis, coeffs = result
    return StoredField(basis.mean, basis.eigen, coeffs, basis.resolution, basis.rms_error,
                       occlusion_kept=basis.occlusion_kept)


def write_field(ob, basis, coeffs, cube_resolution):
    """Store the PCA SSDF of one object (float32, as it is drawn) with its settings."""
    storage.put(ob, BLOB, storage.pack(
        {"mean": np.asarray(basis.mean, np.float32).ravel(),
         "eigen": np.asarray(basis.eigen, np.float32),
         "coeffs": np.asarray(coeffs, np.float32)},
        {"ssdf_resolution": int(basis.resolution), "budget": float(basis.budget),
         "rms": float(basis.rms_error), "occlusion_kept": float(basis.occlusion_kept),
         "occlusion_target": float(basis.occlusion_target),
         "cube_resolution": int(cube_resolution)}))


def _stored_field(arrays, meta):
    """(meta, StoredField) of a stored ``ssdf_sg`` blob."""
    try:
        mean, eigen, coeffs = arrays["mean"], arrays["eigen"], arrays["coeffs"]
        res = int(meta["ssdf_resolution"])
        rms, kept = float(meta["rms"]), float(meta["occlusion_kept"])
    except (KeyError, TypeError, ValueError):
        raise storage.Unreadable("SSDF data incomplete") from None
    D = res * res
    if mean.shape != (D,) or eigen.ndim != 2 or eigen.shape[1] != D or \
            coeffs.ndim != 2 or coeffs.shape[1] != len(eigen):
        raise storage.Unreadable("SSDF data inconsistent")
    if not (np.isfinite(mean).all() and np.isfinite(eigen).all() and np.isfinite(coeffs).all()):
        raise storage.Unreadable("SSDF data not finite")
    return meta, StoredField(mean, eigen, coeffs, res, rms, occlusion_kept=kept)


# fields read from the .blend per stored blob (storage.key)
_READ_CACHE = keys.cache(16)


def read_field(ob, points, cube_resolution, resolution, budget, max_terms,
               occlusion_target=0.0, note=None):
    """The stored StoredField of ``ob``, or None when missing or made otherwise (other
    settings, point count or cube); ``note`` is told why stored data is unreadable."""
    got = storage.load(ob, BLOB, _READ_CACHE, _stored_field, note)
    if got is None:
        return None
    meta, field = got
    try:
        made = (int(meta["cube_resolution"]), float(meta["budget"]),
                float(meta["occlusion_target"]))
    except (KeyError, TypeError, ValueError):
        return None
    if (len(field.coefficients) != points or field.resolution != resolution
            or made[0] != cube_resolution or abs(made[1] - budget) > 1e-9
            or field.terms > max(max_terms, 4) + 3 or abs(made[2] - occlusion_target) > 1e-9):
        return None
    field.precompute_id = ob.prt.precompute_id          # the run its blob belongs to
    return field
