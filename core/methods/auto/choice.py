"""AUTO's numerics (no bpy): the sample of shading points it measures, the estimates
it draws from that sample with their sampling error, its model of a frame's time, and
the assignment of one option per object within the frame's error budget.

Sample (:func:`area_sample`)
    A frame's squared error is a sum over shading points weighted by the surface (or
    the pixels) each point stands for.  AUTO measures a fixed-seed sample of points per
    object instead of all of them: points are put in Morton order (space-filling curve of
    their positions), their cumulative area is cut into ``n`` equal strata and one point
    is drawn uniformly *by area* inside each stratum (jittered systematic sampling with
    probability proportional to area).  Every point then has an inclusion expectation
    proportional to its area, neighbouring surface goes to different strata (the draws
    spread over the object), and the draw is a function of the seed and the geometry
    only.  An object with at most ``n`` points of non-zero area is taken whole (exact).

Estimates (:func:`estimate`)
    For per-point values ``f`` and weights ``w`` (area, or pixels in an image) the
    Hansen-Hurwitz estimate of ``Σ_p w_p f_p`` is ``Σ_k Δ w_k / a_k f_k`` over the draws
    (``Δ`` the stratum's area, ``a_k`` the drawn point's area).  AUTO compares an error
    ``E = Σ w ‖e‖²`` with a reference norm ``B = Σ w ‖b‖²`` drawn from the same sample, so
    what matters is ``E - R B`` at the estimated ratio ``R = Ê / B̂``: its standard error
    ``σ`` is estimated from the draws' linearised residuals ``d_k = Δ w_k / a_k (e_k -
    R̂ b_k)`` as if they were drawn independently, ``σ² = n / (n - 1) Σ_k d_k²`` (for
    stratified draws this is an upper estimate: stratification only removes variance),
    and AUTO uses ``Ê + z σ`` (:data:`MARGIN_Z` = 2, about 98 % one-sided under a normal
    approximation) where it needs the error.  The rel-L2 error ``sqrt(Ê / B̂)`` is
    reported with its sampling error ``sqrt((Ê + z σ) / B̂) - sqrt(Ê / B̂)``.

Time (:func:`relit_time`, :func:`assignment_seconds`)
    A relit frame of a method on an object costs a fixed part ``F`` (resampling the
    environment, lighting tables, per-call work) and a part per shading point ``s`` (its
    per-lighting and per-view work): with a new lighting, a frame of one point first
    (``F`` and one point), then frames of ``n_a`` and ``n_0`` points that find the shared
    lighting work cached (their slope is ``s``), so ``t(P) = F + s P``.  Objects sharing a
    method share its fixed part, so an assignment costs ``Σ_methods (max_i F_i + Σ_i s_i
    P_i)``.

Assignment (:func:`mix`)
    The cheapest option per object (``(key, seconds, err²)``) such that ``Σ err² ≤
    budget²``: Lagrangian relaxation (each object minimises ``seconds + λ err²``, ``λ``
    bisected to the smallest that fits), then the slack it leaves spent greedily on
    cheaper options off the lower convex hull the relaxation reaches.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

#: One-sided normal quantile of the margin added to sampled errors (≈ 98 %).
MARGIN_Z = 2.0


# ------------------------------------------------------------------ sample

def morton_order(positions: np.ndarray, bits: int = 10) -> np.ndarray:
    """Indices of ``positions`` (N, 3) along a Morton (Z-order) curve of their bounding
    box quantised to ``2**bits`` cells per axis (stable for equal codes)."""
    p = np.asarray(positions, dtype=np.float64).reshape(-1, 3)
    if len(p) == 0:
        return np.zeros(0, dtype=np.int64)
    lo, hi = p.min(axis=0), p.max(axis=0)
    scale = (2 ** bits - 1) / np.maximum(hi - lo, 1e-300)
    q = np.clip(np.nan_to_num((p - lo) * scale), 0, 2 ** bits - 1).astype(np.uint64)
    code = np.zeros(len(p), dtype=np.uint64)
    for b in range(bits):
        for axis in range(3):
            code |= ((q[:, axis] >> np.uint64(b)) & np.uint64(1)) << np.uint64(3 * b + axis)
    return np.argsort(code, kind="stable")


@dataclass
class AreaSample:
    """Points of one object drawn by area (:func:`area_sample`).

    ``rows``: the drawn points (sorted, unique); ``scale``: per row, ``Δ · (times
    drawn) / area`` so that ``Σ_rows scale · w · f`` estimates ``Σ_p w_p f_p``;
    ``times``: how often each row was drawn; ``area``: the rows' areas; ``draws``: ``n``;
    ``exact``: every point with area was taken (``scale = 1``, no sampling error)."""

    rows: np.ndarray
    scale: np.ndarray
    times: np.ndarray
    area: np.ndarray
    draws: int
    exact: bool
    count: int

    @property
    def size(self) -> int:
        return int(len(self.rows))


def area_sample(areas: np.ndarray, positions: np.ndarray, count: int,
                seed: int = 0) -> AreaSample:
    """A jittered systematic sample of ``count`` draws with probability proportional to
    ``areas`` (P,) along the Morton order of ``positions`` (P, 3); every point with
    area when there are at most ``count`` of them.  Deterministic for a seed."""
    areas = np.nan_to_num(np.asarray(areas, dtype=np.float64), nan=0.0, posinf=0.0)
    areas = np.maximum(areas, 0.0)
    total_points = len(areas)
    nonzero = np.flatnonzero(areas > 0)
    if len(nonzero) <= count or areas.sum() <= 0:
        rows = nonzero if len(nonzero) else np.arange(total_points)
        return AreaSample(rows, np.ones(len(rows)), np.ones(len(rows), np.int64), areas[rows],
                          len(rows), True, total_points)
    order = morton_order(np.asarray(positions)[nonzero])
    idx = nonzero[order]
    cum = np.cumsum(areas[idx])
    total = float(cum[-1])
    step = total / count
    u = (np.arange(count) + np.random.default_rng(seed).random(count)) * step
    picks = idx[np.minimum(np.searchsorted(cum, u, side="right"), len(idx) - 1)]
    rows, times = np.unique(picks, return_counts=True)
    return AreaSample(rows, step * times / areas[rows], times.astype(np.int64), areas[rows],
                      int(count), False, total_points)


# ------------------------------------------------------------------ estimates

@dataclass
class Estimate:
    """``err2`` (Ê) and ``ref2`` (B̂) of one sample, ``sigma`` the standard error of
    ``Ê - R̂ B̂`` (0 when exact); ``err2_up = Ê + z σ`` is what decisions use."""

    err2: float
    ref2: float
    sigma: float

    def err2_up(self, z: float = MARGIN_Z) -> float:
        return self.err2 + z * self.sigma

    def rel(self) -> float:
        return rel_error(self.err2, self.ref2)

    def rel_margin(self, z: float = MARGIN_Z) -> float:
        """The rel-L2 error's sampling margin: ``sqrt(err2_up / ref2) - sqrt(err2 / ref2)``."""
        return rel_error(self.err2_up(z), self.ref2) - self.rel()


