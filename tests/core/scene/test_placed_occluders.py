"""core.scene.placed_occluders: the two-level shadow test answers as one Embree scene of
every instance's triangles placed in the world."""

import numpy as np

from prt_relight.core.scene import mesh, placed_occluders, visibility


def _sphere(n=12):
    """A closed UV sphere of radius 0.5 as (vertices, triangles)."""
    th, ph = np.meshgrid(np.linspace(0, np.pi, n), np.linspace(0, 2 * np.pi, 2 * n,
                                                               endpoint=False), indexing="ij")
    v = 0.5 * np.stack([np.sin(th) * np.cos(ph), np.sin(th) * np.sin(ph), np.cos(th)], -1)
    v = v.reshape(-1, 3)
    tri = []
    for i in range(n - 1):
        for j in range(2 * n):
            a, b = i * 2 * n + j, i * 2 * n + (j + 1) % (2 * n)
            tri += [[a, a + 2 * n, b], [b, a + 2 * n, b + 2 * n]]
    return v.astype(np.float32), np.array(tri, np.int32)


def _matrix(rng):
    c, s = np.cos(rng.uniform(0, 6.3)), np.sin(rng.uniform(0, 6.3))
    m = np.eye(4)
    m[:3, :3] = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]]) * rng.uniform(0.5, 1.5, 3)
    m[:3, 3] = rng.uniform(-4, 4, 3) * [1, 1, 0.3]
    return m


def test_two_levels_answer_as_the_placed_triangles():
    rng = np.random.default_rng(4)
    v, t = _sphere()
    box = np.array([[-6, -6, -1.2], [6, -6, -1.2], [6, 6, -1.2], [-6, 6, -1.2]], np.float32)
    ground = mesh.Occluders(box, np.array([[0, 1, 2], [0, 2, 3]], np.int32))
    mats = [_matrix(rng) for _ in range(40)]
    mats[7][:3, 2] = 0.0                # flattened to a disc: no inverse, placed instead
    placed = mesh.Occluders.join([ground] + [mesh.Occluders(
        (v @ m[:3, :3].T + m[:3, 3]).astype(np.float32), t) for m in mats])
    flat = visibility.build_occluder_scene(placed)
    two = placed_occluders.PlacedOccluders(ground, [mesh.Occluders(v, t)],
                                           [(0, m) for m in mats])
    n = 20000
    o = rng.uniform([-6, -6, -1.1], [6, 6, 2.0], (n, 3))
    d = rng.normal(size=(n, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    dist = np.where(rng.uniform(size=n) < 0.5, np.inf, rng.uniform(0.1, 8.0, n))
    truth = flat.run(o.astype(np.float32), d.astype(np.float32),
                     dists=np.minimum(dist, 1e30).astype(np.float32), query="OCCLUDED") != -1
    got = two.occluded(o, d, dist)
    assert 0.2 < truth.mean() < 0.8
    assert (got != truth).sum() <= 4, (got != truth).sum()     # measured 0 of 20000
    # rays that start on an instance's surface, told which one
    k = rng.integers(0, len(mats), 2000)
    k[k == 7] = 8                       # on the flat one there is no surface to start on
    p = v[rng.integers(0, len(v), 2000)].astype(np.float64)
    nrm = p / np.linalg.norm(p, axis=1, keepdims=True)
    wp = np.einsum("nij,nj->ni", np.array(mats)[k, :3, :3], p) + np.array(mats)[k, :3, 3]
    wn = np.einsum("nij,nj->ni", np.linalg.inv(np.array(mats)[k, :3, :3]).transpose(0, 2, 1),
                   nrm)
    wn /= np.linalg.norm(wn, axis=1, keepdims=True)
    dd = rng.normal(size=(2000, 3))
    dd /= np.linalg.norm(dd, axis=1, keepdims=True)
    wo = wp + 1e-3 * wn
    truth = flat.run(wo.astype(np.float32), dd.astype(np.float32), query="OCCLUDED") != -1
    got = two.occluded(wo, dd, np.full(2000, np.inf), start=k)
    assert truth.mean() > 0.3                       # half the directions go into its own
    assert (got != truth).sum() <= 4, (got != truth).sum()
