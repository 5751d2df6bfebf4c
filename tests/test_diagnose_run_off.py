"""Fits whose optimiser steps where the simulation overflows: the fit keeps the best finite point it met, and a search
over the delay or the substeps passes a fit that ran off instead of stopping the diagnosis."""

from __future__ import annotations

import math

import numpy as np

from piga.diagnostics import fit
from piga.world.effects import WITHIN_FRAME
from tests.test_diagnostics import NOMINAL, planted


def windows() -> fit.Windows:
    obs = planted({"delay": 2}, n=20, t=12)
    return fit.make_windows(obs.theta, obs.actions, np.arange(20), 4, 2, 0.05)


def test_a_line_search_that_meets_nan_leaves_the_best_finite_fit(monkeypatch) -> None:
    w, real, calls = windows(), fit.loss, []

    def overflows(model, nominal, w, weights=None, params=None):  # the 4th evaluation on lands where it overflows
        value = real(model, nominal, w, weights, params)
        calls.append(1)
        return value * math.nan if len(calls) > 3 else value

    start = fit.Model((), 0, {"g": 0.9 * NOMINAL.g, "a": NOMINAL.a})
    monkeypatch.setattr(fit, "loss", overflows)
    m = fit.fit(start, NOMINAL, w)
    monkeypatch.undo()
    assert all(math.isfinite(v) for v in m.values.values()), m.values
    assert fit.loss(m, NOMINAL, w) <= fit.loss(start, NOMINAL, w)


def test_a_search_over_the_substeps_passes_a_fit_that_ran_off(monkeypatch) -> None:
    """Saturation with the motion within the frame ran off to NaN at one M on 21 sequences of 14 frames with a delay
    of 2, and its score stopped the diagnosis: "a fit ... ran off (g = nan, a = nan) ... a camera the model does not
    read"."""
    w, real = windows(), fit.fit
    first = WITHIN_FRAME.grid[0]

    def runs_off(model, nominal, w, *args, **kwargs):
        m = real(model, nominal, w, *args, **kwargs)
        return m.with_values({k: math.nan for k in m.values}) if model.substeps == first else m

    monkeypatch.setattr(fit, "fit", runs_off)
    m = fit.fit_candidate(("within_frame",), {"g": NOMINAL.g, "a": NOMINAL.a}, NOMINAL, w)
    assert m.substeps != first and not fit.collapsed(m, NOMINAL), m
    assert fit.fitted_loss(m.with_values({"g": math.nan, "a": 1.0}), NOMINAL, w) == math.inf
    assert np.isfinite(fit.fitted_loss(m, NOMINAL, w))