def rel_error(err2: float, ref2: float) -> float:
    """rel-L2 from squared norms (the error itself against a black reference)."""
    if not np.isfinite(err2):
        return float("inf")
    return float(np.sqrt(err2 / ref2)) if ref2 > 0 else float(np.sqrt(max(err2, 0.0)))


def estimate(sample: AreaSample, weights, err2, ref2) -> Estimate:
    """Estimate of ``Σ w ‖e‖²`` and ``Σ w ‖b‖²`` from per-row values of ``sample``:
    ``weights`` (w at the rows; None: their area), ``err2`` and ``ref2`` (‖e‖², ‖b‖² at the
    rows).  ``sigma``: standard error of ``Ê - R̂ B̂`` from the draws' linearised
    residuals (with-replacement formula; an upper estimate for the stratified draws)."""
    e = np.asarray(err2, dtype=np.float64)
    b = np.asarray(ref2, dtype=np.float64)
    c = sample.scale * (sample.area if weights is None else np.asarray(weights, np.float64))
    if not np.isfinite(e).all():
        return Estimate(float("inf"), float(c @ b), 0.0)
    E, B = float(c @ e), float(c @ b)
    if sample.exact or sample.draws < 2:
        return Estimate(E, B, 0.0)
    R = E / B if B > 0 else 0.0
    # per draw: Δ w/a (e - R b); a row drawn t times is t equal draws (they sum to 0)
    d = c / sample.times * (e - R * b)
    n = sample.draws
    mean = float(d @ sample.times) / n
    ss = float(np.sum(sample.times * (d - mean) ** 2))
    return Estimate(E, B, float(np.sqrt(max(n / (n - 1) * ss, 0.0))))


