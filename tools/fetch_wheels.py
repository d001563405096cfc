#!/usr/bin/env python3
# SPDX-License-Identifier: GPL-3.0-or-later
"""Download exactly the wheels that ``blender_manifest.toml`` lists.

The manifest's ``wheels = [...]`` entries are the single source of truth.  For
each entry the wheel filename is parsed (name, version, python/abi/platform
tags) and ``pip download --no-deps --only-binary=:all: --platform ...`` is run
for that exact combination.  Files already present are skipped.

Fails (non-zero exit) when:
- pip cannot provide a listed wheel, or provides a file with a different name
  (i.e. the manifest and what the index publishes disagree);
- a listed wheel path is not under ``./wheels/``;
- ``wheels/`` contains ``*.whl`` files the manifest does not list (these would
  silently go stale; pass ``--prune`` to delete them);
- a present wheel is not a readable zip archive.

Usage: python tools/fetch_wheels.py [--root DIR] [--prune] [--check]
  --check  only verify, never download (exit 1 if anything is missing).
"""
from __future__ import annotations

import argparse
import os
import re
import shutil
import subprocess
import sys
import tempfile
import zipfile
from pathlib import Path

try:
    import tomllib
except ModuleNotFoundError:  # Python < 3.11
    sys.exit("fetch_wheels.py needs Python >= 3.11 (tomllib)")

WHEEL_DIR = "wheels"

# name-version(-build)?-python-abi-platform.whl  (PEP 427)
_WHEEL_RE = re.compile(
    r"^(?P<name>[^-]+)-(?P<version>[^-]+)(?:-(?P<build>\d[^-]*))?"
    r"-(?P<py>[^-]+)-(?P<abi>[^-]+)-(?P<plat>[^-]+)\.whl$"
)


def die(msg: str) -> "NoReturn":  # type: ignore[name-defined]  # noqa: F821
    print(f"fetch_wheels: ERROR: {msg}", file=sys.stderr)
    sys.exit(1)


def manifest_wheels(root: Path) -> list[str]:
    manifest = root / "blender_manifest.toml"
    if not manifest.is_file():
        die(f"{manifest} not found")
    with manifest.open("rb") as fh:
        data = tomllib.load(fh)
    wheels = data.get("wheels", [])
    if not isinstance(wheels, list) or not all(isinstance(w, str) for w in wheels):
        die("manifest 'wheels' must be a list of strings")
    names = []
    for entry in wheels:
        if not re.fullmatch(rf"\./{WHEEL_DIR}/[^/\\]+\.whl", entry):
            die(f"manifest wheel {entry!r} must be of the form './{WHEEL_DIR}/<file>.whl'")
        names.append(entry.rsplit("/", 1)[1])
    if len(set(names)) != len(names):
        die("manifest lists a wheel more than once")
    return names


def pip_args_for(filename: str) -> list[str]:
    m = _WHEEL_RE.match(filename)
    if not m:
        die(f"not a valid wheel filename: {filename!r}")
    name, version = m["name"], m["version"]
    py_tags = m["py"].split(".")
    abi_tags = m["abi"].split(".")
    plat_tags = m["plat"].split(".")
    cp = [t for t in py_tags if re.fullmatch(r"cp\d{2,3}", t)]
    if len(cp) != 1:
        die(f"{filename}: expected exactly one cpXY python tag, got {py_tags}")
    digits = cp[0][2:]
    pyver = f"{digits[0]}.{digits[1:]}"
    args = [
        f"{name}=={version}",
        "--no-deps",
        "--only-binary=:all:",
        "--implementation", "cp",
        "--python-version", pyver,
    ]
    for abi in abi_tags:
        args += ["--abi", abi]
    for plat in plat_tags:
        args += ["--platform", plat]
    return args


def check_zip(path: Path) -> None:
    try:
        with zipfile.ZipFile(path) as zf:
            if not any(n.endswith(".dist-info/WHEEL") for n in zf.namelist()):
                die(f"{path} has no .dist-info/WHEEL (corrupt download?)")
    except zipfile.BadZipFile:
        die(f"{path} is not a valid zip (delete it and re-run)")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--root", type=Path, default=Path(__file__).resolve().parents[1])
    ap.add_argument("--prune", action="store_true", help="delete *.whl in wheels/ the manifest does not list")
    ap.add_argument("--check", action="store_true", help="verify only; do not download")
    ns = ap.parse_args(argv)

    root: Path = ns.root.resolve()
    wanted = manifest_wheels(root)
    wheel_dir = root / WHEEL_DIR
    wheel_dir.mkdir(exist_ok=True)

    extra = sorted(p.name for p in wheel_dir.glob("*.whl") if p.name not in wanted)
    if extra:
        if ns.prune:
            for name in extra:
                print(f"fetch_wheels: removing unlisted {name}")
                (wheel_dir / name).unlink()
        else:
            die("wheels/ holds wheels the manifest does not list (re-run with --prune): " + ", ".join(extra))

    missing = [w for w in wanted if not (wheel_dir / w).is_file()]
    for w in wanted:
        if w not in missing:
            check_zip(wheel_dir / w)
    if ns.check:
        if missing:
            die("missing wheels: " + ", ".join(missing))
        print(f"fetch_wheels: all {len(wanted)} wheels present")
        return 0

    for filename in missing:
        args = pip_args_for(filename)
        print(f"fetch_wheels: downloading {filename}", flush=True)
        with tempfile.TemporaryDirectory(prefix="fetch_wheels_", dir=wheel_dir) as tmp:
            cmd = [sys.executable, "-m", "pip", "download", "--disable-pip-version-check",
                   "--quiet", "-d", tmp, *args]
            proc = subprocess.run(cmd)
            if proc.returncode != 0:
                die(f"pip download failed for {filename} (cmd: {' '.join(cmd)})")
            got = sorted(os.listdir(tmp))
            if got != [filename]:
                die(f"manifest wants {filename} but pip downloaded {got}; "
                    "update the manifest 'wheels' list to the published filename")
            check_zip(Path(tmp) / filename)
            shutil.move(os.path.join(tmp, filename), wheel_dir / filename)

    # Final agreement check: wheels/ must now be exactly the manifest's list.
    present = sorted(p.name for p in wheel_dir.glob("*.whl"))
    if present != sorted(wanted):
        die(f"wheels/ {present} disagrees with manifest {sorted(wanted)}")
    print(f"fetch_wheels: {len(wanted)} wheels OK ({len(missing)} downloaded) in {wheel_dir}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
