#!/usr/bin/env python3
"""Writes the module map of docs/architecture.md from the tree: a line per package and
module, each the first sentence of its docstring (``make docs``; tests/test_house.py fails
when the file and the tree disagree).  Standard library only.

The map goes between the markers ``<!-- module map -->`` and ``<!-- end of module map -->``;
the rest of the page (data flow, glossary) is written by hand.
"""

from __future__ import annotations

import ast
import pathlib
import re
import sys

ROOT = pathlib.Path(__file__).resolve().parents[1]
DOC = ROOT / "docs" / "architecture.md"
BEGIN, END = "<!-- module map -->", "<!-- end of module map -->"
#: trees of the map, in the order of the data flow
TREES = ("core", "addon")


ABBREVIATIONS = ("al", "eq", "e.g", "i.e", "fig", "cf", "vs", "no", "sec", "ch")


def summary(path: pathlib.Path) -> str:
    """The first sentence of a module's docstring, on one line (a full stop ends it unless
    it closes an abbreviation such as "et al." or "eq.")."""
    doc = ast.get_docstring(ast.parse(path.read_text(), str(path))) or ""
    text = " ".join(doc.split())
    for m in re.finditer(r"\.(\s|$)", text):
        word = re.split(r"[\s(]", text[:m.start()])[-1].lower()
        if word.rstrip(".") in ABBREVIATIONS or (word and word[-1].isdigit() and
                                                  text[m.end():m.end() + 1].isdigit()):
            continue
        return text[:m.start() + 1]
    return text


def module_map(root: pathlib.Path = ROOT) -> str:
    lines = []
    for top in TREES:
        packages = sorted({p.parent for p in (root / top).rglob("*.py")
                           if "__pycache__" not in p.parts})
        for pkg in packages:
            rel = pkg.relative_to(root).as_posix()
            init = pkg / "__init__.py"
            head = summary(init) if init.exists() else ""
            lines.append(f"\n### `{rel}/`" + (f" — {head}" if head else "") + "\n")
            mods = sorted(p for p in pkg.glob("*.py") if p.name != "__init__.py")
            if not mods:
                continue
            lines.append("| module | what it holds |")
            lines.append("|---|---|")
            for p in mods:
                lines.append(f"| `{p.name}` | {summary(p) or '—'} |")
    shaders = root / "shaders"
    if shaders.exists():
        for folder in sorted({p.parent for p in shaders.rglob("*.glsl")}):
            rel = folder.relative_to(root).as_posix()
            lines.append(f"\n### `{rel}/`\n")
            lines.append("| file | what it holds |")
            lines.append("|---|---|")
            for p in sorted(folder.glob("*.glsl")):
                first = ""
                for ln in p.read_text().splitlines():
                    s = ln.strip().lstrip("/*").strip()
                    if s:
                        first = s.rstrip("*/").strip()
                        break
                lines.append(f"| `{p.name}` | {first} |")
    return "\n".join(lines).strip() + "\n"


def rendered(root: pathlib.Path = ROOT) -> str:
    """docs/architecture.md with its module map written anew from the tree."""
    text = (root / "docs" / "architecture.md").read_text()
    a, b = text.index(BEGIN) + len(BEGIN), text.index(END)
    return text[:a] + "\n" + module_map(root) + text[b:]


def main(argv) -> int:
    new = rendered()
    if "--check" in argv:
        if new != DOC.read_text():
            print("docs/architecture.md is out of date: run `make docs`")
            return 1
        return 0
    DOC.write_text(new)
    print(f"wrote {DOC.relative_to(ROOT)}")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
