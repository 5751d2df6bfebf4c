"""Fits whose optimiser steps where the simulation overflows: the fit keeps the best finite point it met, and a search
over the delay or the substeps passes a fit that ran off instead of stopping the diagnosis."""

from __future__ import annotations

import math
from dataclasses import replace

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


def test_the_substeps_a_file_states_are_fitted_not_searched(monkeypatch) -> None:
    """A dm_control file (2 physics steps of 0.02 s per 0.04 s frame) with a hinge damping of 1.0 was named
    "within_frame, 3 substeps" beside its damping: where the file states M, the fit takes it, and searches the grid only
    where it does not."""
    from piga.diagnostics.observe import system_substeps

    assert system_substeps(0.04, 0.02) == 2 and system_substeps(0.08, 0.02) == 4
    assert system_substeps(0.04, None) == 0 and system_substeps(0.05, 0.02) == 0  # not known; not a whole number
    assert system_substeps(0.02, 0.02) == 0  # one step per frame: nothing moves within the frame
    real, tried = fit.fit, []

    def recorded(model, nominal, w, *args, **kwargs):
        tried.append(model.substeps)
        return real(model, nominal, w, *args, **kwargs)

    monkeypatch.setattr(fit, "fit", recorded)
    w = windows()
    start = {"g": NOMINAL.g, "a": NOMINAL.a}
    assert fit.fit_candidate(("within_frame",), start, NOMINAL, replace(w, substeps=3)).substeps == 3
    assert tried == [3]
    tried.clear()
    fit.fit_candidate(("within_frame",), start, NOMINAL, w)
    assert tried == list(WITHIN_FRAME.grid)
    tried.clear()
    assert fit.fit_candidate(("damping",), start, NOMINAL, replace(w, substeps=3)).substeps == 0  # no within_frame
    from piga.diagnostics.results import Effect

    stated = Effect("within_frame", 2, "substeps per frame", stated=True)
    assert "2 physics steps per frame, as its file states" in stated.describe() and stated.to_dict()["stated"]
    fitted = Effect("within_frame", 3, "substeps per frame")
    assert "fits best as 3 substeps per frame" in fitted.describe() and "stated" not in fitted.to_dict()
