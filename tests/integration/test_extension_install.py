# SPDX-License-Identifier: GPL-3.0-or-later
"""Package the extension with Blender's own builder and install it like a user.

* ``blender_ext.py validate`` / ``build --split-platforms`` (shipped inside the
  bpy wheel) must accept the manifest and produce a linux-x64 zip;
* the zip holds the add-on sources and exactly the linux embreex wheels, and
  none of the dev-only trees (tests/, docs/, bench/, tools/, ...);
* a fresh Blender (``import bpy`` in a subprocess whose BLENDER_USER_RESOURCES
  and HOME point at a temp dir) installs it with
  ``bpy.ops.extensions.package_install_files(enable_on_install=True)``; the
  add-on must register its scene properties, render engine and operators, and
  the bundled embreex wheel must be installed into Blender's extension
  site-packages and be the copy that ``import embreex`` resolves to.

The test venv has its own embreex (for core/ unit tests), which would shadow
the extension's copy: Blender appends ``<user>/extensions/.local/lib/pythonX.Y/
site-packages`` to the *end* of sys.path.  The install script therefore puts a
meta-path finder in front that resolves ``embreex`` only from that directory
(emulating a stock Blender whose Python has no embreex), so the add-on and the
checks below can only succeed with the wheel shipped in the zip.
"""
from __future__ import annotations

import importlib.util
import json
import os
import re
import subprocess
import sys
import tomllib
import zipfile
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
MANIFEST = ROOT / "blender_manifest.toml"
PLATFORM = "linux-x64"               # manifest platform name
LINUX_WHEEL_RE = re.compile(r"manylinux[^-]*_x86_64\.whl$")

# Top-level entries that must never be shipped.
FORBIDDEN_PREFIXES = (
    "tests/", "docs/", "bench/", "tools/", ".ci/", ".venv/", "dist/", "out/",
    ".git", ".pytest_cache/", "Makefile", "requirements.txt",
)


def _manifest() -> dict:
    with MANIFEST.open("rb") as fh:
        return tomllib.load(fh)


def _blender_ext_cli() -> Path:
    spec = importlib.util.find_spec("bpy")   # locates the wheel without importing it
    if spec is None or not spec.submodule_search_locations:
        pytest.fail("bpy is not installed in this interpreter (run `make setup`)")
    bpy_dir = Path(next(iter(spec.submodule_search_locations)))
    hits = sorted(bpy_dir.glob("*/scripts/addons_core/bl_pkg/cli/blender_ext.py"))
    if not hits:
        pytest.fail(f"blender_ext.py not found under {bpy_dir}")
    return hits[-1]


def _run(cmd: list, **kw) -> subprocess.CompletedProcess:
    proc = subprocess.run([str(c) for c in cmd], capture_output=True, text=True, **kw)
    if proc.returncode != 0:
        pytest.fail(
            f"command failed ({proc.returncode}): {' '.join(map(str, cmd))}\n"
            f"--- stdout ---\n{proc.stdout}\n--- stderr ---\n{proc.stderr}"
        )
    return proc


def _manifest_wheels_for_linux() -> list[str]:
    return sorted(w for w in _manifest().get("wheels", []) if LINUX_WHEEL_RE.search(w))


@pytest.fixture(scope="module")
def blender_ext() -> Path:
    return _blender_ext_cli()


@pytest.fixture(scope="module")
def linux_zip(blender_ext, tmp_path_factory) -> Path:
    """Fresh ``build --split-platforms`` of the working tree; returns the linux-x64 zip."""
    missing = [w for w in _manifest().get("wheels", []) if not (ROOT / w).is_file()]
    if missing:
        pytest.fail("wheels missing (run `make wheels`): " + ", ".join(missing))
    out = tmp_path_factory.mktemp("dist")
    _run([sys.executable, blender_ext, "build", "--source-dir", ROOT,
          "--output-dir", out, "--split-platforms"])
    m = _manifest()
    zip_path = out / f"{m['id']}-{m['version']}-{PLATFORM.replace('-', '_')}.zip"
    assert zip_path.is_file(), f"expected {zip_path.name}, got {sorted(p.name for p in out.iterdir())}"
    return zip_path


@pytest.fixture(scope="module")
def zip_names(linux_zip) -> list[str]:
    with zipfile.ZipFile(linux_zip) as zf:
        return zf.namelist()


# --------------------------------------------------------------------------
# Manifest / build
# --------------------------------------------------------------------------

