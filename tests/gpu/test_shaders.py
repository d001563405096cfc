"""Every shader is built one way (addon/gpu/shaders.py): each spec's files exist, libraries
first and in the order their functions are called; what it declares is in its GLSL; no
library function is written twice; no GLSL is left in Python; every spec and variant builds
through Blender's gpu module; shaders/lib/constants.glsl is what tools/glsl_constants.py
writes from the Python constants today."""

import importlib.util
import pathlib
import re

import pytest

from prt_relight.addon.gpu import shaders

ROOT = pathlib.Path(__file__).resolve().parents[2]
LIB = shaders.SHADER_DIR / "lib"
#: a function definition at the start of a line: return type, name, "("
DEFINITION = re.compile(r"^[A-Za-z_]\w*\s+([A-Za-z_]\w*)\s*\(", re.M)
#: what a GLSL file says once its comments are gone
COMMENT = re.compile(r"/\*.*?\*/|//[^\n]*", re.S)


def _code(name: str) -> str:
    return COMMENT.sub(" ", (shaders.SHADER_DIR / name).read_text())


def _functions(name: str) -> set:
    return set(DEFINITION.findall(_code(name))) - {"main"}


def _words(text: str) -> set:
    return set(re.findall(r"[A-Za-z_]\w*", text))


def _lib_functions() -> dict:
    """{function: the lib file defining it}."""
    out = {}
    for path in sorted(LIB.glob("*.glsl")):
        for f in _functions(f"lib/{path.name}"):
            out.setdefault(f, []).append(f"lib/{path.name}")
    return out


# --------------------------------------------------------------------------- Blender-free

@pytest.mark.parametrize("name", list(shaders.SPECS))
def test_a_spec_names_files_that_declare_what_it_declares(name):
    spec = shaders.SPECS[name]
    for stage in ("vertex", "fragment"):
        files = getattr(spec, stage)
        assert files and all((shaders.SHADER_DIR / f).is_file() for f in files), files
        # libraries first (lib/ or a method's own *_lib.glsl); one main, in the last file
        assert [f for f in files if re.search(r"\bvoid\s+main\s*\(", _code(f))] == \
            [files[-1]], (stage, files)
        assert all(f.startswith("lib/") or f.endswith("_lib.glsl") for f in files[:-1]), files
    vertex = _words(COMMENT.sub(" ", shaders.source(spec, "vertex")))
    fragment = _words(COMMENT.sub(" ", shaders.source(spec, "fragment")))
    for _, ident in spec.push_constants + spec.samplers:
        assert ident in vertex | fragment, ident
    for _, ident in spec.vertex_inputs:
        assert ident in vertex, ident
    for _, _, ident in spec.varyings:
        assert ident in vertex and ident in fragment, ident
    for _, ident in spec.outputs:
        assert ident in fragment, ident
    text = shaders.source(spec, "vertex") + shaders.source(spec, "fragment")
    for ident in [n for n, _ in spec.defines] + list(spec.switches) + [n for n, _ in spec.values]:
        assert re.search(rf"#\s*if(n?def)?\b[^\n]*\b{ident}\b", text), ident


@pytest.mark.parametrize("name", list(shaders.SPECS))
def test_a_library_comes_before_the_files_that_call_it(name):
    """Every call of a lib/ function (or use of a generated constant) comes after the lib
    file that defines it, in every spec that calls it."""
    defined_in = {f: files[0] for f, files in _lib_functions().items()}
    constants = set(re.findall(r"\bconst\s+\w+\s+(\w+)", _code("lib/constants.glsl")))
    spec = shaders.SPECS[name]
    for stage in ("vertex", "fragment"):
        seen = []
        for f in getattr(spec, stage):
            used = _words(_code(f))
            for func in used & set(defined_in):
                if defined_in[func] != f:
                    assert defined_in[func] in seen, (name, f, func, defined_in[func])
            if f != "lib/constants.glsl" and used & constants:
                assert "lib/constants.glsl" in seen, (name, f)
            seen.append(f)


def test_every_glsl_file_is_built_and_no_library_function_is_written_twice():
    used = {f for spec in shaders.SPECS.values() for f in spec.vertex + spec.fragment}
    on_disk = {p.relative_to(shaders.SHADER_DIR).as_posix()
               for p in shaders.SHADER_DIR.rglob("*.glsl")}
    assert on_disk == used
    lib = _lib_functions()
    assert {f: files for f, files in lib.items() if len(files) > 1} == {}
    for f in sorted(on_disk - {f"lib/{p.name}" for p in LIB.glob("*.glsl")}):
        assert _functions(f) & set(lib) == set(), f       # a pass redefining a lib function


def test_no_glsl_is_left_in_python():
    for path in sorted((ROOT / "addon").rglob("*.py")):
        text = path.read_text()
        assert not re.search(r"gl_Position|gl_FragCoord|\btexelFetch\s*\(|void\s+main\s*\(|"
                             r"^\s*[\"']*#\s*define\s", text, re.M), path


def test_a_variant_sets_only_what_its_spec_declares():
    assert shaders.parse_defines(shaders.SPECS["lights"], ("GLOSSY", "PCF_TAPS 12")) == (
        ("GLOSSY", "1"), ("PCF_TAPS", "12"))
    for bad in (("FLAT_PAIRS",), ("GLOSSY 1",), ("PCF_TAPS",)):
        with pytest.raises(ValueError):
            shaders.parse_defines(shaders.SPECS["lights"], bad)


# --------------------------------------------------------------------------- constants

def _generator():
    spec = importlib.util.spec_from_file_location("glsl_constants",
                                                  ROOT / "tools" / "glsl_constants.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_constants_glsl_is_what_the_python_constants_make():
    gen = _generator()
    assert gen.rendered() == (LIB / "constants.glsl").read_text(), \
        "shaders/lib/constants.glsl is out of date: run `make shaders`"


def test_a_changed_python_constant_changes_constants_glsl(monkeypatch):
    from prt_relight.core.sg import ndf
    gen = _generator()
    monkeypatch.setattr(ndf, "SG_ALPHA_MIN", 0.004)
    assert "const float SG_ALPHA_MIN = 0.004;" in gen.rendered()


def test_no_generated_constant_is_written_again_by_hand():
    names = [n for n, _, _ in _generator().CONSTANTS]
    for path in sorted(shaders.SHADER_DIR.rglob("*.glsl")):
        if path.name == "constants.glsl":
            continue
        code = COMMENT.sub(" ", path.read_text())
        for n in names:
            assert not re.search(rf"(#\s*define\s+{n}\b|\bconst\s+\w+\s+{n}\b)", code), (path, n)


# --------------------------------------------------------------------------- GPU

@pytest.mark.slow
def test_every_shader_and_variant_builds():
    """Through Blender's gpu module (llvmpipe in -b: about 15 s, most of it the lights
    pass's 64 feature sets)."""
    import bpy
    import gpu

    from prt_relight.addon.gpu import drawing
    drawing.ensure_gpu(bpy.context.scene)
    for name, spec in shaders.SPECS.items():
        for defines in shaders.variants(name):
            info = shaders.create_info(spec, defines, name)
            assert gpu.shader.create_from_info(info) is not None, (name, defines)
    assert shaders.shader("surface") is shaders.shader("surface")         # built once
