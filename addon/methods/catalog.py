"""Every shading method of the add-on, registered in the order of the UI enum (imported
by ``addon/ui/properties.py``, which builds ``scene.prt.method`` from the registry)."""

from . import reference, sh, wavelet  # noqa: F401
from . import ssdf_sg  # noqa: F401
from . import rsl  # noqa: F401
from . import blocks  # noqa: F401
from . import auto  # noqa: F401  (last: AUTO chooses among the methods above)
