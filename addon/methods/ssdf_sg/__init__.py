"""SSDF_SG (Wang, Ren, Gong, Snyder, Guo 2009): per-pixel shading with spherical Gaussians and
PCA-compressed SSDF visibility."""

from .. import register
from ..contract import Method
from .shading import SSDFSGShading
from .settings import SSDFSGSettings
from .bench import SSDFSGBench

METHOD = register(Method(
    'SSDF_SG', 'SSDF + Spherical Gaussians',
    ('Per-pixel all-frequency shading (Wang et al. 2009): spherical-Gaussian BRDF and '
                 'lighting, visibility as PCA-compressed signed distance fields'),
    shading=SSDFSGShading(),
    settings=SSDFSGSettings(),
    bench=SSDFSGBench()))
