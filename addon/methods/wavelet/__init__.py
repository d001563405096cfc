"""WAVELET (Ng, Ramamoorthi, Hanrahan 2003 / 2004): Haar wavelets on the cube faces, non-linear
lighting approximation and triple products."""

from .. import register
from ..contract import Method
from .shading import WaveletShading
from .settings import WaveletSettings
from .bench import WaveletBench

METHOD = register(Method(
    'WAVELET', 'Haar Wavelets',
    ("Haar wavelets on the cube faces: the lighting's N largest terms for diffuse "
                 'transfer (Ng et al. 2003), a triple product keeping a fraction of the lighting '
                 'and BRDF coefficients for glossy materials (Ng et al. 2004)'),
    shading=WaveletShading(),
    settings=WaveletSettings(),
    bench=WaveletBench()))
