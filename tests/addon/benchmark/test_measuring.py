"""addon.benchmark.measuring: the PNG the report writes (OpenImageIO, or Blender's image API
where it is missing) holds the pixels given, and the error heatmap's ramp."""

from __future__ import annotations

import numpy as np
import pytest

from prt_relight.addon.benchmark import measuring
from prt_relight.core.report import metrics as core_report


# ----------------------------------------------------------------------------- core

def _read_png(path) -> np.ndarray:
    """The 8-bit pixels of a PNG, top row first, alpha as stored (OpenImageIO)."""
    import OpenImageIO as oiio
    config = oiio.ImageSpec()
    config.attribute("oiio:UnassociatedAlpha", 1)
    inp = oiio.ImageInput.open(str(path), config)
    try:
        return np.asarray(inp.read_image(oiio.UINT8))
    finally:
        inp.close()


@pytest.mark.parametrize("channels", [3, 4])
def test_png_round_trip_and_heatmap_ramp(tmp_path, channels):
    """The PNG written (OpenImageIO, and Blender's image API where it is missing) holds the
    pixels given, alpha unpremultiplied."""
    rng = np.random.default_rng(3)
    rgb = rng.integers(0, 256, (5, 11, channels), dtype=np.uint8)
    core_report.write_png(tmp_path / "a.png", rgb)
    np.testing.assert_array_equal(_read_png(tmp_path / "a.png"), rgb)
    saved = core_report.oiio
    try:
        core_report.oiio = None
        measuring.write_png(tmp_path / "b.png", rgb)
    finally:
        core_report.oiio = saved
    np.testing.assert_array_equal(_read_png(tmp_path / "b.png"), rgb)
    heat = core_report.heatmap_rgb(np.array([[0.0, 0.1, 0.2, 5.0, np.nan]]), 0.2)
    assert tuple(heat[0, 0]) == (0, 0, 5)                        # ramp start
    assert tuple(heat[0, 2]) == tuple(heat[0, 3])                # saturates at vmax
    assert tuple(heat[0, 4]) == (0, 255, 0)                      # non-finite stands out
    assert heat[0, 1].sum() < heat[0, 2].sum()
