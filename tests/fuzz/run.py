"""The long scene fuzzer (``make fuzz``): scenes ``--seed0`` .. ``--seed0 + --n - 1``, each
in a fresh Blender process (a crash of Blender itself or a hang is a failing seed, and
the process's peak memory is the scene's own), then a summary: how many ran clean, time
and memory per scene, each failing seed with what it built and what went wrong.

A failing seed's number goes into ``REGRESSION_SEEDS`` in ``tests/fuzz/test_fuzz.py``,
which ``make test`` runs every time.  ``--one SEED`` runs one seed in this process."""

from __future__ import annotations

import argparse
import json
import os
import pathlib
import subprocess
import sys
import tempfile
import time

ROOT = pathlib.Path(__file__).resolve().parents[2]
#: a child that runs past this many times the per-scene bound is stopped: a hang
HANG_FACTOR = 3.0
MARK = "FUZZ-RESULT "


def _one(seed: int) -> int:
    """Run one seed here and print its verdict and a JSON line for the parent."""
    sys.path.insert(0, str(ROOT / "bench"))
    import scenes  # noqa: F401  (registers the checkout as the package prt_relight)
    from prt_relight.tests.fuzz import check
    scenes.load_addon()
    with tempfile.TemporaryDirectory() as tmp:
        out = check.run(seed, tmp)
    print(check.describe(out), flush=True)
    print(MARK + json.dumps({"seed": seed, "ok": out.ok, "seconds": out.seconds,
                             "peak_mb": out.peak_mb, "refusals": out.refusals,
                             "failures": out.failures, "bound_s": check.MAX_SECONDS}),
          flush=True)
    return 0 if out.ok else 1


def _child(seed: int, bound_s: float):
    """(result dict, the child's log, its peak resident MB) of one seed in a new process."""
    with tempfile.TemporaryFile("w+") as log:
        proc = subprocess.Popen([sys.executable, __file__, "--one", str(seed)],
                                stdout=log, stderr=subprocess.STDOUT, cwd=ROOT)
        t0 = time.monotonic()
        while True:
            pid, status, usage = os.wait4(proc.pid, os.WNOHANG)
            if pid:
                break
            if time.monotonic() - t0 > HANG_FACTOR * bound_s:
                proc.kill()
                pid, status, usage = os.wait4(proc.pid, 0)
                break
            time.sleep(0.05)
        proc.returncode = os.waitstatus_to_exitcode(status)
        log.seek(0)
        text = log.read()
    line = next((ln for ln in text.splitlines() if ln.startswith(MARK)), None)
    rss_mb = usage.ru_maxrss / 1024.0
    if line is None:
        why = (f"hung: stopped after {time.monotonic() - t0:.0f} s" if status == 9 or
               proc.returncode == -9 else f"the process ended with {proc.returncode} "
               "before a verdict (Blender crashed?)")
        return {"seed": seed, "ok": False, "failures": [why], "refusals": [],
                "seconds": time.monotonic() - t0, "peak_mb": float("nan")}, text, rss_mb
    return json.loads(line[len(MARK):]), text, rss_mb


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=500, help="how many seeds (default 500)")
    ap.add_argument("--seed0", type=int, default=0, help="the first seed (default 0)")
    ap.add_argument("--one", type=int, default=None, help="run this one seed here")
    ap.add_argument("--bound", type=float, default=120.0,
                    help="check.MAX_SECONDS, for the hang limit (default 120)")
    args = ap.parse_args(argv)
    if args.one is not None:
        return _one(args.one)
    results, t_start = [], time.monotonic()
    for seed in range(args.seed0, args.seed0 + args.n):
        res, text, rss_mb = _child(seed, args.bound)
        res["rss_mb"] = rss_mb
        results.append(res)
        verdict = "ok" if res["ok"] else "FAIL"
        print(f"seed {seed}: {verdict} {res['seconds']:.1f} s, scene +{res['peak_mb']:.0f} MB, "
              f"process {rss_mb:.0f} MB" + (f", refused: {res['refusals']}"
                                             if res["refusals"] else ""), flush=True)
        if not res["ok"]:                  # the child's verdict, else all it wrote
            verdict = text.find(f"seed {seed}: FAIL in")
            print(text[verdict:] if verdict >= 0 else text, flush=True)
    bad = [r["seed"] for r in results if not r["ok"]]
    secs = sorted(r["seconds"] for r in results)
    print(f"\n{len(results) - len(bad)} of {len(results)} scenes clean in "
          f"{time.monotonic() - t_start:.0f} s; per scene median {secs[len(secs) // 2]:.1f} s, "
          f"max {secs[-1]:.1f} s; peak added {max(r['peak_mb'] for r in results):.0f} MB, "
          f"process peak {max(r['rss_mb'] for r in results):.0f} MB; "
          f"{sum(bool(r['refusals']) for r in results)} with a refusal")
    if bad:
        print(f"failing seeds (add them to REGRESSION_SEEDS in tests/fuzz/test_fuzz.py): {bad}")
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
