#!/usr/bin/env python3
"""The house rules anyone can check from the repo (``make lint``; tests/test_house.py runs
the same checks): no Python file over 600 lines, no folder with more than 15 modules, no
private name imported across modules, no import cycle, core free of Blender.

Standard library only (it runs before the venv exists).  Exit status 1 lists what breaks.
"""

from __future__ import annotations

import ast
import pathlib
import sys

ROOT = pathlib.Path(__file__).resolve().parents[1]
#: folders of Python the rules cover (the package, its tests, benches and tools)
TREES = ("core", "addon", "tests", "bench", "tools")
MAX_LINES = 600
MAX_MODULES = 15
#: what core/ may never import: Blender's modules and the add-on
BLENDER = ("bpy", "gpu", "mathutils", "bmesh", "bl_math", "blf", "addon")


def python_files(root: pathlib.Path = ROOT) -> list[pathlib.Path]:
    files = [root / "__init__.py"] if (root / "__init__.py").exists() else []
    for top in TREES:
        files += sorted(p for p in (root / top).rglob("*.py") if "__pycache__" not in p.parts)
    return files


def package_modules(root: pathlib.Path = ROOT) -> dict[str, pathlib.Path]:
    """``{dotted name: path}`` of the extension's modules (``core...``, ``addon...``)."""
    mods = {}
    for top in ("core", "addon"):
        for p in (root / top).rglob("*.py"):
            parts = list(p.relative_to(root).with_suffix("").parts)
            if parts[-1] == "__init__":
                parts = parts[:-1]
            mods[".".join(parts)] = p
    return mods


def long_files(root: pathlib.Path = ROOT, limit: int = MAX_LINES) -> list[str]:
    out = []
    for p in python_files(root):
        n = len(p.read_text().splitlines())
        if n > limit:
            out.append(f"{p.relative_to(root)}: {n} lines (at most {limit})")
    return out


def crowded_folders(root: pathlib.Path = ROOT, limit: int = MAX_MODULES) -> list[str]:
    """Folders holding more than ``limit`` modules (``__init__.py`` not counted)."""
    out = []
    folders = {p.parent for p in python_files(root)}
    for d in sorted(folders):
        n = sum(1 for p in d.glob("*.py") if p.name != "__init__.py")
        if n > limit:
            out.append(f"{d.relative_to(root) if d != root else '.'}: {n} modules (at most {limit})")
    return out


def _resolve(mod: str, is_pkg: bool, node: ast.ImportFrom) -> str:
    """Absolute dotted target of a relative ``from`` import in module ``mod``."""
    base = mod.split(".") if is_pkg else mod.split(".")[:-1]
    if node.level > 1:
        base = base[:len(base) - node.level + 1]
    return ".".join(base + (node.module.split(".") if node.module else []))


def imports(root: pathlib.Path = ROOT):
    """``(module, path, node, target, names)`` for every relative import of the package:
    ``target`` the module or package imported from, ``names`` the imported names."""
    for mod, path in package_modules(root).items():
        is_pkg = path.name == "__init__.py"
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            if isinstance(node, ast.ImportFrom) and node.level:
                yield mod, path, node, _resolve(mod, is_pkg, node), [a.name for a in node.names]


def private_imports(root: pathlib.Path = ROOT) -> list[str]:
    """``from x import _name`` across modules, and ``alias._name`` on an imported module of
    the package (tests, benches and tools included, through ``prt_relight.``)."""
    mods = package_modules(root)
    out = []
    for p in python_files(root):
        tree = ast.parse(p.read_text(), str(p))
        rel = p.relative_to(root)
        parts = list(rel.with_suffix("").parts)
        is_pkg = parts[-1] == "__init__"
        mod = ".".join(parts[:-1] if is_pkg else parts)
        aliases = {}                    # local name -> our module it binds
        for node in ast.walk(tree):
            target = None
            if isinstance(node, ast.ImportFrom):
                if node.level and parts[0] in ("core", "addon"):
                    target = _resolve(mod, is_pkg, node)
                elif node.module and node.module.startswith("prt_relight"):
                    target = node.module[len("prt_relight."):]
            if target is None:
                continue
            for a in node.names:
                sub = f"{target}.{a.name}" if target else a.name
                if sub in mods:
                    aliases[a.asname or a.name] = sub
                elif a.name.startswith("_") and not a.name.startswith("__"):
                    out.append(f"{rel}:{node.lineno}: imports {target}.{a.name}")
        for node in ast.walk(tree):
            if isinstance(node, ast.Attribute) and isinstance(node.value, ast.Name) \
                    and node.value.id in aliases and node.attr.startswith("_") \
                    and not node.attr.startswith("__"):
                out.append(f"{rel}:{node.lineno}: uses {aliases[node.value.id]}.{node.attr}")
    return out


def import_graph(root: pathlib.Path = ROOT) -> dict[str, set]:
    """``{module: modules it imports}`` over the package (function-level imports too).
    ``from . import x`` depends on the submodule ``x`` when there is one, on the package
    for any other name; a package does not depend on its submodules by containing them."""
    mods = package_modules(root)
    graph = {m: set() for m in mods}
    for mod, _path, _node, target, names in imports(root):
        subs = {f"{target}.{n}" for n in names} & set(mods)
        graph[mod] |= subs
        if len(subs) < len(names) and target in mods:
            graph[mod].add(target)
        graph[mod].discard(mod)
    return graph


def find_cycle(graph: dict) -> list | None:
    """One cycle of ``graph`` as a list of nodes (first == last), or None."""
    state, path = {}, []

    def visit(u):
        state[u] = "open"
        path.append(u)
        for v in sorted(graph.get(u, ())):
            if state.get(v) == "open":
                return path[path.index(v):] + [v]
            if v not in state:
                found = visit(v)
                if found:
                    return found
        path.pop()
        state[u] = "done"
        return None

    sys.setrecursionlimit(max(sys.getrecursionlimit(), 10000))
    for u in sorted(graph):
        if u not in state:
            found = visit(u)
            if found:
                return found
    return None


def import_cycles(root: pathlib.Path = ROOT) -> list[str]:
    cycle = find_cycle(import_graph(root))
    return [] if cycle is None else ["import cycle: " + " -> ".join(cycle)]


def core_blender_imports(root: pathlib.Path = ROOT) -> list[str]:
    """Imports of Blender's modules or of the add-on anywhere in core/."""
    out = []
    for p in sorted((root / "core").rglob("*.py")):
        rel = p.relative_to(root)
        depth = len(rel.parts) - 1              # packages between the root and the file
        for node in ast.walk(ast.parse(p.read_text(), str(p))):
            if isinstance(node, ast.Import):
                names = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom):
                if node.level > depth:           # climbs out of core/
                    out.append(f"{rel}:{node.lineno}: imports outside core")
                    continue
                names = [node.module or ""]
            else:
                continue
            bad = [n for n in names if n.split(".")[0] in BLENDER]
            if bad:
                out.append(f"{rel}:{node.lineno}: imports {', '.join(bad)}")
    return out


CHECKS = {
    f"files over {MAX_LINES} lines": long_files,
    f"folders over {MAX_MODULES} modules": crowded_folders,
    "private names used across modules": private_imports,
    "import cycles": import_cycles,
    "core importing Blender or the add-on": core_blender_imports,
}


def main() -> int:
    failed = 0
    for title, check in CHECKS.items():
        found = check()
        if found:
            failed += 1
            print(f"{title}:")
            for line in found:
                print("  " + line)
    if not failed:
        print(f"lint: {len(CHECKS)} checks passed ({len(python_files())} files)")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