# ------------------------------------------------------------------ time

def linear_time(n_a: int, t_a: float, n_b: int, t_b: float, count: int):
    """``(fixed, per_point, seconds at count)`` of a frame timed at ``n_a`` and ``n_b``
    points: ``t(n) = F + s n`` through the two timings, with ``s ≥ 0`` and ``F ≥ 0``.
    With one timing (``n_b <= n_a``, e.g. the whole object) all of it is per point."""
    if not (np.isfinite(t_a) and np.isfinite(t_b)):
        return float("inf"), float("inf"), float("inf")
    if n_b <= n_a:
        per_point = float(t_a) / max(n_a, 1)
        return 0.0, per_point, per_point * count
    per_point = max(float(t_b) - float(t_a), 0.0) / (n_b - n_a)
    fixed = max(float(t_a) - per_point * n_a, 0.0)
    return fixed, per_point, fixed + per_point * count


def relit_time(n_0: int, t_0: float, n_a: int, t_a: float, t_1: float, count: int):
    """``(fixed, per_point, seconds at count)`` of a relit frame from three frames with
    the same new lighting: ``t_1`` of one point first (it does the lighting's shared work:
    resampling, tables), then ``t_a`` and ``t_0`` of ``n_a > n_0`` points (the shared
    work cached, their own per-lighting and per-view work not): their slope is the
    per-point part, ``t_1`` less one point's the fixed part."""
    if not all(np.isfinite(v) for v in (t_0, t_a, t_1)):
        return float("inf"), float("inf"), float("inf")
    per_point = max(float(t_a) - float(t_0), 0.0) / max(n_a - n_0, 1)
    fixed = max(float(t_1) - per_point, 0.0)
    return fixed, per_point, fixed + per_point * count


def assignment_seconds(assignment, models) -> float:
    """Modelled time of one frame: ``assignment`` a method key per object, ``models``
    per object ``{key: (fixed, per_point, points)}``; objects sharing a method pay its
    fixed (per-lighting) part once (the largest of theirs)."""
    groups: dict = {}
    for key, model in zip(assignment, models):
        fixed, per_point, points = model[key]
        g = groups.setdefault(key[0], [0.0, 0.0])
        g[0] = max(g[0], fixed)
        g[1] += per_point * points
    return float(sum(f + v for f, v in groups.values()))


# ------------------------------------------------------------------ assignment

def mix(options, budget2: float):
    """Per object, one ``(key, seconds, err2)`` of ``options[i]`` (finite ones only) with
    ``Σ err2 ≤ budget2`` and small total seconds: Lagrangian relaxation (each object
    minimises ``seconds + λ err2``, ties to the smaller error; ``λ`` bisected to the
    smallest that fits), then cheaper options the relaxation cannot reach swapped in
    while the sum still fits.  When nothing fits, the relaxation's most accurate pick."""
    usable = [[o for o in ok if np.isfinite(o[1]) and np.isfinite(o[2])] for ok in options]

    def pick(lam):
        return [min(ok, key=lambda o: (o[1] + lam * o[2], o[2])) for ok in usable]

    def spend_slack(chosen):
        chosen = list(chosen)
        while True:
            slack = budget2 - sum(o[2] for o in chosen)
            swaps = [(c[1] - o[1], i, o) for i, (ok, c) in enumerate(zip(usable, chosen))
                     for o in ok if o[1] < c[1] and o[2] - c[2] <= slack]
            if not swaps:
                return chosen
            _, i, o = max(swaps, key=lambda x: x[0])
            chosen[i] = o

    if any(not ok for ok in usable):
        raise ValueError("an object has no option with a finite time and error")
    if sum(o[2] for o in pick(0.0)) <= budget2:
        return spend_slack(pick(0.0))
    lo, hi = 0.0, 1.0
    while sum(o[2] for o in pick(hi)) > budget2 and hi < 1e30:
        lo, hi = hi, hi * 10.0
    for _ in range(200):
        mid = (lo + hi) / 2
        if mid in (lo, hi):
            break
        if sum(o[2] for o in pick(mid)) <= budget2:
            hi = mid
        else:
            lo = mid
    best = pick(hi)
    return spend_slack(best) if sum(o[2] for o in best) <= budget2 else best
