"""SH (Sloan, Kautz, Snyder 2002): diffuse shadowed transfer in spherical harmonics."""

from .. import register
from ..contract import Method
from .shading import SHShading
from .settings import SHSettings
from .bench import SHBench

METHOD = register(Method(
    'SH', 'Spherical Harmonics',
    ('Diffuse shadowed transfer in spherical harmonics (Sloan et al. 2002): low '
                 'frequency, fastest; draws the diffuse part of materials only'),
    shading=SHShading(),
    settings=SHSettings(),
    bench=SHBench()))
