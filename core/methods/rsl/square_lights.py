"""RSL's light decomposition (Xu, Jia, Hu, Tai 2006, §4.1): the environment merged bottom-up
into K subregions, each a rotatable square light of its energy, centre and solid angle."""

from __future__ import annotations

import heapq
import math
from dataclasses import dataclass

import numpy as np

from ...sphere.directions import Cubemap, direction_to_texel
from ...sphere.envmap import LUMINANCE, CubeLighting


@dataclass
class SquareLights:
    """``K`` rotatable square lights in the lighting's own (texture) frame.

    ``centres`` (K, 3) unit: the luminance-weighted mean direction of each subregion;
    ``solid_angles`` (K,): ``|S_i|`` (the square has this solid angle, i.e. area
    ``|S_i|/2`` in the disk map); ``energy`` (K, 3): ``integral of L over S_i``, so the
    intensity ``I_i = energy_i / |S_i|`` preserves each subregion's energy (§4.1.1).
    ``labels`` (6N²,): the subregion of every cubemap texel.  ``fit_error``: the
    intensity part of the RSL fitting error, ``sum_i integral_{S_i} (L - I_i)²`` in
    luminance (grows with every merge), relative to ``integral of Y² dw`` (see :func:`decompose`).
    """

    centres: np.ndarray
    solid_angles: np.ndarray
    energy: np.ndarray
    labels: np.ndarray
    fit_error: float = 0.0
    seconds: float = 0.0

    @property
    def count(self) -> int:
        return len(self.solid_angles)

    @property
    def half_sides(self) -> np.ndarray:
        """Half edge of each square in the disk plane: ``sqrt(|S|/2) / 2``."""
        return 0.5 * np.sqrt(0.5 * self.solid_angles)

    @property
    def intensity(self) -> np.ndarray:
        return self.energy / self.solid_angles[:, None]

    def rotated(self, world_to_texture: np.ndarray) -> np.ndarray:
        """Centres in world space for a world whose lighting reads ``E(R d)``:
        ``d = R^T c``, i.e. rows ``c @ R``."""
        return self.centres @ np.asarray(world_to_texture, dtype=np.float64)


def texel_neighbours(cube: Cubemap) -> np.ndarray:
    """(E, 2) pairs of edge-adjacent texels, across cube faces too."""
    n = cube.resolution
    D = cube.size
    idx = np.arange(D)
    face, row, col = idx // (n * n), (idx // n) % n, idx % n
    from ...sphere.directions import FACE_AXES
    ax = FACE_AXES[face]
    h = 2.0 / n
    s = -1.0 + (col + 0.5) * h
    t = -1.0 + (row + 0.5) * h
    pairs = []
    for ds, dt in ((h, 0.0), (0.0, h)):
        d = ax[:, 0] + (s + ds)[:, None] * ax[:, 1] + (t + dt)[:, None] * ax[:, 2]
        other = direction_to_texel(d, n)
        pairs.append(np.stack([idx, other], axis=1))
        d = ax[:, 0] + (s - ds)[:, None] * ax[:, 1] + (t - dt)[:, None] * ax[:, 2]
        other = direction_to_texel(d, n)
        pairs.append(np.stack([idx, other], axis=1))
    p = np.concatenate(pairs)
    p = p[p[:, 0] != p[:, 1]]
    p.sort(axis=1)
    return np.unique(p, axis=0)


def square_fit_error(A, E, Q, M):
    """Mean over the four rotations of ``integral (T - F(theta))^2`` (§4.1.1), from moments.

    ``A`` solid angle, ``E = integral Y``, ``Q = integral Y^2``, ``M = integral w`` (3,).
    The square of area ``A`` (intensity ``I = E/A``) leaves the subregion's own
    variance ``Q - E²/A`` and, where region and square differ, ``I²`` times the area
    of the symmetric difference, averaged over the rotations 0, π/8, π/4, 3π/8.  That
    area is estimated from the region's second moment about its centre
    ``J = A - |M|²/A``: ``A (0.1 + 1.9 (1 - min(1, A²/2πJ)))``, from about ``0.1 A``
    for disk-like regions to ``2 A`` for long ones.  (The plane's own mean, 0.18 A for a disk,
    rendered worse on the tuning HDRIs: docs/measurements.md, RSL.)
    """
    var = max(Q - E * E / A, 0.0)
    J = max(A - (M[0] * M[0] + M[1] * M[1] + M[2] * M[2]) / A, 1e-300)
    compact = min(A * A / (2.0 * math.pi * J), 1.0)
    mismatch = A * (0.1 + 1.9 * (1.0 - compact))
    return var + (E / A) ** 2 * mismatch


