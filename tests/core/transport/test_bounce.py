"""core.transport.bounce: the bounces' series, the lamps' direct light at gather points."""

import math

import numpy as np
import pytest

from prt_relight.core.shading.brdf import diffuse_view_weight
from prt_relight.core.shading.materials import Material, principled_material
from prt_relight.core.sg.lamp_lobes import Lamp
from prt_relight.core.transport import bounce


def test_bounces_sum_the_series_of_an_enclosure():
    """Two clusters that see only each other (rows of pi: a closed enclosure's cosine
    integral) and albedo rho: the radiance sent is L0 (1 + rho + ... + rho^(B-1))."""
    cols = np.array([[1], [0]], np.int32)
    w = np.full((2, 1), math.pi, np.float32)
    direct = np.array([[math.pi, math.pi, math.pi], [math.pi, math.pi, math.pi]])
    rho = np.full((2, 3), 0.5)
    for b in (1, 2, 4):
        got = bounce.bounce(direct, rho, cols, w, b)
        assert got[0, 0] == pytest.approx(sum(0.5 ** (j + 1) for j in range(b)))
    np.testing.assert_allclose(bounce.receive(cols, w, np.array([[1.0] * 3, [2.0] * 3])),
                               [[2 * math.pi] * 3, [math.pi] * 3], rtol=1e-6)


def test_point_and_sun_lamps_light_as_cycles_does():
    x = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0]])
    n = np.array([[0.0, 0.0, 1.0], [0.0, 0.0, 1.0]])
    point = Lamp("POINT", color=(100.0, 100.0, 100.0), position=(0.0, 0.0, 2.0), radius=0.0)
    E = bounce.lamp_irradiance([point], x, n)
    d2 = np.array([4.0, 5.0])
    cos = np.array([1.0, 2.0 / math.sqrt(5.0)])
    np.testing.assert_allclose(E[:, 0], 100.0 / (4 * math.pi * d2) * cos, rtol=1e-9)
    sun = Lamp("SUN", color=(3.0, 3.0, 3.0), direction=(0.0, -0.6, -0.8), angle=0.0)
    np.testing.assert_allclose(bounce.lamp_irradiance([sun], x, n)[:, 0], 2.4, rtol=1e-9)
    blocked = bounce.lamp_irradiance([sun], x, n,
                                     occluded=lambda o, d, t, rows: np.ones(len(o), bool))
    assert not blocked.any()


def test_area_lamp_matches_its_surface_integral():
    """Four points on the lamp against a fine quadrature of its surface (a point 1.5 m
    below a 0.5 m square lamp facing down, and one off to the side)."""
    lamp = Lamp("AREA", color=(50.0, 50.0, 50.0), position=(0.0, 0.0, 1.5),
                direction=(0.0, 0.0, -1.0), half_x=(0.25, 0.0, 0.0), half_y=(0.0, 0.25, 0.0))
    x = np.array([[0.0, 0.0, 0.0], [1.0, 0.3, 0.0]])
    n = np.tile([0.0, 0.0, 1.0], (2, 1))
    g = (np.arange(64) + 0.5) / 64 * 2 - 1
    sx, sy = np.meshgrid(g, g)
    pts = np.column_stack([0.25 * sx.ravel(), 0.25 * sy.ravel(), np.full(sx.size, 1.5)])
    L = 50.0 / (math.pi * lamp.area)
    truth = []
    for p in x:
        v = pts - p
        d = np.linalg.norm(v, axis=1)
        truth.append(np.sum(L * (lamp.area / len(pts)) * (v[:, 2] / d) ** 2 / d ** 2))
    np.testing.assert_allclose(bounce.lamp_irradiance([lamp], x, n)[:, 0], truth, rtol=0.02)


def test_diffuse_reflectance_of_a_principled_base():
    plain = Material(diffuse_albedo=(0.5, 0.4, 0.3))
    np.testing.assert_allclose(bounce.diffuse_reflectance(plain, diffuse_view_weight),
                               (0.5, 0.4, 0.3))
    metal = principled_material(base_color=(0.8, 0.8, 0.8), metallic=1.0)
    assert bounce.diffuse_reflectance(metal, diffuse_view_weight).max() == 0.0
    dielectric = principled_material(base_color=(0.8, 0.8, 0.8))
    r = bounce.diffuse_reflectance(dielectric, diffuse_view_weight)
    assert 0.6 < r[0] < 0.8                       # the specular layer keeps a few percent


