"""The scene fuzzer's check of one seed: build the scene (``generator.build``), precompute
(``prt.precompute``) and render F12 with the PRT Relight engine, then judge it.

A scene passes when nothing crashed (no Python exception escapes the operator or the
render engine, whose exceptions Blender would only print), every refusal is a clear
message (no traceback) that leaves the scene's stored data and datablocks as they were,
the Combined pass is finite and non-negative at the render size, and the scene kept within
``MAX_SECONDS`` and ``MAX_PEAK_MB``."""

from __future__ import annotations

import dataclasses
import pathlib
import resource
import time

import bpy
import numpy as np

from prt_relight.addon.blender import storage
from prt_relight.bench import scenes

from . import generator

#: a scene (build, precompute, F12) takes 2 s (median) to 40 s on this 2-core machine; the
#: slowest, a subdivided, mirrored Suzanne of 62k shading points under AUTO (which measures
#: every method), 61 s beside other work: twice that means a scene went wrong
#: (docs/measurements.md, "Scene fuzzer")
MAX_SECONDS = 120.0
#: resident memory a scene may add at its peak over what the process held before it
#: (Blender and the add-on loaded, ~300 MB): a clean scene adds at most 1.02 GB, of which
#: ~0.4 GB is the first F12's GPU context (llvmpipe); a dynamic object's shadows read all
#: at once added 1.4-1.5 GB
MAX_PEAK_MB = 1280.0


@dataclasses.dataclass
class Outcome:
    seed: int
    notes: list
    failures: list = dataclasses.field(default_factory=list)
    refusals: list = dataclasses.field(default_factory=list)
    warnings: list = dataclasses.field(default_factory=list)
    seconds: float = 0.0
    peak_mb: float = 0.0

    @property
    def ok(self) -> bool:
        return not self.failures


def stored_blobs() -> dict:
    """Every object's stored blobs by name: what a refused precompute must leave alone."""
    out = {}
    for ob in bpy.data.objects:
        store = ob.get(storage.STORE)
        out[ob.name] = {} if store is None else {n: bytes(store[n]["blob"]) for n in store.keys()}
    return out


def datablock_counts() -> dict:
    counts = {kind: len(getattr(bpy.data, kind)) for kind in
              ("objects", "meshes", "materials", "worlds", "collections", "lights")}
    counts["images"] = sum(i.type != "RENDER_RESULT" for i in bpy.data.images)
    return counts


def is_clear(message: str) -> bool:
    """A refusal an artist can act on: a sentence of ours, not a Python traceback."""
    return bool(message.strip()) and "Traceback" not in message


# ------------------------------------------------------------------ memory

def _status_kb(field: str) -> float | None:
    try:
        for line in pathlib.Path("/proc/self/status").read_text().splitlines():
            if line.startswith(field + ":"):
                return float(line.split()[1])
    except OSError:
        pass
    return None


def _reset_peak() -> bool:
    """Reset the kernel's peak resident size of this process (Linux); False where not."""
    try:
        pathlib.Path("/proc/self/clear_refs").write_text("5")
        return True
    except OSError:
        return False


class _Memory:
    """Peak resident memory a stretch of work adds over the process's size at its start
    (VmHWM after a reset; elsewhere ru_maxrss, an upper bound)."""

    def __enter__(self):
        self.exact = _reset_peak()
        self.start_kb = _status_kb("VmRSS") or 0.0
        return self

    def __exit__(self, *exc):
        peak = _status_kb("VmHWM") if self.exact else None
        if peak is None:
            peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
        self.added_mb = max(peak - self.start_kb, 0.0) / 1024.0
        return False


# ------------------------------------------------------------------ the engine's errors

def _engine_class():
    return next(c for c in bpy.types.RenderEngine.__subclasses__()
                if getattr(c, "bl_idname", "") == "PRT_RELIGHT")