def decompose(lighting: CubeLighting, cube: Cubemap, count: int | None = 30,
              error_budget: float | None = None, area_power: float = 1.0,
              _history: list | None = None) -> SquareLights:
    """Bottom-up merging of cubemap texels into ``count`` subregions (§4.1.2, Fig. 5).

    Each step merges the pair of adjacent subregions (across cube faces too) whose
    merged subregion has the least penalised fitting error ``|S|^p E(eta²)`` (eq. 7,
    ``p = area_power``; Fig. 5 picks the least merged error, not the least increase of
    the sum); costs come from moments (they add on a merge) and are kept in a priority
    queue with lazy invalidation, so 6x32² texels -> 30 lights takes well under a
    second instead of the paper's two minutes.  With ``error_budget``
    the count is the smallest one (not below ``count``; ``None``: 1) whose intensity
    fitting error ``sum_i integral_{S_i} (L - I_i)²`` is at most ``error_budget`` times
    ``(integral Y dw)² / 4 pi`` (the squared luminance integral of a uniform
    environment of the same power); the merge order does not depend on the budget.
    """
    if error_budget is not None:
        history = []
        decompose(lighting, cube, 1, None, area_power, _history=history)
        allowed = float(error_budget)
        floor_count = 1 if count is None else max(1, int(count))
        fits = [n for n, err in history if err <= allowed and n >= floor_count]
        best = min(fits) if fits else cube.size
        return decompose(lighting, cube, best, None, area_power)
    import time
    t0 = time.perf_counter()
    rad = np.asarray(lighting.radiance, dtype=np.float64)
    if not np.all(np.isfinite(rad)):
        raise ValueError("lighting has NaN/Inf radiance")
    D = cube.size
    if rad.shape != (D, 3):
        raise ValueError(f"lighting has {rad.shape[0]} texels, cubemap {D}")
    dw = np.asarray(cube.solid_angles, dtype=np.float64)
    Y = np.maximum(rad @ LUMINANCE, 0.0)
    target = 1 if count is None else max(1, min(int(count), D))
    A = dw.tolist()
    E = (Y * dw).tolist()
    Q = (Y * Y * dw).tolist()
    Mg = cube.mean_directions * dw[:, None]
    M = [tuple(m) for m in Mg.tolist()]
    p = float(area_power)
    alive = [True] * D
    parent = list(range(D))
    stamp = [0] * D
    neigh = [set() for _ in range(D)]
    for a, b in texel_neighbours(cube).tolist():
        neigh[a].add(b)
        neigh[b].add(a)
    # scale: integral of Y² of a uniform environment with the same power
    q_total = max(float(np.sum(Y * dw)) ** 2 / (4.0 * np.pi), 1e-300)
    total_var = 0.0               # sum of Q - E²/A over subregions (0 for single texels)

    def merged_moments(a, b):
        Ma, Mb = M[a], M[b]
        return (Ma[0] + Mb[0], Ma[1] + Mb[1], Ma[2] + Mb[2])

    def merged(a, b):
        """Penalised fitting error ``|S|^p E(eta²)`` of the union of regions a and b."""
        Am = A[a] + A[b]
        return square_fit_error(Am, E[a] + E[b], Q[a] + Q[b], merged_moments(a, b)) * Am ** p

    heap = []
    for a in range(D):
        for b in neigh[a]:
            if a < b:
                heap.append((merged(a, b), a, b, 0, 0))
    heapq.heapify(heap)
    regions = D
    while regions > target and heap:
        _, a, b, sa, sb = heapq.heappop(heap)
        if not (alive[a] and alive[b]) or stamp[a] != sa or stamp[b] != sb:
            continue
        Mm = merged_moments(a, b)
        if len(neigh[a]) < len(neigh[b]):
            a, b = b, a
        total_var += (Q[a] + Q[b] - (E[a] + E[b]) ** 2 / (A[a] + A[b])
                      - (Q[a] - E[a] ** 2 / A[a]) - (Q[b] - E[b] ** 2 / A[b]))
        A[a] += A[b]
        E[a] += E[b]
        Q[a] += Q[b]
        M[a] = Mm
        alive[b] = False
        stamp[a] += 1
        nb = neigh[b]
        nb.discard(a)
        na = neigh[a]
        na.discard(b)
        for x in nb:
            nx = neigh[x]
            nx.discard(b)
            nx.add(a)
        na |= nb
        neigh[b] = set()
        parent[b] = a
        regions -= 1
        if _history is not None:
            _history.append((regions, max(total_var, 0.0) / q_total))
        sa = stamp[a]
        for x in na:
            heapq.heappush(heap, (merged(a, x), a, x, sa, stamp[x]))
    labels = np.array(parent)
    while True:                       # follow merge parents to the surviving roots
        nxt = labels[labels]
        if np.array_equal(nxt, labels):
            break
        labels = nxt
    roots = np.nonzero(np.array(alive))[0]
    remap = np.full(D, -1, dtype=np.int64)
    remap[roots] = np.arange(len(roots))
    lab = remap[labels]
    K = len(roots)
    sa_k = np.bincount(lab, weights=dw, minlength=K)
    energy = np.stack([np.bincount(lab, weights=rad[:, c] * dw, minlength=K)
                       for c in range(3)], axis=1)
    # centre: luminance-weighted mean light direction (a sun keeps its direction);
    # geometric centre for dark subregions.
    ld = np.asarray(lighting.directions, dtype=np.float64)
    yw = Y * dw
    mom = np.stack([np.bincount(lab, weights=yw * ld[:, c], minlength=K) for c in range(3)], 1)
    geo = np.stack([np.bincount(lab, weights=Mg[:, c], minlength=K) for c in range(3)], 1)
    lum = np.bincount(lab, weights=yw, minlength=K)
    lit = lum > 1e-12 * max(lum.max(initial=0.0), 1e-300)
    centre = np.where(lit[:, None], mom, geo)
    nrm = np.linalg.norm(centre, axis=1, keepdims=True)
    bad = nrm[:, 0] < 1e-12
    centre = np.where(bad[:, None], geo, centre)
    centre /= np.maximum(np.linalg.norm(centre, axis=1, keepdims=True), 1e-300)
    return SquareLights(centre, sa_k, energy, lab, max(total_var, 0.0) / q_total,
                        time.perf_counter() - t0)
