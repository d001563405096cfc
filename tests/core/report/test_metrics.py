"""core.report.metrics: rel-L2 and PSNR against their definitions, the Pareto frontier
against the non-dominated set, the fastest candidates meeting a target, and the SVG plot.
No bpy."""

from __future__ import annotations

import math
import re

import numpy as np
import pytest

from prt_relight.core.report import metrics as core_report


# ----------------------------------------------------------------------------- core

def test_rel_l2_and_psnr_match_their_definitions():
    rng = np.random.default_rng(1)
    ref = rng.random((9, 7, 4)).astype(np.float32)
    ref[..., 3] = (rng.random((9, 7)) > 0.3)
    img = ref + 0.05 * rng.standard_normal(ref.shape).astype(np.float32)
    m = ref[..., 3] > 0.5
    num = sum(float(np.sum((img[i, j, :3].astype(np.float64) - ref[i, j, :3]) ** 2))
              for i in range(9) for j in range(7) if m[i, j])
    den = sum(float(np.sum(ref[i, j, :3].astype(np.float64) ** 2))
              for i in range(9) for j in range(7) if m[i, j])
    assert core_report.rel_l2(img, ref) == pytest.approx(math.sqrt(num / den), rel=1e-9)
    mse = num / (3 * m.sum())
    peak = float(ref[m][:, :3].max())
    assert core_report.psnr(img, ref) == pytest.approx(10 * math.log10(peak ** 2 / mse),
                                                       rel=1e-9)
    assert core_report.rel_l2(ref, ref) == 0.0 and core_report.psnr(ref, ref) == math.inf
    black = np.zeros_like(ref)
    black[..., 3] = 1.0
    assert core_report.rel_l2(black, black) == 0.0          # no division by zero
    bad = img.copy()
    bad[0, 0, 0] = np.nan
    bad[..., 3] = 1.0
    assert core_report.rel_l2(bad, black) == math.inf


def test_pareto_frontier_is_exactly_the_non_dominated_set():
    rng = np.random.default_rng(2)
    for _ in range(20):
        n = int(rng.integers(1, 30))
        t = rng.random(n).round(2)
        e = rng.random(n).round(2)
        front = core_report.pareto_frontier(t, e)
        dominated = {i for i in range(n) for j in range(n)
                     if t[j] <= t[i] and e[j] <= e[i] and (t[j] < t[i] or e[j] < e[i])}
        # duplicates of a frontier point: exactly one of them is kept
        expected = {i for i in range(n) if i not in dominated}
        kept = {(t[i], e[i]) for i in front}
        assert kept == {(t[i], e[i]) for i in expected}
        assert len(front) == len(kept)
        assert list(front) == sorted(front, key=lambda i: t[i])
    assert core_report.pareto_frontier([1.0, np.nan, 2.0], [0.5, 0.0, np.inf]) == [0]


def test_fastest_candidates_are_the_fast_rows_meeting_the_target():
    rows = [dict(method="A", frame_seconds=0.010, error_ref=0.03),      # misses
            dict(method="B", frame_seconds=0.020, error_ref=0.01),
            dict(method="C", frame_seconds=0.030, error_ref=0.015),
            dict(method="D", frame_seconds=0.039, error_ref=0.0),
            dict(method="E", frame_seconds=0.041, error_ref=0.0),       # > 2x the fastest
            dict(method="F", frame_seconds=0.025, error_ref=float("nan")),
            dict(method="G", frame_seconds=float("inf"), error_ref=0.0)]
    got = [r["method"] for r in core_report.fastest_candidates(rows, 0.02)]
    assert got == ["B", "C", "D"]
    assert [r["method"] for r in core_report.fastest_candidates(rows, 0.02, count=2)] == ["B", "C"]
    assert core_report.fastest_candidates(rows, 0.02)[0] is core_report.fastest_meeting(rows, 0.02)
    assert core_report.fastest_candidates(rows, -1.0) == []


def test_svg_plot_shows_every_method_and_the_frontier():
    rows = [dict(method="A", label="1", frame_seconds=0.01, error_ref=0.2),
            dict(method="A", label="2", frame_seconds=0.02, error_ref=0.1),
            dict(method="B", label="", frame_seconds=1.0, error_ref=0.0),
            dict(method="C", label="x", frame_seconds=2.0, error_ref=0.3),
            dict(method="D", label="", frame_seconds=math.nan, error_ref=None)]
    svg = core_report.speed_error_svg(rows)
    for mid in "ABC":
        assert f">{mid}<" in svg
    assert "D (no finite point)" in svg
    assert svg.count("<circle") == 4 + 4                         # 4 points, 4 legend dots
    frontier = re.search(r'<polyline points="([^"]+)"', svg).group(1).split()
    assert len(frontier) == 3                                    # C is dominated
