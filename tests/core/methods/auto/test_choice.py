"""core.methods.auto.choice (no Blender): AUTO's assignment against brute-force enumeration, its
area sample, the sampled estimates and their stated error, its time model."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from prt_relight.core.methods.auto import choice as ac


# ------------------------------------------------------------------ assignment

def _random_options(rng, objects, per_object):
    out = []
    for i in range(objects):
        errs = rng.uniform(0.0, 1.0, per_object) ** 2
        times = rng.uniform(0.1, 1.0, per_object)
        out.append([((f"M{k}", None, i), float(t), float(e))
                    for k, (t, e) in enumerate(zip(times, errs))])
    return out


def _brute(options, budget2):
    """(seconds, assignment) of the fastest assignment within the budget, or None."""
    best = None
    for combo in itertools.product(*options):
        if sum(o[2] for o in combo) <= budget2:
            t = sum(o[1] for o in combo)
            if best is None or t < best[0]:
                best = (t, combo)
    return best


@pytest.mark.parametrize("seed", range(200))
def test_mix_against_brute_force(seed):
    """Feasible exactly when an assignment within the budget exists; then its time is
    within the relaxation's bound of the optimum (the largest spread of one object's
    times: at most one object sits between two hull options at the critical λ) and
    usually equal to it; infeasible: the most accurate assignment."""
    rng = np.random.default_rng(seed)
    options = _random_options(rng, int(rng.integers(1, 5)), int(rng.integers(1, 6)))
    min_err = sum(min(o[2] for o in ok) for ok in options)
    budget2 = float(rng.uniform(0.5, 2.0) * min_err + rng.uniform(0.0, 0.6))
    got = ac.mix(options, budget2)
    assert len(got) == len(options)
    assert all(o in ok for o, ok in zip(got, options))
    best = _brute(options, budget2)
    if best is None:
        assert sum(o[2] for o in got) == pytest.approx(min_err)
        return
    assert sum(o[2] for o in got) <= budget2
    spread = max(max(o[1] for o in ok) - min(o[1] for o in ok) for ok in options)
    assert sum(o[1] for o in got) <= best[0] + spread + 1e-12
    if len(options) == 1:                      # one object: the cheapest that fits
        assert sum(o[1] for o in got) == pytest.approx(best[0])


def test_mix_is_optimal_on_most_small_cases():
    hits = 0
    cases = 300
    for seed in range(cases):
        rng = np.random.default_rng(1000 + seed)
        options = _random_options(rng, 3, 4)
        budget2 = float(rng.uniform(0.2, 1.5))
        best = _brute(options, budget2)
        got = ac.mix(options, budget2)
        if best is None or sum(o[1] for o in got) <= best[0] + 1e-12:
            hits += 1
    assert hits >= 0.9 * cases, hits


def test_mix_skips_options_without_a_time_or_error_and_refuses_none_left():
    inf = float("inf")
    options = [[(("A", None, 1), inf, 0.0), (("B", None, 1), 1.0, 0.1)],
               [(("A", None, 2), 0.5, inf), (("B", None, 2), 2.0, 0.0)]]
    got = ac.mix(options, 1.0)
    assert [o[0][0] for o in got] == ["B", "B"]
    with pytest.raises(ValueError):
        ac.mix([[(("A", None, 1), inf, 0.0)]], 1.0)


def test_mix_takes_a_cheaper_option_off_the_hull():
    """(err, time) (0, 10), (0.5, 6), (1, 1): the middle one is above the hull between
    the others; a budget of 0.6 only fits it and the exact one, and it is cheaper."""
    options = [[(("R", None, None), 10.0, 0.0), (("M", None, None), 6.0, 0.5),
                (("S", None, None), 1.0, 1.0)]]
    assert ac.mix(options, 0.6)[0][0][0] == "M"


# ------------------------------------------------------------------ sample

def _surface(n=4000, seed=0):
    rng = np.random.default_rng(seed)
    positions = rng.uniform(-1, 1, (n, 3))
    areas = rng.gamma(2.0, 1.0, n)
    return positions, areas


def test_area_sample_is_deterministic_and_spans_the_area():
    positions, areas = _surface()
    a = ac.area_sample(areas, positions, 256, seed=3)
    b = ac.area_sample(areas, positions, 256, seed=3)
    assert np.array_equal(a.rows, b.rows) and np.array_equal(a.scale, b.scale)
    assert not a.exact and a.draws == 256 and int(a.times.sum()) == 256
    assert np.all(np.diff(a.rows) > 0)
    # Σ scale · area is the total area exactly (each draw stands for one stratum)
    assert float(a.scale @ areas[a.rows]) == pytest.approx(areas.sum())
    c = ac.area_sample(areas, positions, 256, seed=4)
    assert not np.array_equal(a.rows, c.rows)


def test_area_sample_takes_everything_when_small_and_skips_zero_area():
    positions, areas = _surface(100)
    areas[:10] = 0.0
    s = ac.area_sample(areas, positions, 256)
    assert s.exact and np.array_equal(s.rows, np.arange(10, 100))
    e = ac.estimate(s, None, np.ones(90), 2 * np.ones(90))
    assert e.sigma == 0.0 and e.err2 == pytest.approx(areas.sum())


def test_area_sample_is_stratified_in_space():
    """Draws spread over the surface: each octant of a uniform cube of points gets close
    to its share (a plain random draw would vary by ~sqrt(n/8))."""
    positions, _ = _surface(20000)
    s = ac.area_sample(np.ones(20000), positions, 512, seed=1)
    octant = ((positions[s.rows] > 0) * [1, 2, 4]).sum(axis=1)
    counts = np.bincount(octant, weights=s.times, minlength=8)
    assert np.all(np.abs(counts - 64) <= 3), counts


def _field(positions, areas, seed):
    """Per-point squared errors with a heavy tail (a shadow edge) and reference norms."""
    rng = np.random.default_rng(seed)
    ref2 = 1.0 + 0.5 * np.sin(3 * positions[:, 0]) ** 2
    err2 = 1e-4 * rng.gamma(0.5, 1.0, len(areas))
    edge = np.abs(positions[:, 1] - 0.3) < 0.05
    err2[edge] += 0.02 * rng.random(int(edge.sum()))
    return err2, ref2


def test_estimate_is_unbiased_and_its_stated_error_covers_the_truth():
    """Over many seeds: the mean estimate is the full sum (within its spread / sqrt of
    the seeds), and the true error lies below the stated bound ``Ê + 2σ`` (relative to
    the estimated reference norm) in at least 95 % of the seeds."""
    positions, areas = _surface(20000, seed=5)
    err2, ref2 = _field(positions, areas, 6)
    E, B = float(areas @ err2), float(areas @ ref2)
    ests, covered, sigmas = [], 0, []
    seeds = 200
    for seed in range(seeds):
        s = ac.area_sample(areas, positions, 512, seed=seed)
        est = ac.estimate(s, None, err2[s.rows], ref2[s.rows])
        ests.append(est.err2 / est.ref2)
        sigmas.append(est.sigma / est.ref2)
        covered += (E / B) <= est.err2_up() / est.ref2
    ests = np.array(ests)
    spread = ests.std()
    assert abs(ests.mean() - E / B) <= 4 * spread / np.sqrt(seeds)
    assert covered >= 0.95 * seeds, covered
    # the stated σ is an upper estimate of the real spread (stratification), not wild
    assert spread <= np.mean(sigmas) <= 4 * spread


def test_estimate_with_pixel_weights():
    """Weights other than area (pixels in an image) are estimated from the same draws."""
    positions, areas = _surface(20000, seed=7)
    err2, ref2 = _field(positions, areas, 8)
    w = areas * (positions[:, 2] > 0)                 # half the points do not show
    E, B = float(w @ err2), float(w @ ref2)
    s = ac.area_sample(areas, positions, 1024, seed=0)
    est = ac.estimate(s, w[s.rows], err2[s.rows], ref2[s.rows])
    assert est.ref2 == pytest.approx(B, rel=0.05)
    assert abs(est.err2 / est.ref2 - E / B) <= 2 * est.sigma / est.ref2 + 1e-12
    assert est.rel_margin() > 0 and np.isfinite(est.rel())


def test_estimate_of_a_non_finite_error_is_infinite():
    positions, areas = _surface(2000)
    s = ac.area_sample(areas, positions, 64)
    e = np.zeros(s.size)
    e[0] = np.inf
    assert ac.estimate(s, None, e, np.ones(s.size)).err2 == np.inf


def test_morton_order_is_a_permutation_grouping_neighbours():
    positions, _ = _surface(4096)
    order = ac.morton_order(positions)
    assert np.array_equal(np.sort(order), np.arange(4096))
    steps = np.linalg.norm(np.diff(positions[order], axis=0), axis=1)
    rand = np.linalg.norm(np.diff(positions, axis=0), axis=1)
    assert np.median(steps) < 0.3 * np.median(rand)
    assert len(ac.morton_order(np.zeros((0, 3)))) == 0


# ------------------------------------------------------------------ time

def test_linear_time_and_assignment_seconds():
    # 0.1 s per lighting + 1 ms per point, timed at 100 and 400 points
    fixed, per_point, at = ac.linear_time(100, 0.2, 400, 0.5, 10000)
    assert (fixed, per_point, at) == pytest.approx((0.1, 1e-3, 10.1))
    # relit: one point (0.3 s: the lighting's shared work), then 1000 and 100 points
    fixed, per_point, at = ac.relit_time(100, 0.02, 1000, 0.11, 0.3, 10000)
    assert (fixed, per_point, at) == pytest.approx((0.3 - 1e-4, 1e-4, 1.2999))
    assert ac.relit_time(100, 0.02, 1000, np.inf, 0.3, 10)[2] == np.inf
    # one timing (the whole object): all per point
    assert ac.linear_time(50, 0.5, 50, 0.5, 50) == pytest.approx((0.0, 0.01, 0.5))
    # a noisy pair never gives a negative slope or fixed part
    fixed, per_point, at = ac.linear_time(100, 0.3, 400, 0.2, 1000)
    assert per_point == 0.0 and fixed == 0.3 and at == 0.3
    assert ac.linear_time(100, np.inf, 400, 0.2, 10)[2] == np.inf
    a, b = ("SH", "sh_order", 3), ("RSL", "rsl_lights", 20)
    models = [{a: (0.1, 1e-6, 1000), b: (0.3, 1e-5, 1000)},
              {a: (0.2, 1e-6, 4000), b: (0.3, 2e-5, 4000)}]
    # a method shared by both objects pays its per-lighting part once (the larger)
    assert ac.assignment_seconds([a, a], models) == pytest.approx(0.2 + 1e-6 * 5000)
    assert ac.assignment_seconds([a, b], models) == pytest.approx(0.1 + 1e-3 + 0.3 + 0.08)
