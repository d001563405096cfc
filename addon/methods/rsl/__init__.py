"""RSL (Xu, Jia, Hu, Tai 2006): rotatable square lights, BRDF summed-area tables and visibility
distance tables."""

from .. import register
from ..contract import Method
from .shading import RSLShading
from .settings import RSLSettings
from .bench import RSLBench

METHOD = register(Method(
    'RSL', 'Rotatable Square Lights',
    ('Environment split into K rotatable square lights; BRDF from summed-area tables, '
                 'visibility from distance tables (Xu et al. 2006)'),
    shading=RSLShading(),
    settings=RSLSettings(),
    bench=RSLBench()))
