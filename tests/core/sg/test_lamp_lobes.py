"""core.sg.lamp_lobes (Wang et al. 2009, eq. 32-33): a lamp's spherical Gaussian integrated
against the clamped cosine by quadrature gives the lamp's exact irradiance; that irradiance
against the closed form of a sphere and a disc of uniform radiance; the lobes' axes,
sharpness and integrals as eq. 32-33 define them, the spot cone as Cycles', the input
checks and area lamps' sizes.  No bpy."""

from __future__ import annotations

import math

import numpy as np
import pytest

from prt_relight.core.sg import algebra as sg, lamp_lobes
from prt_relight.core.sg.lighting import LAMP_LAMBDA_MAX


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


@pytest.mark.parametrize("lamp", [
    lamp_lobes.Lamp("POINT", color=(100.0, 80.0, 60.0), position=(0.5, -0.3, 3.0), radius=0.1),
    lamp_lobes.Lamp("POINT", color=(100.0, 100.0, 100.0), position=(0.0, 1.0, 2.0), radius=0.5),
    lamp_lobes.Lamp("POINT", color=(50.0, 50.0, 50.0), position=(0.0, 0.0, 4.0), radius=0.0),
    lamp_lobes.Lamp("SPOT", color=(200.0, 200.0, 200.0), position=(0.0, 0.0, 3.0),
                     direction=(0.0, 0.1, -1.0), radius=0.05, spot_size=math.radians(60)),
    lamp_lobes.Lamp("SUN", color=(3.0, 2.5, 2.0), direction=(-0.3, 0.2, -0.9), angle=math.radians(2.0)),
    lamp_lobes.Lamp("SUN", color=(3.0, 3.0, 3.0), direction=(0.0, 0.0, -1.0), angle=0.0),
])
def test_lamp_sg_gives_the_lamps_irradiance(lamp):
    x = np.array([[0.0, 0.0, 0.0], [0.3, 0.2, 0.0], [-0.5, 0.4, 0.1]])
    axes, lam, mu = lamp_lobes.lamp_sgs([lamp], x)
    ths = np.radians([0.0, 30.0, 60.0, 80.0])
    errs = []
    for p in range(len(x)):
        a = axes[p, 0]
        t = np.cross(a, [1.0, 0.0, 0.0])
        t /= np.linalg.norm(t)
        normals = np.cos(ths)[:, None] * a + np.sin(ths)[:, None] * t
        ref = lamp_lobes.lamp_irradiance(lamp, np.repeat(x[p:p + 1], len(ths), 0), normals)
        got = np.array([_sg_irradiance(a, lam[p, 0], mu[p, 0], nn) for nn in normals])
        errs.append(np.abs(got - ref) / np.maximum(ref[:, :1].max(), 1e-30))
    err = float(np.max(errs))
    print(f"{lamp.kind} r={lamp.radius} angle={lamp.angle}: lam {lam[:, 0].round(1)}, "
          f"max irradiance error / normal-incidence irradiance {err:.4f}")
    # measured 0.026 for a 0.5 m sphere 2 m away at 80 deg (the SG is not a disc), <1e-3 otherwise
    assert err <= 0.03


@pytest.mark.parametrize("radius, dist, tilt", [(0.1, 2.0, 0.0), (0.5, 2.0, 40.0),
                                                (0.3, 1.0, 60.0), (0.0, 3.0, 30.0)])
def test_sphere_lamp_irradiance_is_the_closed_form(radius, dist, tilt):
    """A sphere of uniform radiance whose cap is wholly above the horizon gives
    E = pi L sin^2(alpha) cos(tilt): with Cycles' E = Phi / (4 pi d^2) at normal incidence,
    Phi / (4 pi d^2) cos(tilt) -- the quadrature of lamp_irradiance against it."""
    phi = np.array([100.0, 50.0, 10.0])
    lamp = lamp_lobes.Lamp("POINT", color=phi, position=(0.0, 0.0, dist), radius=radius)
    t = math.radians(tilt)
    n = np.array([[math.sin(t), 0.0, math.cos(t)]])
    got = lamp_lobes.lamp_irradiance(lamp, np.zeros((1, 3)), n)[0]
    np.testing.assert_allclose(got, phi / (4 * math.pi * dist ** 2) * math.cos(t), rtol=1e-6)


def test_sun_irradiance_is_the_closed_form_of_its_disc():
    """The sun is a disc of radiance strength / its solid angle 2 pi (1 - cos h) (h half its
    angle): wholly above the horizon, E = pi L sin^2(h) cos(tilt) = strength (1 + cos h) / 2
    cos(tilt) -- the strength at normal incidence to 3e-4 at 4 degrees."""
    h = math.radians(2.0)
    sun = lamp_lobes.Lamp("SUN", color=(3.0, 2.0, 1.0), direction=(0.0, 0.0, -1.0), angle=2 * h)
    for tilt in (0.0, 30.0, 70.0):
        t = math.radians(tilt)
        n = np.array([[0.0, math.sin(t), math.cos(t)]])
        got = lamp_lobes.lamp_irradiance(sun, np.zeros((1, 3)), n)[0]
        want = np.array([3.0, 2.0, 1.0]) * (1.0 + math.cos(h)) / 2.0 * math.cos(t)
        np.testing.assert_allclose(got, want, rtol=1e-6)
        np.testing.assert_allclose(got, np.array([3.0, 2.0, 1.0]) * math.cos(t), rtol=3.1e-4)


