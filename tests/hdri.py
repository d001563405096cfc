"""Blender's bundled HDRIs without Blender: the bpy wheel's ``<bpy>/<version>/datafiles/
studiolights/world/*.exr``, found through ``importlib.util.find_spec("bpy")`` (which locates
the wheel without importing it), so Blender-free tests (tests/core) can light with them.

A test that needs one calls :func:`hdri_path`; where no bpy wheel is installed it is skipped
(the HDRIs ship only with Blender).
"""

from __future__ import annotations

import importlib.util
import pathlib

import pytest


def world_folder() -> pathlib.Path | None:
    """The folder of Blender's bundled world HDRIs, or None without a bpy wheel."""
    try:
        spec = importlib.util.find_spec("bpy")
    except (ImportError, ValueError):
        return None
    if spec is None:
        return None
    roots = list(spec.submodule_search_locations or [])
    if spec.origin:
        roots.append(str(pathlib.Path(spec.origin).parent))
    for root in roots:
        hits = sorted(pathlib.Path(root).glob("*/datafiles/studiolights/world"))
        if hits:
            return hits[-1]
    return None


def hdri_path(name: str) -> pathlib.Path:
    """The bundled HDRI ``name`` (``"forest"``, ``"sunset"``, ...); skips the calling test
    when Blender's datafiles are not installed."""
    folder = world_folder()
    path = None if folder is None else folder / f"{name}.exr"
    if path is None or not path.is_file():
        pytest.skip(f"Blender's bundled HDRI '{name}' is not installed (no bpy wheel)")
    return path