class _EngineWatch:
    """Records what the engine's ``render`` raises (Blender prints it and returns
    FINISHED) and what it reports, while the ``with`` block runs."""

    def __enter__(self):
        cls = self.cls = _engine_class()
        self.raised, self.reports, self.ran = [], [], False
        self.render = cls.render
        watch = self

        def render(engine, depsgraph):
            watch.ran = True
            try:
                return watch.render(engine, depsgraph)
            except BaseException as exc:
                import traceback
                watch.raised.append("".join(traceback.format_exception(exc)))
                raise

        def report(engine, kind, message):
            # RenderEngine.report is Blender's, found on the instance once ours is gone
            watch.reports.append((set(kind), message))
            del cls.report
            try:
                return engine.report(kind, message)
            finally:
                cls.report = report

        cls.render, cls.report = render, report
        return self

    def __exit__(self, *exc):
        self.cls.render = self.render
        del self.cls.report
        return False


# ------------------------------------------------------------------ one seed

def _precompute(out: Outcome):
    scene = bpy.context.scene
    before, counts, run_id = stored_blobs(), datablock_counts(), scene.prt.precompute_id
    try:
        result = bpy.ops.prt.precompute()
    except RuntimeError as exc:
        message = str(exc)
        if not is_clear(message):
            out.failures.append(f"precompute crashed:\n{message}")
            return
        out.refusals.append(f"precompute: {message.strip()}")
        if stored_blobs() != before or datablock_counts() != counts \
                or scene.prt.precompute_id != run_id:
            out.failures.append(f"precompute refused ({message.strip()}) but changed the scene")
        return
    if result != {"FINISHED"}:
        out.failures.append(f"precompute returned {result} without a message")


def _render(out: Outcome, path: pathlib.Path):
    scene = bpy.context.scene
    with _EngineWatch() as watch:
        try:
            scenes.render([path], transparent=scene.render.film_transparent)
            refused = None
        except RuntimeError as exc:
            refused = str(exc)
    out.warnings += [m for kind, m in watch.reports if "WARNING" in kind]
    if watch.raised:
        out.failures.append("F12 crashed:\n" + "\n".join(watch.raised))
        return
    if refused is not None:
        if not is_clear(refused):
            out.failures.append(f"F12 failed:\n{refused}")
            return
        out.refusals.append(f"F12: {refused.strip()}")
        if not watch.ran:                  # refused by Blender (no camera): no frame
            return
        # our engine draws on after some errors (a World it cannot read lights as black)
        scenes.save_render(path)
    errors = [m for kind, m in watch.reports if "ERROR" in kind]
    frame = scenes.read_exr(path)
    r = scene.render
    want = (r.resolution_y * r.resolution_percentage // 100,
            r.resolution_x * r.resolution_percentage // 100, 4)
    if frame.shape != want:
        out.failures.append(f"F12 frame is {frame.shape}, not {want}")
        return
    if not np.isfinite(frame).all():
        out.failures.append(f"F12 frame has {int((~np.isfinite(frame)).sum())} non-finite "
                            f"values" + (f" (engine said: {errors})" if errors else ""))
    elif frame.min() < 0.0:
        out.failures.append(f"F12 frame has negative values (min {frame.min():.3g})")
    if refused is None:
        out.refusals += [f"F12 error: {m}" for m in errors]


def run(seed: int, workdir) -> Outcome:
    """Build, precompute and render scene ``seed`` in this process (the add-on
    registered); the F12 frame is written into ``workdir``."""
    t0 = time.perf_counter()
    with _Memory() as memory:
        out = Outcome(seed, generator.build(seed))
        _precompute(out)
        if not any(f.startswith("precompute crashed") for f in out.failures):
            _render(out, pathlib.Path(workdir) / f"fuzz_{seed}.exr")
    out.seconds = time.perf_counter() - t0
    out.peak_mb = memory.added_mb
    if out.seconds > MAX_SECONDS:
        out.failures.append(f"took {out.seconds:.1f} s (bound {MAX_SECONDS:.0f} s)")
    if out.peak_mb > MAX_PEAK_MB:
        out.failures.append(f"added {out.peak_mb:.0f} MB at its peak (bound {MAX_PEAK_MB:.0f} MB)")
    return out


def describe(out: Outcome) -> str:
    """The seed's verdict, what it built and what went wrong, for a log."""
    head = (f"seed {out.seed}: {'ok' if out.ok else 'FAIL'} in {out.seconds:.1f} s, "
            f"+{out.peak_mb:.0f} MB")
    lines = [head] + [f"  | {n}" for n in out.notes]
    lines += [f"  refused: {r}" for r in out.refusals]
    lines += [f"  FAILURE: {f}" for f in out.failures]
    return "\n".join(lines)
