"""The scene fuzzer's fast subset (``make test``; ``make fuzz`` runs 500 seeds): a few
fixed seeds covering what the generator makes, every seed that once failed, and checks
that the fuzzer itself builds the same scene from a seed and fails what it must fail."""

from __future__ import annotations

import bpy
import numpy as np
import pytest

from prt_relight.addon.blender import precompute, scene_export
from prt_relight.addon.frame import engine

from . import check, generator

pytestmark = pytest.mark.usefixtures("registered_addon")

#: a spread of the generator's scenes, about 20 s together: nested instances with
#: degenerate and flattened meshes (3), a dynamic object under 7 lamps (5), lamps of
#: every type with textures and a normal map (24, 34), tiny, mirrored and arrayed meshes
#: (21), particles with a dynamic object (28) and with nested instances, huge meshes and an
#: orthographic camera (40), a huge dynamic object (15), AUTO with particles (18); and the
#: refusals: no World (1), no camera (2), nothing with faces (9).  Every method is among them.
FAST_SEEDS = (1, 2, 3, 5, 9, 15, 18, 21, 24, 28, 34, 40)

#: seeds that once failed: seed -> (what was wrong, a line of the scene it builds: the
#: generator must still build that scene for the seed to test the fix)
#: (one seed per bug where several found it: 31, 44 and 82 take 8-25 s; make fuzz runs them)
REGRESSION_SEEDS = {
    35: ("a dynamic object scaled to 0 on an axis crashed the precompute (singular matrix)",
         "Sphere06: sphere, scale flat"),
    46: ("a dynamic object's shadow on its neighbours read 512 points x every texel at once: "
         "1.4 GB", "OpenCylinder01: open cylinder, scale uniform, modifiers ['mirror']"),
    86: ("RSL's store of an object scaled to 0 on an axis crashed inverting its matrix",
         "Monkey04: monkey, scale flat"),
}


@pytest.mark.parametrize("seed", FAST_SEEDS)
def test_fuzzed_scene_is_clean(seed, tmp_path):
    out = check.run(seed, tmp_path)
    assert out.ok, check.describe(out)


@pytest.mark.parametrize("seed", sorted(REGRESSION_SEEDS))
def test_once_failing_scene_is_clean(seed, tmp_path):
    why, line = REGRESSION_SEEDS[seed]
    out = check.run(seed, tmp_path)
    assert any(n.startswith(line) for n in out.notes), \
        f"seed {seed} no longer builds the scene that failed ({why}): {out.notes}"
    assert out.ok, f"{why}\n{check.describe(out)}"


def _scene_summary():
    return sorted((o.name, o.type, tuple(np.round(o.matrix_world, 6).ravel()),
                   [m.type for m in o.modifiers]) for o in bpy.data.objects)


def test_a_seed_builds_the_same_scene_every_time():
    notes = generator.build(5)
    summary = _scene_summary()
    assert generator.build(5) == notes and _scene_summary() == summary
    assert generator.build(6) != notes


#: a quick seed that precomputes and renders (SSDF_SG, four lamps)
QUICK = 34


def test_the_check_fails_bad_pixels_crashes_and_slowness(monkeypatch, tmp_path):
    """NaN and negative pixels (also in a frame drawn after an error), an exception in the
    engine (Blender only prints it) or in the precompute, and a scene past the time bound
    each fail the seed."""
    real = engine.render_pixels

    def poisoned(value):
        def draw(*args, **kwargs):
            pixels = np.array(real(*args, **kwargs))
            pixels[0, 0, 0] = value
            return pixels
        return draw

    for value, says in ((np.nan, "non-finite"), (-1.0, "negative")):
        monkeypatch.setattr(engine, "render_pixels", poisoned(value))
        out = check.run(QUICK, tmp_path)
        assert not out.ok and says in out.failures[0], check.describe(out)
    # a frame the engine draws on after an error (no World: lit as black) is checked too
    out = check.run(1, tmp_path)
    assert out.refusals and "negative" in out.failures[0], check.describe(out)

    def crash(*args, **kwargs):
        raise ZeroDivisionError("fuzz")

    monkeypatch.setattr(engine, "render_pixels", crash)
    monkeypatch.setattr(check, "MAX_SECONDS", 0.0)
    out = check.run(QUICK, tmp_path)
    assert "F12 crashed" in out.failures[0] and "ZeroDivisionError" in out.failures[0]
    assert "took" in out.failures[-1]
    monkeypatch.setattr(engine, "render_pixels", real)
    monkeypatch.setattr(precompute, "gather", crash)
    out = check.run(QUICK, tmp_path)
    assert "precompute crashed" in out.failures[0] and "ZeroDivisionError" in out.failures[0]


def test_a_refusal_must_leave_the_scene_as_it_was(monkeypatch, tmp_path):
    """A clear refusal is no failure; one that changed the scene before refusing is."""
    real = precompute.gather

    def refuse(depsgraph, settings):
        raise scene_export.ExportError("Refused by the test")

    def change_then_refuse(depsgraph, settings):
        bpy.data.materials.new("Left behind")
        refuse(depsgraph, settings)

    monkeypatch.setattr(precompute, "gather", refuse)
    out = check.run(QUICK, tmp_path)
    assert out.ok and out.refusals == ["precompute: Error: Refused by the test"], \
        check.describe(out)
    monkeypatch.setattr(precompute, "gather", change_then_refuse)
    out = check.run(QUICK, tmp_path)
    assert not out.ok and "changed the scene" in out.failures[0], check.describe(out)
    monkeypatch.setattr(precompute, "gather", real)
    assert check.is_clear("The scene has no World") and not check.is_clear(
        "Error: Python: Traceback (most recent call last): ...")
