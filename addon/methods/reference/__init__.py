"""REFERENCE (Inger, Farbman, Lischinski 2013, eq. 1): the pixel-basis triple product over
every cubemap texel, the yardstick every other method is measured against."""

from .. import register
from ..contract import Method
from .shading import ReferenceShading
from .settings import ReferenceSettings

METHOD = register(Method(
    'REFERENCE', 'Reference',
    ('Pixel-basis triple product over every cubemap texel (exact for the cubemap; '
                 'slowest)'),
    shading=ReferenceShading(),
    settings=ReferenceSettings()))
