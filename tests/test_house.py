"""The house rules of tools/lint.py (``make lint``) hold for the tree, and each check finds
what it is for in a small tree made to break it."""

import importlib.util
import pathlib

import pytest

ROOT = pathlib.Path(__file__).resolve().parents[1]
_spec = importlib.util.spec_from_file_location("house_lint", ROOT / "tools" / "lint.py")
lint = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(lint)


@pytest.mark.parametrize("title", list(lint.CHECKS))
def test_the_tree_keeps_the_house_rules(title):
    assert lint.CHECKS[title](ROOT) == []


def _tree(tmp_path, files):
    for rel, text in files.items():
        p = tmp_path / rel
        p.parent.mkdir(parents=True, exist_ok=True)
        p.write_text(text)
    return tmp_path


def test_each_check_finds_what_it_is_for(tmp_path):
    root = _tree(tmp_path, {
        "core/__init__.py": "",
        "core/a.py": "from .b import _hidden\nimport bpy\n",
        "core/b.py": "from . import a\n_hidden = 1\n",
        "core/long.py": "x = 1\n" * (lint.MAX_LINES + 1),
        "addon/__init__.py": "",
        "addon/c.py": "from ..core import b\ny = b._hidden\n",
        **{f"tests/test_{i}.py": "" for i in range(lint.MAX_MODULES + 1)},
    })
    assert lint.long_files(root) == [f"core/long.py: {lint.MAX_LINES + 1} lines (at most "
                                     f"{lint.MAX_LINES})"]
    assert lint.crowded_folders(root) == [f"tests: {lint.MAX_MODULES + 1} modules (at most "
                                          f"{lint.MAX_MODULES})"]
    assert sorted(lint.private_imports(root)) == ["addon/c.py:2: uses core.b._hidden",
                                                  "core/a.py:1: imports core.b._hidden"]
    cycles = lint.import_cycles(root)
    assert len(cycles) == 1 and set(cycles[0].split(": ")[1].split(" -> ")) == {"core.a", "core.b"}
    assert lint.core_blender_imports(root) == ["core/a.py:2: imports bpy"]


def test_find_cycle():
    assert lint.find_cycle({"a": {"b"}, "b": set(), "c": {"a", "b"}}) is None
    assert lint.find_cycle({"a": {"b"}, "b": {"c"}, "c": {"a"}}) == ["a", "b", "c", "a"]


def test_architecture_doc_lists_every_module_as_the_tree_has_it():
    spec = importlib.util.spec_from_file_location("house_architecture",
                                                  ROOT / "tools" / "architecture.py")
    arch = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(arch)
    assert arch.rendered(ROOT) == (ROOT / "docs" / "architecture.md").read_text(), \
        "docs/architecture.md is out of date: run `make docs`"


def _core_modules():
    return sorted(p.relative_to(ROOT / "core") for p in (ROOT / "core").rglob("*.py")
                  if p.name != "__init__.py" and "__pycache__" not in p.parts)


def test_every_core_module_has_a_test_file_mirroring_it():
    """core/<package>/<module>.py is tested by tests/core/<package>/test_<module>.py, and
    every test file there names a module that exists."""
    want = {rel.parent / f"test_{rel.name}" for rel in _core_modules()}
    have = {p.relative_to(ROOT / "tests" / "core")
            for p in (ROOT / "tests" / "core").rglob("test_*.py")}
    assert sorted(map(str, want - have)) == [], "core modules without a test file"
    assert sorted(map(str, have - want)) == [], "test files without a core module"


def test_tests_of_core_need_no_blender():
    """`pytest tests/core` runs without Blender: no file there imports Blender's modules or
    the add-on (not even through pytest.importorskip)."""
    import ast
    found = []
    for p in sorted((ROOT / "tests" / "core").rglob("*.py")):
        for node in ast.walk(ast.parse(p.read_text(), str(p))):
            names = []
            if isinstance(node, ast.Import):
                names = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom) and node.module and not node.level:
                names = [node.module]
            elif isinstance(node, ast.Call) and getattr(node.func, "attr", "") in (
                    "importorskip", "import_module") and node.args:
                names = [getattr(node.args[0], "value", "")]
            for name in names:
                parts = str(name).split(".")
                if parts[0] in lint.BLENDER or parts[:2] == ["prt_relight", "addon"]:
                    found.append(f"{p.relative_to(ROOT)}:{node.lineno}: {name}")
    assert found == []
