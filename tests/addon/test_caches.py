"""The add-on's caches: every module-level cache is a core.common.cache.Cache (bounded,
listed), and unregister empties every one of them."""

import ast
import importlib
import pkgutil
import sys

from prt_relight.core.common import cache as core_cache


#: module-level dicts that are state, not caches (or outside this check)
NOT_CACHES = {
    "addon.methods.REGISTRY",              # the registered methods
    "addon.methods.blocks.shading.LAST_STATS",     # statistics of the newest BLOCKS frame
}


def _all_modules():
    names = []
    for pkg in ("prt_relight.core", "prt_relight.addon"):
        mod = importlib.import_module(pkg)
        names.append(pkg)
        names += [m.name for m in pkgutil.walk_packages(mod.__path__, pkg + ".")]
    return [importlib.import_module(n) for n in names]


def _empty_dicts(path):
    """Module-level names bound to an empty dict (``X = {}``, ``X: dict = {}``, ``dict()``)."""
    out = []
    for node in ast.parse(path.read_text()).body:
        targets = (node.targets if isinstance(node, ast.Assign)
                   else [node.target] if isinstance(node, ast.AnnAssign) else [])
        value = getattr(node, "value", None)
        empty = (isinstance(value, ast.Dict) and not value.keys) or (
            isinstance(value, ast.Call) and getattr(value.func, "id", "") == "dict"
            and not value.args and not value.keywords)
        out += [t.id for t in targets if empty and isinstance(t, ast.Name)]
    return out


def test_every_module_level_cache_is_listed(repo_root):
    """No module keeps a plain dict between calls: each is a core.common.cache.Cache (bounded,
    locked, listed) -- or named in NOT_CACHES with the reason."""
    plain = []
    for folder in ("core", "addon"):
        for path in sorted((repo_root / folder).rglob("*.py")):
            short = ".".join(path.relative_to(repo_root).with_suffix("").parts)
            short = short.removesuffix(".__init__")
            plain += [f"{short}.{n}" for n in _empty_dicts(path)
                      if f"{short}.{n}" not in NOT_CACHES]
    assert plain == []
    modules = _all_modules()        # import them all first: a cache lists itself when made
    listed = {id(c) for c in core_cache.CACHES}
    for mod in modules:
        for value in vars(mod).values():
            if isinstance(value, core_cache.Cache):
                assert id(value) in listed and value.limit >= 1


def test_unregister_empties_every_cache(registered_addon):
    """Fill every listed cache (and draw a frame, which fills the memoised tables), then
    unregister: nothing is left, GPU or not."""
    from prt_relight.addon.frame import keys
    from prt_relight.core.sphere import directions
    directions.cubemap(8)
    for c in core_cache.CACHES:
        if isinstance(c, core_cache.Cache):
            c["probe"] = ((), "value")
    assert all(len(c) for c in core_cache.CACHES if isinstance(c, core_cache.Cache))
    registered_addon.unregister()
    try:
        left = [repr(c) for c in core_cache.CACHES if len(c)]
        assert left == []
    finally:
        registered_addon.register()       # the fixture unregisters at the end
    assert keys.free is not None
    assert sys.modules["prt_relight.addon.frame.keys"] is keys
