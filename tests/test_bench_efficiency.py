"""benchmarks/efficiency.py: the data an agent needs for a success rate, and the ratio of two agents' needs."""

from __future__ import annotations

import math
import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
from efficiency import Need, Point, bootstrap_needs, crossing, data_ratio  # noqa: E402

sys.path.pop(0)


def test_the_need_is_read_between_grid_points_in_log_size() -> None:
    """0.8 is reached halfway (in rate) from 0.6 at 100 to 1.0 at 400: the geometric midpoint, 200."""
    need = crossing([25, 100, 400], [0.0, 0.6, 1.0], 0.8)
    assert need.bound == "exact" and need.size == pytest.approx(200.0)
    assert crossing([25, 100, 400], [0.0, 0.8, 1.0], 0.8).size == pytest.approx(100.0)  # reached at a grid point


def test_a_curve_at_the_rate_from_its_smallest_size_or_never_there_gives_a_bound() -> None:
    assert crossing([5, 10], [1.0, 1.0], 0.95) == Need(5.0, "at_most")
    assert crossing([100, 500], [0.0, 0.5], 0.8) == Need(500.0, "more_than")
    # the first crossing counts: a dip after it does not move it
    assert crossing([10, 20, 40], [0.0, 0.9, 0.5], 0.8).size < 20


def test_the_bootstrap_redraws_seeds_and_episodes_and_is_seeded() -> None:
    points = [Point(10, ((0, 20), (2, 20))), Point(100, ((10, 20), (20, 20))), Point(1000, ((20, 20), (20, 20)))]
    a = bootstrap_needs(points, 0.8, 300, np.random.default_rng(1))
    b = bootstrap_needs(points, 0.8, 300, np.random.default_rng(1))
    assert a == b
    sizes = [need.size for need in a]
    assert min(sizes) >= 10 and max(sizes) <= 1000 and len(set(sizes)) > 20  # the draws spread between the points
    # a seed that never succeeds and one that always does are both drawn: some curves cross before 100
    assert any(size < 100 for size in sizes) and any(size > 100 for size in sizes)
    certain = [Point(10, ((0, 20),)), Point(100, ((20, 20),))]  # rates 0 and 1: every draw is the same curve
    assert [need.size for need in bootstrap_needs(certain, 0.5, 50, np.random.default_rng(0))] == [pytest.approx(math.sqrt(1000))] * 50


def test_the_ratio_is_a_lower_bound_when_the_denominator_is_at_its_rate_from_its_smallest_size() -> None:
    slow = [Point(100, ((0, 20),)), Point(1000, ((20, 20),))]
    fast = [Point(5, ((20, 20),)), Point(10, ((20, 20),))]
    out = data_ratio(slow, fast, 0.8, draws=200)
    assert out["denominator"]["bound"] == "at_most" and out["denominator"]["bounded_draws"] == 1
    assert out["ratio"]["bound"] == "at_least"
    assert out["ratio"]["value"] == pytest.approx(100 * 10 ** 0.8 / 5)
    assert data_ratio(fast, slow, 0.8, draws=200)["ratio"]["bound"] == "at_most"
    both = [Point(5, ((20, 20),))]
    assert data_ratio(both, both, 0.8, draws=50)["ratio"]["bound"] == "undefined"


def test_a_ratio_read_between_points_on_both_curves_has_an_interval_around_it() -> None:
    slow = [Point(100, ((2, 20), (6, 20))), Point(300, ((14, 20), (18, 20))), Point(1000, ((20, 20), (19, 20)))]
    fast = [Point(5, ((4, 20), (8, 20))), Point(10, ((15, 20), (17, 20))), Point(50, ((20, 20), (20, 20)))]
    out = data_ratio(slow, fast, 0.8, draws=500, seed=3)
    ratio = out["ratio"]
    assert out["numerator"]["bound"] == out["denominator"]["bound"] == "exact"
    assert ratio["low"] < ratio["value"] < ratio["high"]
    assert data_ratio(slow, fast, 0.8, draws=500, seed=3) == out  # the same seed, the same draws
