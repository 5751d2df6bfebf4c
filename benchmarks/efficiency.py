"""How much data an agent needs to reach a success rate, and the ratio of two agents' needs, with intervals.

A success curve is the mean success rate over training seeds at each data size of a grid. The data an
agent needs for a threshold is read off its curve where it first reaches the threshold, interpolated
linearly in log(size) between the grid point below and the one at or above it (:func:`crossing`). A
curve that is already at the threshold at its smallest size only bounds the need from above ("at most
that size"); one that never reaches it only bounds it from below ("more than the largest size").

The interval is a two-level bootstrap (:func:`bootstrap_needs`): each draw resamples, at every size,
the seeds with replacement and then each chosen seed's episodes (its success count drawn again from
its own rate), and reads the crossing off the redrawn curve. The seeds' spread and the episodes'
both enter. ``scipy.stats.bootstrap`` resamples the observations of each sample independently and has
no such two-level draw, so the draw is written here (a few lines of numpy, with an explicit
Generator).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal, Sequence

import numpy as np

__all__ = ["Need", "Point", "bootstrap_needs", "crossing", "data_ratio"]

Bound = Literal["exact", "at_most", "more_than"]
"""What a need is: read between two grid points ("exact"), at most the smallest size, or more than the largest."""


@dataclass(frozen=True)
class Point:
    """One grid point of a success curve: a data size and, per training seed, (successes, episodes)."""

    size: int
    seeds: tuple[tuple[int, int], ...]

    @property
    def rate(self) -> float:
        """The mean over seeds of each seed's success rate."""
        return float(np.mean([k / n for k, n in self.seeds]))


@dataclass(frozen=True)
class Need:
    """The data an agent needs for a threshold: a size and whether it is read between points or a bound."""

    size: float
    bound: Bound


def crossing(sizes: Sequence[float], rates: Sequence[float], threshold: float) -> Need:
    """Where the curve (``rates`` at increasing ``sizes``) first reaches ``threshold``, in log(size) between
    the grid point below and the first one at or above it (:class:`Need`)."""
    for i, (n, r) in enumerate(zip(sizes, rates)):
        if r >= threshold:
            if i == 0:
                return Need(float(n), "at_most")
            n0, r0 = sizes[i - 1], rates[i - 1]  # r0 < threshold <= r
            t = (threshold - r0) / (r - r0)
            return Need(float(math.exp(math.log(n0) + t * (math.log(n) - math.log(n0)))), "exact")
    return Need(float(sizes[-1]), "more_than")


def bootstrap_needs(points: Sequence[Point], threshold: float, draws: int, rng: np.random.Generator) -> list[Need]:
    """The need of ``draws`` curves redrawn from ``points`` (seeds, then episodes; module docstring)."""
    sizes = [p.size for p in points]
    needs = []
    for _ in range(draws):
        rates = []
        for p in points:
            chosen = rng.integers(len(p.seeds), size=len(p.seeds))  # seeds with replacement
            rates.append(np.mean([rng.binomial(p.seeds[j][1], p.seeds[j][0] / p.seeds[j][1]) / p.seeds[j][1]
                                  for j in chosen]))
        needs.append(crossing(sizes, rates, threshold))
    return needs


def _summary(needs: list[Need], point: Need) -> dict[str, object]:
    lo, hi = np.percentile([need.size for need in needs], [2.5, 97.5])
    return {"value": point.size, "bound": point.bound, "low": float(lo), "high": float(hi),
            "bounded_draws": sum(need.bound != "exact" for need in needs) / len(needs)}


def data_ratio(numerator: Sequence[Point], denominator: Sequence[Point], threshold: float, draws: int = 4000,
               seed: int = 0) -> dict[str, object]:
    """The need of each agent for ``threshold`` and their ratio (numerator's over denominator's), each with
    its 95% percentile interval over ``draws`` paired bootstrap draws.

    A ratio is a lower bound ("at_least") where the denominator's need is at most its smallest size or the
    numerator's more than its largest, in the point estimate or in more than 2.5% of the draws (those that a
    percentile could not leave out); an upper bound ("at_most") in the opposite cases; "undefined" where
    both kinds meet (the interval is then of ratios of bounds).
    """
    rng = np.random.default_rng(seed)
    num_points, den_points = sorted(numerator, key=lambda p: p.size), sorted(denominator, key=lambda p: p.size)
    num = crossing([p.size for p in num_points], [p.rate for p in num_points], threshold)
    den = crossing([p.size for p in den_points], [p.rate for p in den_points], threshold)
    num_draws = bootstrap_needs(num_points, threshold, draws, rng)
    den_draws = bootstrap_needs(den_points, threshold, draws, rng)

    def bounded(a: Need, b: Need) -> tuple[bool, bool]:  # is a / b bounded from below, from above (both: neither)
        return a.bound == "more_than" or b.bound == "at_most", a.bound == "at_most" or b.bound == "more_than"

    # a bound where the point estimate is one, or where more than the 2.5% of draws that a percentile leaves out are
    kinds = [bounded(a, b) for a, b in zip(num_draws, den_draws)]
    lower = bounded(num, den)[0] or sum(lo for lo, _ in kinds) > 0.025 * draws
    upper = bounded(num, den)[1] or sum(hi for _, hi in kinds) > 0.025 * draws
    ratios = [a.size / b.size for a, b in zip(num_draws, den_draws)]
    lo, hi = np.percentile(ratios, [2.5, 97.5])
    return {"threshold": threshold, "draws": draws, "seed": seed,
            "numerator": _summary(num_draws, num), "denominator": _summary(den_draws, den),
            "ratio": {"value": num.size / den.size, "low": float(lo), "high": float(hi),
                      "bound": "undefined" if lower and upper else "at_least" if lower else "at_most" if upper else "exact"}}