def test_manifest_fields():
    m = _manifest()
    assert m["schema_version"] == "1.0.0"
    assert m["id"] == "prt_relight"
    assert m["type"] == "add-on"
    assert m["license"] == ["SPDX:GPL-3.0-or-later"]
    assert set(m["platforms"]) == {"linux-x64", "windows-x64", "macos-arm64", "macos-x64"}
    assert len(m["tagline"]) <= 64 and not m["tagline"].endswith(".")
    reason = m["permissions"]["files"]
    assert len(reason) <= 64 and not reason.endswith(".")
    wheels = m["wheels"]
    assert not any("numpy" in w.lower() for w in wheels), "numpy ships with Blender; never bundle it"
    # every platform x {cp311, cp313}
    for tag in ("cp311", "cp313"):
        for plat in (r"manylinux[^-]*_x86_64", r"win_amd64", r"macosx_\d+_\d+_arm64", r"macosx_\d+_\d+_x86_64"):
            pat = re.compile(rf"/embreex-[^-]+-{tag}-{tag}-{plat}\.whl$")
            assert sum(bool(pat.search(w)) for w in wheels) == 1, (tag, plat, wheels)


def test_validate_source(blender_ext):
    _run([sys.executable, blender_ext, "validate", ROOT])


def test_validate_built_zip(blender_ext, linux_zip):
    _run([sys.executable, blender_ext, "validate", linux_zip])


def test_zip_excludes_dev_files(zip_names):
    bad = [n for n in zip_names if n.startswith(FORBIDDEN_PREFIXES)]
    bad += [n for n in zip_names if "__pycache__/" in n or n.endswith(".pyc")]
    bad += [n for n in zip_names if n.endswith(".md") and n != "README.md"]
    assert not bad, f"dev-only files shipped in the extension zip: {bad}"


def test_zip_bundles_exactly_linux_wheels(zip_names):
    shipped = sorted("./" + n for n in zip_names if n.endswith(".whl"))
    expected = _manifest_wheels_for_linux()
    assert len(expected) == 2, expected          # cp311 + cp313
    assert shipped == expected
    assert not any("numpy" in n.lower() for n in zip_names)


def test_zip_contains_package(zip_names):
    names = set(zip_names)
    assert "__init__.py" in names
    assert "blender_manifest.toml" in names
    for d in ("core/", "addon/", "shaders/"):
        assert any(n.startswith(d) and not n.endswith("/") for n in names), f"no files under {d} in zip"


# --------------------------------------------------------------------------
# Install into a fresh Blender user profile
# --------------------------------------------------------------------------

INSTALL_SCRIPT = r'''
import importlib.machinery, json, os, sys, traceback

zip_path, out_path = sys.argv[1], sys.argv[2]
res = {"errors": []}

def err(where):
    res["errors"].append(where + ":\n" + traceback.format_exc())

try:
    import bpy
    import addon_utils

    ext_root = bpy.utils.user_resource("EXTENSIONS")
    ext_site = os.path.join(ext_root, ".local", "lib",
                            "python%d.%d" % sys.version_info[:2], "site-packages")
    res["ext_root"] = ext_root
    res["ext_site"] = ext_site

    class ExtensionOnlyEmbreex:
        """Resolve top-level ``embreex`` only from Blender's extension site-packages."""
        @staticmethod
        def find_spec(name, path=None, target=None):
            if name != "embreex":
                return None
            spec = importlib.machinery.PathFinder.find_spec(name, [ext_site])
            if spec is None:
                raise ModuleNotFoundError(
                    "No module named 'embreex' in extension site-packages " + ext_site, name=name)
            return spec

    sys.meta_path.insert(0, ExtensionOnlyEmbreex)
    sys.modules.pop("embreex", None)

    repo = next((r for r in bpy.context.preferences.extensions.repos if r.module == "user_default"), None)
    res["repo_dir"] = repo.directory if repo else None

    try:
        ret = bpy.ops.extensions.package_install_files(
            filepath=zip_path, repo="user_default", enable_on_install=True)
        res["install_return"] = sorted(ret)
    except Exception:
        err("package_install_files")

    if res["repo_dir"]:
        pkg_dir = os.path.join(res["repo_dir"], "prt_relight")
        res["pkg_dir_exists"] = os.path.isdir(pkg_dir)

    res["addons"] = list(bpy.context.preferences.addons.keys())
    res["ext_site_in_sys_path"] = ext_site in sys.path
    res["ext_site_listing"] = sorted(os.listdir(ext_site)) if os.path.isdir(ext_site) else None

    def after_enable(tag):
        out = {}
        out["scene_prt"] = hasattr(bpy.types.Scene, "prt")
        # __subclasses__() also lists classes that were unregistered but are
        # still alive; only those carrying their own bl_rna are registered.
        seen, stack = [], list(bpy.types.RenderEngine.__subclasses__())
        while stack:
            c = stack.pop()
            if "bl_rna" in c.__dict__:
                seen.append(getattr(c, "bl_idname", c.__name__))
            stack.extend(c.__subclasses__())
        out["engines"] = seen
        try:
            bpy.ops.prt.precompute.get_rna_type()
            out["precompute_op"] = True
        except Exception:
            out["precompute_op"] = False
        res[tag] = out

    after_enable("enabled")

    try:
        import embreex
        res["embreex_file"] = os.path.realpath(embreex.__file__)
        import numpy as np
        from embreex import rtcore_scene
        from embreex.mesh_construction import TriangleMesh
        scene = rtcore_scene.EmbreeScene()
        TriangleMesh(scene, np.array([[[0, 0, 0], [1, 0, 0], [0, 1, 0]]], dtype=np.float32))
        hits = scene.run(np.array([[0.2, 0.2, 1.0], [5.0, 5.0, 1.0]], dtype=np.float32),
                         np.array([[0, 0, -1.0], [0, 0, -1.0]], dtype=np.float32))
        res["embreex_hits"] = [int(h) for h in hits]
    except Exception:
        err("import embreex")

    # Disabling must cleanly unregister everything again.
    keys = [k for k in bpy.context.preferences.addons.keys() if k.endswith("prt_relight")]
    if keys:
        try:
            addon_utils.disable(keys[0], default_set=True, handle_error=None)
        except Exception:
            err("addon_utils.disable")
        res["addons_after_disable"] = list(bpy.context.preferences.addons.keys())
        after_enable("disabled")
except Exception:
    err("script")
finally:
    with open(out_path, "w") as fh:
        json.dump(res, fh, indent=2)
'''


