# SPDX-License-Identifier: GPL-3.0-or-later
"""Speed-against-error reports (``prt.report``) on held-out scenes.

    .venv/bin/python bench/report.py [--scenes demo spot_courtyard teapot_forest
                                               suzanne_sunrise_glossy]
                                     [--resolution 200x150] [--cuts 32] [--repeats 3] [--cycles]
                                     [--stability] [--out out/report] [--docs]

Writes out/report/<scene>/index.html (images, error maps, plot, tables) and prints, per
scene, every method/budget's per-frame time and rel-L2 against REFERENCE, then the AUTO
check: AUTO's error against REFERENCE and its time against the fastest single
fixed method that also meets the target (relit frames of the two interleaved, same run).  ``--docs``
copies the demo scene's images that docs/report.md shows into docs/images/report/.
"""

from __future__ import annotations

import argparse
import pathlib
import re
import shutil
import sys
import time

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))
import scenes  # noqa: E402

MESHES = scenes.ROOT.parent / "shared/data/meshes"


def _diffuse(ob, name, colour):
    scenes.add_bsdf_material(ob, name, "ShaderNodeBsdfDiffuse", Color=colour)


def _glossy(ob, name, colour, roughness):
    """Cycles Glossy BSDF, Beckmann (the glossy material of the SSDF_SG and BLOCKS benches)."""
    scenes.add_bsdf_material(ob, name, "ShaderNodeBsdfGlossy", distribution="BECKMANN",
                             Color=colour, Roughness=roughness)


def build(name: str, cuts: int):
    """The held-out scenes: a mesh from /work/shared/data/meshes on a diffuse grid."""
    scenes.reset()
    if name == "demo":
        scenes.add_world("sunset", rotation_z=0.6)
        ground = scenes.add_ground(cuts=cuts)
        ob = scenes.add_suzanne(subdiv=1)
    elif name == "spot_courtyard":
        scenes.add_world("courtyard", rotation_z=1.2)
        ground = scenes.add_ground(cuts=cuts)
        ob = scenes.add_obj(MESHES / "spot.obj", height=1.4)
    elif name == "teapot_forest":
        scenes.add_world("forest", rotation_z=-0.4)
        ground = scenes.add_ground(cuts=cuts)
        ob = scenes.add_obj(MESHES / "teapot.obj", height=1.2)
    elif name == "suzanne_sunrise_glossy":
        scenes.add_world("sunrise", rotation_z=2.0)
        ground = scenes.add_ground(cuts=cuts)
        ob = scenes.add_obj(MESHES / "suzanne.obj", height=1.2)
    else:
        raise SystemExit(f"unknown scene {name}")
    _diffuse(ground, "Ground", (0.8, 0.8, 0.8, 1.0))
    if name.endswith("_glossy"):
        _glossy(ob, "Object", (0.9, 0.7, 0.5, 1.0), 0.3)
    else:
        _diffuse(ob, "Object", (0.75, 0.55, 0.4, 1.0))
    scenes.add_camera()
    return ob


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--scenes", nargs="+",
                   default=["demo", "spot_courtyard", "teapot_forest", "suzanne_sunrise_glossy"])
    p.add_argument("--resolution", default="200x150")
    p.add_argument("--cuts", type=int, default=32, help="ground grid subdivisions")
    p.add_argument("--repeats", type=int, default=3)
    p.add_argument("--target", type=float, default=0.02, help="AUTO error target")
    p.add_argument("--cycles", action="store_true", help="also compare with Cycles")
    p.add_argument("--cycles-samples", type=int, default=64)
    p.add_argument("--stability", action="store_true",
                   help="add the stability table (to the first scene's report)")
    p.add_argument("--methods", nargs="+", default=None,
                   help="method ids to report (default: every registered method)")
    p.add_argument("--budgets", type=int, default=None,
                   help="budget values per method (evenly spread; default: every value)")
    p.add_argument("--out", type=pathlib.Path, default=scenes.ROOT / "out/report")
    p.add_argument("--docs", action="store_true",
                   help="copy the demo report into docs/images/report/")
    args = p.parse_args(argv)
    w, h = (int(v) for v in args.resolution.lower().split("x"))
    import bpy
    scenes.load_addon()
    from prt_relight.addon.benchmark import sweep

    summary = []
    for name in args.scenes:
        build(name, args.cuts)
        scene = bpy.context.scene
        scene.render.resolution_x, scene.render.resolution_y = w, h
        scene.render.resolution_percentage = 100
        scene.prt.auto_error_target = args.target
        t0 = time.perf_counter()
        run = sweep.ReportRun(scene, args.out / name, repeats=args.repeats,
                                     include_cycles=args.cycles,
                                     cycles_samples=args.cycles_samples,
                                     stability=args.stability and name == args.scenes[0],
                                     budgets_per_method=args.budgets,
                                     method_ids=args.methods,
                                     title=f"PRT report: {name}")
        for step in run.steps():
            print(f"  [{time.perf_counter() - t0:6.1f} s] {name}: {step}", flush=True)
        index = run.index
        seconds = time.perf_counter() - t0
        print(f"\n== {name}: {index} ({seconds:.0f} s)")
        for r in run.rows:
            cyc = (f"  vs Cycles {100 * r['error_cycles']:6.2f} %"
                   if r.get("error_cycles") is not None else "")
            print(f"  {r['method']:10s} {r['budget']:22s} {1e3 * r['frame_seconds']:9.2f} ms"
                  f"  rel-L2 {100 * r.get('error_ref', float('nan')):7.3f} %{cyc}")
        for a in run.auto_rows:
            print(f"  AUTO {a['object']}: {a['choice']} ({a['reason']})")
        check = run.auto_check
        if check:
            ok = check["auto_error"] <= args.target
            ratio = check["ratio"]
            line = (f"{name}: AUTO {100 * check['auto_error']:.2f} % in "
                    f"{1e3 * check['auto_seconds']:.2f} ms; fastest fixed method within "
                    f"{args.target:.0%}: {check['fixed']} ({100 * check['fixed_error']:.2f} %) "
                    f"{1e3 * check['fixed_seconds']:.2f} ms (medians of {check['rounds']} "
                    f"interleaved relit frames) -> AUTO {'meets' if ok else 'MISSES'} the "
                    f"target, {ratio:.2f}x {'faster' if ratio > 1 else 'SLOWER'}"
                    f" (fixed candidates timed: {'; '.join(check.get('candidates', []))})")
            summary.append(line)
        if run.report.get("stability"):
            bad = [(c["name"], m) for c in run.report["stability"]["cases"]
                   for m, cell in c["cells"].items() if not cell["finite"]]
            summary.append(f"{name}: stability cells non-finite: {bad or 'none'}")
            over = [(c["name"], m) for c in run.report["stability"]["cases"]
                    for m, cell in c["cells"].items() if cell.get("within") is False]
            summary.append(f"{name}: stability cells above their bound: {over or 'none'}")
        if args.docs and name == "demo":
            dst = scenes.ROOT / "docs/images/report"
            dst.mkdir(parents=True, exist_ok=True)
            shown = set(re.findall(r"images/report/([\w.]+)",
                                   (scenes.ROOT / "docs/report.md").read_text()))
            for f in (args.out / name).iterdir():
                if f.name in shown:                  # the images docs/report.md shows
                    shutil.copy(f, dst / f.name)
    print("\n" + "\n".join(summary))
    (args.out / "summary.txt").write_text("\n".join(summary) + "\n")


if __name__ == "__main__":
    main()
