"""Quadrature helpers and Cycles' tables the core.shading tests share: a Fibonacci sphere,
views at an angle, a hemisphere grid graded to a lobe's width, the lobe integral of a
material, and values transcribed from Cycles' shader tables (Blender-free)."""

from __future__ import annotations

import numpy as np

from prt_relight.core.shading import brdf


#: the normal of the tests' hemisphere, and the two microfacet distributions
N_UP = np.array([[0.0, 0.0, 1.0]])
DISTS = ("BECKMANN", "GGX")


def fibonacci_sphere(n):
    """n nearly-uniform unit vectors; equal weights 4*pi/n."""
    i = np.arange(n, dtype=np.float64) + 0.5
    z = 1.0 - 2.0 * i / n
    r = np.sqrt(np.maximum(0.0, 1.0 - z * z))
    phi = i * np.pi * (3.0 - np.sqrt(5.0))
    return np.stack([r * np.cos(phi), r * np.sin(phi), z], axis=1)


def view_at(theta_deg, phi_deg=0.0):
    t, p = np.radians(theta_deg), np.radians(phi_deg)
    return np.array([[np.sin(t) * np.cos(p), np.sin(t) * np.sin(p), np.cos(t)]])


def hemisphere_grid(alpha, n_theta, n_phi):
    """(theta, phi) grid on the upper hemisphere, theta concentrated near 0 on
    the scale alpha: theta = arctan(alpha * tan(pi/2 * u)), u uniform.
    Returns directions (T*F, 3), trapezoid weights (T*F,) incl. sin(theta)."""
    u = np.linspace(0.0, 1.0, n_theta)
    theta = np.arctan(alpha * np.tan(0.5 * np.pi * np.minimum(u, 1.0 - 1e-12)))
    theta[-1] = 0.5 * np.pi
    wt = np.zeros_like(theta)
    dt = np.diff(theta)
    wt[:-1] += 0.5 * dt
    wt[1:] += 0.5 * dt
    phi = (np.arange(n_phi) + 0.5) * (2.0 * np.pi / n_phi)
    T, F = np.meshgrid(theta, phi, indexing="ij")
    dirs = np.stack([np.sin(T) * np.cos(F), np.sin(T) * np.sin(F), np.cos(T)], axis=-1)
    w = (wt * np.sin(theta))[:, None] * np.full(n_phi, 2.0 * np.pi / n_phi)[None, :]
    return dirs.reshape(-1, 3), w.reshape(-1)


def lobe_integral(mat, views, dirs, weights, chunk=250_000):
    """sum_d reflectance_cosine[p, d, :] * w_d, chunked over D -> (P, 3)."""
    acc = np.zeros((views.shape[0], 3))
    normals = np.repeat(N_UP, views.shape[0], axis=0)
    for s in range(0, dirs.shape[0], chunk):
        rc = brdf.reflectance_cosine(mat, normals, views, dirs[s:s + chunk])
        acc += np.einsum("pdc,d->pc", rc.astype(np.float64), weights[s:s + chunk])
    return acc


# Cycles' own precomputed single-scattering GGX directional albedo,
# intern/cycles/scene/shader.tables, ``table_ggx_E[1024]`` (32 x 32, row = mu
# index, column = roughness index, grid value = index / 31; read in
# microfacet_ggx_preserve_energy via lookup_table_read_2D(rough, mu)).
# (row, col) -> E: the values the tests check our quadrature against.
CYCLES_TABLE_GGX_E = {
    (31, 31): 0.306853, (31, 20): 0.770757, (31, 15): 0.926694, (31, 10): 0.987261,
    (15, 31): 0.457779, (15, 20): 0.748187, (15, 10): 0.964995,
    (5, 31): 0.681600, (5, 20): 0.832480,
    (1, 31): 0.888202, (1, 15): 0.952526,
}
