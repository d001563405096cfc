"""Shading methods: one package each (``reference/``, ``sh/``, ...), registered here.

A method package's ``__init__`` registers a :class:`.contract.Method` record -- id, label,
description and the method's three parts: its numerics (``shading.py``, a
:class:`.contract.Shading`), its settings in ``scene.prt`` (``settings.py``, a
:class:`.contract.Settings`) and what the benchmarks, the report and AUTO read of it
(``bench.py``, a :class:`.contract.Bench`); a method without settings or budgets uses the
contract's defaults.  ``scene.prt.method``, the settings, the panels and the benchmarks
are built from :data:`REGISTRY`, so adding a method touches no other glue but one import
line in :mod:`.catalog` (which loads the packages in their UI order).
"""

from __future__ import annotations

from .contract import Method

REGISTRY: dict[str, Method] = {}


def register(method: Method) -> Method:
    REGISTRY[method.id] = method
    return method


def get(method_id: str) -> Method:
    return REGISTRY.get(method_id) or REGISTRY["REFERENCE"]


def enum_items():
    return [(m.id, m.label, m.description) for m in REGISTRY.values()]


def scene_properties() -> dict:
    props = {}
    for m in REGISTRY.values():
        props.update(m.settings.scene_properties())
    return props