def _brute_glossy_albedo(material, cos_o, n_theta=400, n_phi=1200):
    """The glossy part's directional albedo by a fine midpoint quadrature over the
    hemisphere (uniform in theta and phi, sin(theta) dtheta dphi)."""
    from prt_relight.core.shading import brdf
    theta = (np.arange(n_theta) + 0.5) * (0.5 * math.pi / n_theta)
    phi = (np.arange(n_phi) + 0.5) * (2 * math.pi / n_phi)
    t, p = np.meshgrid(theta, phi, indexing="ij")
    dirs = np.stack([np.sin(t) * np.cos(p), np.sin(t) * np.sin(p), np.cos(t)], -1).reshape(-1, 3)
    dw = (np.sin(t) * (0.5 * math.pi / n_theta) * (2 * math.pi / n_phi)).reshape(-1)
    out = []
    for c in cos_o:
        v = np.array([[math.sqrt(1 - c * c), 0.0, c]])
        f = np.asarray(brdf.specular_cosine(material, [[0.0, 0.0, 1.0]], v, dirs), np.float64)
        f = f[0] if f.ndim == 3 else f[0][:, None] * np.asarray(material.specular_color)
        out.append(dw @ f)
    return np.array(out)


@pytest.mark.parametrize("material", [
    Material(diffuse_albedo=(0, 0, 0), specular_color=(0.9, 0.6, 0.3), roughness=0.5,
             distribution="GGX"),
    principled_material(base_color=(0.7, 0.35, 0.15), roughness=0.6),
    principled_material(base_color=(0.9, 0.7, 0.5), roughness=0.45, metallic=1.0)])
def test_glossy_albedo_matches_a_fine_quadrature(material):
    cos_o = np.array([0.15, 0.5, 0.9])
    got = bounce.glossy_albedo(material, cos_o)
    np.testing.assert_allclose(got, _brute_glossy_albedo(material, cos_o), rtol=0.02, atol=2e-4)


def test_multiscatter_glossy_conserves_energy_and_reflectors_keep_their_glossy_share():
    """Cycles' multiscatter GGX with a white colour reflects all the light it gets, at any
    roughness (a mirror-like one is integrated at GLOSSY_QUADRATURE_ROUGHNESS); a
    reflector sends its diffuse and its glossy share."""
    for r in (0.05, 0.3, 0.8):
        white = Material(diffuse_albedo=(0, 0, 0), specular_color=(1, 1, 1), roughness=r,
                         distribution="MULTI_GGX")
        np.testing.assert_allclose(bounce.glossy_albedo(white, [0.3, 0.7, 1.0]), 1.0, atol=0.02)
    m = principled_material(base_color=(0.7, 0.35, 0.15), roughness=0.8)
    total = bounce.reflectance(m, diffuse_view_weight)
    base = bounce.diffuse_reflectance(m, diffuse_view_weight)
    assert np.all(total > base + 0.02) and np.all(total < 1.0)


def test_a_compact_source_lights_as_the_disc_it_is():
    """A World source (a disc of 2 degrees, uniform radiance) as a sun: its irradiance on
    a tilted plane is the disc's radiance integrated over the disc times the cosine
    (quadrature of the disc), and a blocked shadow ray takes it all."""
    r, L = math.radians(2.0), np.array([50.0, 40.0, 30.0])
    axis = np.array([0.3, -0.2, 0.93])
    axis /= np.linalg.norm(axis)
    lamp = bounce.distant_source(axis, L, r)
    n = np.array([[0.0, 0.0, 1.0], [0.6, 0.0, 0.8]])
    got = bounce.lamp_irradiance([lamp], np.zeros((2, 3)), n)
    # the disc by quadrature: polar rings around the axis
    t = (np.arange(200) + 0.5) * (r / 200)
    ph = (np.arange(400) + 0.5) * (2 * math.pi / 400)
    T, P = np.meshgrid(t, ph, indexing="ij")
    u = np.cross(axis, [1.0, 0.0, 0.0])
    u /= np.linalg.norm(u)
    v = np.cross(axis, u)
    d = (np.cos(T)[..., None] * axis + (np.sin(T) * np.cos(P))[..., None] * u
         + (np.sin(T) * np.sin(P))[..., None] * v)
    dw = np.sin(T) * (r / 200) * (2 * math.pi / 400)
    expected = [L * float((np.maximum(d @ nn, 0.0) * dw).sum()) for nn in n]
    np.testing.assert_allclose(got, expected, rtol=1e-3)
    blocked = bounce.lamp_irradiance([lamp], np.zeros((2, 3)), n,
                                     lambda o, dd, dist, rows: np.ones(len(o), bool))
    np.testing.assert_array_equal(blocked, 0.0)
    point = bounce.distant_source(axis, L, 0.0, point_like=True)
    np.testing.assert_allclose(bounce.lamp_irradiance([point], np.zeros((1, 3)), n[:1]),
                               [L * axis[2]], rtol=1e-9)
