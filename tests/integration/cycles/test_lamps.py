"""SG lamps (core.sg.lamp_lobes) against Cycles: a white Lambert plane under one lamp, Cycles'
pixels against albedo/pi times the SG lamp's irradiance: slow."""

import math

import numpy as np
import pytest

from prt_relight.core.sg import lamp_lobes
from prt_relight.bench import scenes

from ...cases.lights import add_light, lamp_scene


# --------------------------------------------------------------------------- lamps

def _sg_irradiance(axis, lam, mu, n):
    """int G max(0, n.i) di by quadrature on a cap around the axis (handles lam up to 1e5)."""
    t = np.cross(axis, [0.0, 0.0, 1.0] if abs(axis[2]) < 0.9 else [1.0, 0.0, 0.0])
    t /= np.linalg.norm(t)
    b = np.cross(axis, t)
    tmax = math.acos(max(1.0 - 40.0 / lam, -1.0))
    x, w = np.polynomial.legendre.leggauss(96)
    edges = np.linspace(0, tmax, 5)
    th = np.concatenate([(edges[i] + edges[i + 1]) / 2 + (edges[i + 1] - edges[i]) / 2 * x for i in range(4)])
    wt = np.concatenate([(edges[i + 1] - edges[i]) / 2 * w for i in range(4)]) * np.sin(th)
    ph = (np.arange(128) + 0.5) * 2 * math.pi / 128
    d = (np.sin(th)[:, None, None] * (np.cos(ph)[None, :, None] * t + np.sin(ph)[None, :, None] * b)
         + np.cos(th)[:, None, None] * axis)
    g = np.exp(-lam * 2 * np.sin(th / 2) ** 2)[:, None] * np.maximum(d @ n, 0)
    return mu * np.sum(g * wt[:, None]) * (2 * math.pi / 128)


# --------------------------------------------------------------------------- Blender lamps

@pytest.mark.slow
@pytest.mark.usefixtures("registered_addon")
@pytest.mark.parametrize("kind", ["POINT", "SUN", "SPOT"])
def test_lamp_sg_units_match_cycles(kind, tmp_path):
    """A white Lambert plane under one lamp: Cycles' pixels vs albedo/pi * (SG lamp (x)
    cosine), the cosine integral done by quadrature -- checks the power/strength units."""
    import bpy

    from prt_relight.addon.blender import scene_export


    lamp_scene()
    if kind == "POINT":
        add_light("POINT", (0.4, -0.3, 1.5), energy=60.0, shadow_soft_size=0.05)
    elif kind == "SUN":
        add_light("SUN", rotation=(0.5, 0.2, 0.0), energy=2.0, angle=0.05)
    else:
        add_light("SPOT", (0.0, 0.0, 1.5), rotation=(0.2, 0.0, 0.0), energy=80.0,
                   spot_size=1.2, spot_blend=1.0, shadow_soft_size=0.05)  # edge wider than a pixel
    lamps = scene_export.export_lamps(bpy.context.evaluated_depsgraph_get())
    img = scenes.render_exr(tmp_path / "lamp.exr", engine="CYCLES", samples=16)
    h, w = img.shape[:2]
    # pixel centres on the plane (top row first: +y at the top)
    xs = -1.0 + (np.arange(w) + 0.5) * 2.0 / w
    ys = 1.0 - (np.arange(h) + 0.5) * 2.0 / h
    X, Y = np.meshgrid(xs, ys)
    pos = np.stack([X.ravel(), Y.ravel(), 0 * X.ravel()], 1)
    axes, lam, mu = lamp_lobes.lamp_sgs(lamps, pos)
    n = np.array([0.0, 0.0, 1.0])
    E = np.array([_sg_irradiance(axes[p, 0], lam[p, 0], mu[p, 0, 0], n) for p in range(len(pos))])
    ours = (0.8 / math.pi * E).reshape(h, w)
    cyc = img[..., :3].mean(axis=2)
    err = np.linalg.norm(ours - cyc) / np.linalg.norm(cyc)
    print(f"{kind}: Cycles vs SG lamp on a Lambert plane: rel L2 {err:.4f}, "
          f"mean ratio {ours.mean() / cyc.mean():.4f}")
    assert err <= 0.04