@pytest.fixture(scope="module")
def installed(linux_zip, tmp_path_factory) -> dict:
    home = tmp_path_factory.mktemp("blender_user")
    script = home / "install_check.py"
    script.write_text(INSTALL_SCRIPT)
    out = home / "result.json"
    env = dict(os.environ)
    env.update(BLENDER_USER_RESOURCES=str(home), HOME=str(home), PYTHONNOUSERSITE="1")
    env.pop("PYTHONPATH", None)
    proc = subprocess.run([sys.executable, str(script), str(linux_zip), str(out)],
                          env=env, capture_output=True, text=True, timeout=600)
    log = f"--- rc={proc.returncode} stdout ---\n{proc.stdout[-6000:]}\n--- stderr ---\n{proc.stderr[-6000:]}"
    if not out.is_file():
        pytest.fail("install subprocess produced no result\n" + log)
    res = json.loads(out.read_text())
    res["_log"] = log
    return res


def _detail(res: dict) -> str:
    errs = "\n".join(res.get("errors", []))
    return f"\nerrors:\n{errs}\n{res.get('_log', '')}"


def test_install_succeeds(installed):
    assert installed.get("install_return") == ["FINISHED"], _detail(installed)
    assert installed.get("pkg_dir_exists"), _detail(installed)


def test_addon_enabled(installed):
    keys = [k for k in installed.get("addons", []) if k.endswith("prt_relight")]
    assert keys, f"prt_relight not enabled; addons={installed.get('addons')}" + _detail(installed)
    assert keys[0].startswith("bl_ext."), keys   # installed as an extension, not a legacy add-on


def test_addon_registers_scene_props_engine_and_ops(installed):
    en = installed.get("enabled", {})
    assert en.get("scene_prt"), "bpy.types.Scene.prt missing" + _detail(installed)
    assert "PRT_RELIGHT" in en.get("engines", []), f"engines={en.get('engines')}" + _detail(installed)
    assert en.get("precompute_op"), "bpy.ops.prt.precompute missing" + _detail(installed)


def test_bundled_embreex_wheel_installed_and_used(installed):
    site = installed.get("ext_site")
    listing = installed.get("ext_site_listing") or []
    # NB: Blender only installs the wheels of *enabled* extensions, so this also
    # fails whenever enabling the add-on failed (see test_addon_enabled).
    assert "embreex" in listing, f"embreex not installed into {site}: {listing}" + _detail(installed)
    assert "embreex-4.4.0.post1.dist-info" in listing, listing
    assert installed.get("ext_site_in_sys_path"), f"{site} not on Blender's sys.path"
    emb = installed.get("embreex_file") or ""
    assert emb.startswith(os.path.realpath(site) + os.sep), (
        f"import embreex resolved to {emb!r}, not the extension copy in {site}" + _detail(installed))
    assert installed.get("embreex_hits") == [0, -1], _detail(installed)


def test_addon_disable_unregisters(installed):
    if "disabled" not in installed:
        pytest.fail("add-on was never enabled" + _detail(installed))
    dis = installed["disabled"]
    assert not any(k.endswith("prt_relight") for k in installed.get("addons_after_disable", []))
    assert not dis["scene_prt"], "Scene.prt still registered after disable"
    assert "PRT_RELIGHT" not in dis["engines"], "render engine still registered after disable"
    assert not dis["precompute_op"], "prt.precompute still registered after disable"
    assert not [e for e in installed.get("errors", []) if e.startswith("addon_utils.disable")], _detail(installed)
