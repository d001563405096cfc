# SPDX-License-Identifier: GPL-3.0-or-later
"""Shared pytest configuration for prt_relight.

The repository root *is* the extension package, but the checkout directory may
be named anything (``main``, a CI clone dir, ...).  Register it under the
package name ``prt_relight`` so tests can ``import prt_relight.core...``.
"""
import importlib.util
import pathlib
import sys

import pytest

ROOT = pathlib.Path(__file__).resolve().parents[1]

if "prt_relight" not in sys.modules:
    _spec = importlib.util.spec_from_file_location(
        "prt_relight", ROOT / "__init__.py", submodule_search_locations=[str(ROOT)]
    )
    _mod = importlib.util.module_from_spec(_spec)
    sys.modules["prt_relight"] = _mod
    _spec.loader.exec_module(_mod)


def pytest_configure(config):
    config.addinivalue_line(
        "markers", "slow: Cycles/GPU comparisons; still run by make test"
    )


@pytest.fixture(scope="session")
def repo_root() -> pathlib.Path:
    """Absolute path of the repository root (== the extension source dir)."""
    return ROOT


@pytest.fixture(scope="module")
def registered_addon():
    """The add-on registered in this process (Blender as a module) for one test module."""
    addon = sys.modules["prt_relight"]
    addon.register()
    yield addon
    addon.unregister()
