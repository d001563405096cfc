"""addon.methods.ssdf_sg.gpu: the GPU textures SSDF_SG caches are freed before Blender's exit
handler destroys the GPU context (Python exits cleanly after per-pixel drawing)."""

from __future__ import annotations

import pytest


pytestmark = [pytest.mark.usefixtures("registered_addon"), pytest.mark.slow]


def test_python_exits_cleanly_after_per_pixel_gpu_drawing(tmp_path):
    """GPU textures cached by the per-pixel methods are freed before Blender's exit
    handler destroys the GPU context (a bpy-module script that drew SSDF_SG used to
    crash in Python's final garbage collection: exit code 139)."""
    import pathlib
    import subprocess
    import sys
    bench = pathlib.Path(__file__).resolve().parents[4] / "bench"
    script = tmp_path / "draw_and_exit.py"
    script.write_text(
        "import sys\n"
        f"sys.path.insert(0, {str(bench)!r})\n"
        "import scenes, bpy\n"
        "scenes.reset(); scenes.add_world('sunset'); scenes.add_ground(cuts=4)\n"
        "scenes.add_suzanne(subdiv=0); scenes.add_camera()\n"
        "sc = bpy.context.scene\n"
        "sc.render.resolution_x, sc.render.resolution_y = 40, 30\n"
        "from prt_relight.addon import report\n"
        "run = report.ReportRun(sc, sys.argv[1], repeats=1,\n"
        "                       method_ids={'REFERENCE', 'SSDF_SG'}, budgets_per_method=1)\n"
        "run.run()\n"
        "print('drawn', flush=True)\n")
    proc = subprocess.run([sys.executable, str(script), str(tmp_path / "rep")],
                          capture_output=True, text=True, timeout=600)
    assert "drawn" in proc.stdout, proc.stderr[-2000:]
    assert proc.returncode == 0, proc.stderr[-2000:]
