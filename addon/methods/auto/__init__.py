"""AUTO: per object, the cheapest method and budget that meets the error target against
REFERENCE."""

from .. import register
from ..contract import Method
from .shading import AutoShading
from .settings import AutoSettings
from .bench import AutoBench

METHOD = register(Method(
    'AUTO', 'Auto',
    ('Per object, the cheapest method and budget that meets the error target against '
                 'REFERENCE (chosen at Precompute or Choose, stored with the scene)'),
    shading=AutoShading(),
    settings=AutoSettings(),
    bench=AutoBench()))