def test_lobes_follow_eq_32_33():
    """POINT: axis toward the lamp, sharpness -ln(0.1) d^2 / r^2 (eq. 32), integral the
    irradiance at normal incidence Phi / (4 pi d^2); SUN: axis against its direction,
    sharpness -ln(0.1) / (angle / 2)^2 (eq. 33), integral its strength; both capped."""
    x = np.array([[0.0, 0.0, 0.0], [1.0, -2.0, 0.5]])
    point = lamp_lobes.Lamp("POINT", color=(40.0, 20.0, 10.0), position=(0.5, 0.5, 3.0), radius=0.2)
    sun = lamp_lobes.Lamp("SUN", color=(2.0, 2.0, 2.0), direction=(0.3, 0.0, -1.0), angle=0.1)
    tiny = lamp_lobes.Lamp("POINT", color=(1.0, 1.0, 1.0), position=(0.0, 0.0, 1.0), radius=0.0)
    axes, lam, mu = lamp_lobes.lamp_sgs([point, sun, tiny], x)
    ln10 = math.log(10.0)
    for p in range(len(x)):
        v = np.asarray(point.position) - x[p]
        d2 = float(v @ v)
        np.testing.assert_allclose(axes[p, 0], v / math.sqrt(d2))
        assert lam[p, 0] == pytest.approx(ln10 * d2 / 0.04)
        np.testing.assert_allclose(sg.integral(lam[p, 0], mu[p, 0]),
                                   np.array([40.0, 20.0, 10.0]) / (4 * math.pi * d2), rtol=1e-12)
        np.testing.assert_allclose(axes[p, 1], -sun.direction)
        assert lam[p, 1] == pytest.approx(ln10 / 0.05 ** 2)
        np.testing.assert_allclose(sg.integral(lam[p, 1], mu[p, 1]), 2.0, rtol=1e-12)
    assert np.all(lam[:, 2] == LAMP_LAMBDA_MAX)            # a point: the sharpest lobe
    assert np.all(lam <= LAMP_LAMBDA_MAX)


def test_spot_cone_is_cycles_smoothstep():
    """Inside the cone less its blend: 1; outside: 0; in the blend: smoothstep of
    (cos - cos_half) / ((1 - cos_half) blend), times the point lamp's lobe."""
    size, blend = math.radians(60.0), 0.4
    spot = lamp_lobes.Lamp("SPOT", color=(1.0, 1.0, 1.0), position=(0.0, 0.0, 2.0),
                           direction=(0.0, 0.0, -1.0), radius=0.1, spot_size=size, spot_blend=blend)
    point = lamp_lobes.Lamp("POINT", color=(1.0, 1.0, 1.0), position=(0.0, 0.0, 2.0), radius=0.1)
    angles = np.radians([0.0, 10.0, 24.0, 28.0, 31.0, 50.0])
    x = np.stack([2.0 * np.tan(angles), np.zeros_like(angles), np.zeros_like(angles)], 1)
    ratio = lamp_lobes.lamp_sgs([spot], x)[2][:, 0, 0] / lamp_lobes.lamp_sgs([point], x)[2][:, 0, 0]
    cos_half = math.cos(size / 2)
    t = np.clip((np.cos(angles) - cos_half) / ((1 - cos_half) * blend), 0.0, 1.0)
    np.testing.assert_allclose(ratio, t * t * (3 - 2 * t), atol=1e-12)
    assert ratio[0] == 1.0 and ratio[-1] == 0.0 and 0.0 < ratio[3] < 1.0


def test_lamps_check_their_input_and_area_lamps_their_size():
    with pytest.raises(ValueError, match="kind"):
        lamp_lobes.Lamp("LASER")
    with pytest.raises(ValueError, match="NaN"):
        lamp_lobes.Lamp("POINT", position=(0.0, np.nan, 1.0))
    with pytest.raises(ValueError, match="shading positions"):
        lamp_lobes.lamp_sgs([lamp_lobes.Lamp("POINT")])
    assert np.linalg.norm(lamp_lobes.Lamp("SUN", direction=(0.0, 3.0, -4.0)).direction) == \
        pytest.approx(1.0)
    rect = lamp_lobes.Lamp("AREA", half_x=(1.0, 0.0, 0.0), half_y=(0.0, 0.5, 0.0), shape="RECTANGLE")
    disk = lamp_lobes.Lamp("AREA", half_x=(1.0, 0.0, 0.0), half_y=(0.0, 1.0, 0.0), shape="DISK")
    assert rect.area == pytest.approx(2.0) and disk.area == pytest.approx(math.pi)
    assert lamp_lobes.Lamp("POINT").area == 0.0
