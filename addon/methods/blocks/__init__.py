"""BLOCKS (Inger, Farbman, Lischinski 2013): Algorithm 1 per 16x16 cubemap block with
differential visibility."""

from .. import register
from ..contract import Method
from .shading import BlocksShading
from .settings import BlocksSettings
from .bench import BlocksBench

METHOD = register(Method(
    'BLOCKS', 'Locally Adaptive Blocks',
    ('Inger et al. 2013: per 16x16 cubemap block, Algorithm 1 (skip / light-BRDF / '
                 'light-visibility / triple product) with differential visibility and the BRDF '
                 'sampled per view; needs 6x64x64 or finer'),
    shading=BlocksShading(),
    settings=BlocksSettings(),
    bench=BlocksBench()))
