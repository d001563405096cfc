# SPDX-License-Identifier: GPL-3.0-or-later
"""prt_relight: all-frequency precomputed radiance transfer for Blender.

The package root only wires registration.  ``core`` is pure numpy and can be
imported without Blender; ``addon`` holds everything that touches ``bpy``.
"""


def register():
    from .addon import register as _register
    _register()


def unregister():
    from .addon import unregister as _unregister
    _unregister()
