"""The add-on's modules import each other without a cycle (no Blender: the sources are
parsed, function-level imports included)."""

import ast


def _modules(root):
    mods = {}
    for path in (root / "addon").rglob("*.py"):
        parts = list(path.relative_to(root).with_suffix("").parts)
        if parts[-1] == "__init__":
            parts = parts[:-1]
        mods[".".join(parts)] = path
    return mods


def import_graph(root) -> dict:
    """``{module: {modules it imports}}`` for the package ``addon`` under ``root``: every
    relative ``from ... import ...`` anywhere in a module (module level or inside a
    function).  ``from . import x`` depends on the submodule ``x`` when there is one, on
    the package itself for any other name; a package is not counted as depending on
    its submodules through Python importing a parent before its child."""
    mods = _modules(root)
    graph = {}
    for name, path in mods.items():
        base = name.split(".") if path.name == "__init__.py" else name.split(".")[:-1]
        deps = set()
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            if isinstance(node, ast.Import):
                assert not any(a.name.startswith(("prt_relight", "addon")) for a in node.names)
            if not isinstance(node, ast.ImportFrom) or not node.level:
                continue
            target = ".".join(base[:len(base) - node.level + 1]
                              + (node.module.split(".") if node.module else []))
            if not target.startswith("addon"):
                continue                    # ..core: the numerics never import the add-on
            subs = {f"{target}.{a.name}" for a in node.names} & set(mods)
            deps |= subs
            if len(subs) < len(node.names):
                deps.add(target)
        deps.discard(name)
        graph[name] = deps
    return graph


def find_cycle(graph):
    """One cycle of ``graph`` as a list of modules (first == last), or None."""
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

    for u in sorted(graph):
        if u not in state:
            found = visit(u)
            if found:
                return found
    return None


def test_find_cycle_finds_one():
    assert find_cycle({"a": {"b"}, "b": {"c"}, "c": {"a"}}) == ["a", "b", "c", "a"]
    assert find_cycle({"a": {"b"}, "b": set(), "c": {"a", "b"}}) is None


def test_addon_has_no_import_cycle(repo_root):
    graph = import_graph(repo_root)
    assert "addon.runtime" in graph and "addon.methods.ssdf_sg" in graph
    # the method modules' imports seen (a function-level one too)
    assert "addon.methods" in graph["addon.methods.rsl"]
    assert find_cycle(graph) is None


def test_core_never_imports_the_addon(repo_root):
    for path in (repo_root / "core").rglob("*.py"):
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            names = ([a.name for a in node.names] if isinstance(node, ast.Import) else
                     [node.module or ""] if isinstance(node, ast.ImportFrom) else [])
            assert not any(n.split(".")[0] in ("bpy", "gpu", "mathutils", "addon")
                           for n in names), path
            if isinstance(node, ast.ImportFrom) and node.level >= 2:
                raise AssertionError(f"{path}: imports outside core")
