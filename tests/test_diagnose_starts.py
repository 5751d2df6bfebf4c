"""Fitted start states (errors in variables): a window's start velocity is the difference of two read
angles, and a fit that takes it as read takes its error for damping."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
import torch

from piga.diagnostics import DiagnoseConfig, analyse, fit
from tests.test_diagnostics import NOMINAL, planted


@pytest.fixture(scope="module")
def noisy():
    """Damping 0.2 read through 10 mrad of independent angle error (its velocities 0.28 rad/s off)."""
    return planted({"damping": 0.2}, n=150, t=30, noise=0.01)


def test_fitted_starts_remove_the_damping_bias_of_read_starts(noisy) -> None:
    w = fit.make_windows(noisy.theta, noisy.actions, np.flatnonzero(noisy.fit), 8, 2, noisy.dt)
    read = fit.fit_candidate(("damping",), {}, NOMINAL, w)
    fitted = fit.fit(read, NOMINAL, replace(w, fit_starts=True))
    assert read.values["b"] > 0.203  # measured 0.207 (0.215 on 300 sequences): biased up by the start velocities
    assert abs(fitted.values["b"] / 0.2 - 1) < 0.01 and abs(fitted.values["g"] / 10 - 1) < 0.003
    assert read.values["b"] - 0.2 > 3 * abs(fitted.values["b"] - 0.2)
    assert abs(read.values["g"] / 10 - 1) > 2 * abs(fitted.values["g"] / 10 - 1)  # g biased too


def test_fitted_starts_solve_each_window_and_leave_exact_data_alone() -> None:
    """On noise-free angles the read starts are the best ones; one-step windows never move them."""
    exact = planted({"damping": 0.2}, n=40, t=20, noise=0.0)
    w = fit.make_windows(exact.theta, exact.actions, np.arange(40), 8, 2, exact.dt)
    model = fit.Model(("damping",), 0, {"g": 10.0, "a": 1.0, "b": 0.2})
    d = fit.fitted_starts(model, NOMINAL, w, fit.parameters_of(model, NOMINAL))
    assert d.shape == (len(w.theta0), 2) and float(d.abs().max()) < 1e-8
    w1 = fit.make_windows(exact.theta, exact.actions, np.arange(40), 1, 1, exact.dt)
    same = fit.loss(model, NOMINAL, replace(w1, fit_starts=True))
    assert torch.equal(same, fit.loss(model, NOMINAL, w1))


def test_a_window_whose_simulation_overflows_keeps_its_starts() -> None:
    """A dm_control recording with a damping of 100 ended in exit 70: "torch.linalg.solve: The solver failed because
    the input matrix is singular" (its windows' simulation overflowed, so their Jacobians were not finite)."""
    exact = planted({"damping": 0.2}, n=20, t=20, noise=0.0)
    w = fit.make_windows(exact.theta, exact.actions, np.arange(20), 8, 2, exact.dt)
    model = fit.Model(("damping",), 0, {"g": 10.0, "a": 1.0, "b": 1e300})  # explicit damping at 1e300: overflow
    d = fit.fitted_starts(model, NOMINAL, w, fit.parameters_of(model, NOMINAL))
    assert d.shape == (len(w.theta0), 2) and bool(torch.isfinite(d).all())


def test_a_window_whose_system_is_singular_though_finite_keeps_its_starts() -> None:
    """dm_control's camera 0 read by a model of the face-on camera ended in exit 70 the same way: a finite Jacobian so
    large that adding the identity leaves the 2x2 system singular in float64."""
    huge = torch.tensor([[[1e300, 1e300], [1e300, 1e300]], [[2.0, 0.0], [0.0, 2.0]]], dtype=torch.float64)
    step = fit.gauss_newton_step(huge + torch.eye(2, dtype=torch.float64), torch.tensor([[1.0, 1.0], [2.0, 4.0]],
                                                                                         dtype=torch.float64))
    assert torch.equal(step[0], torch.zeros(2, dtype=torch.float64))  # kept
    assert torch.allclose(step[1], torch.tensor([2.0 / 3.0, 4.0 / 3.0], dtype=torch.float64))  # solved


@pytest.mark.slow
def test_the_option_refits_the_chosen_values(noisy) -> None:
    """``DiagnoseConfig.fit_starts``: the same choice (damping), its value refitted (read starts: b 7% high)."""
    fitted = analyse(noisy, NOMINAL, DiagnoseConfig(bootstrap=0, max_effects=1))  # on by default (the damping alone)
    assert DiagnoseConfig().fit_starts and DiagnoseConfig().matched_angles
    assert fitted.verdict_class == "damping", fitted.verdict
    assert abs(fitted.corrected["b"] / 0.2 - 1) < 0.01


@pytest.mark.slow
def test_matched_angles_read_the_chosen_values_on_the_matched_angles(noisy) -> None:
    """``DiagnoseConfig.matched_angles``: the selection on the encoder's angles (here 10 mrad of error), the
    chosen effects' values on the matched ones (here 2 mrad); without the option ``matched`` is not used.
    ``fit_starts`` is off here, so that only the angles differ."""
    matched = planted({"damping": 0.2}, n=150, t=30, noise=0.002).theta  # the same motion, read better
    config = DiagnoseConfig(bootstrap=0, fit_starts=False, matched_angles=True, max_effects=1)  # (the damping alone)
    on_matched = analyse(noisy, NOMINAL, config, matched=lambda: matched)
    assert on_matched.verdict_class == "damping", on_matched.verdict
    assert abs(on_matched.corrected["b"] / 0.2 - 1) < 0.01  # read on the encoder's angles: 0.207
    assert any("matching every frame to the decoder's renders" in n for n in on_matched.notes)
    plain = analyse(noisy, NOMINAL, replace(config, matched_angles=False), matched=lambda: matched)
    assert plain.corrected["b"] > 0.203 and not any("decoder's renders" in n for n in plain.notes)


@pytest.mark.slow
def test_a_sign_seen_only_on_the_matched_angles_moves_the_whole_diagnosis_onto_them() -> None:
    """An encoder that misreads the recording (here: angles that barely respond to the actions) misses the actuation's
    sign, and with it the selection misses what else there is; the matched angles show the reversed actuation: then the
    selection, the values and the gap are all done on them (dm_control filmed from the other side of the hinge, with
    its damping tripled, was named "flipped actuation" alone, at a free-run closure of -12.5%)."""
    from piga.diagnostics.vision import Camera, CameraFindings

    truth = planted({"gain": -1.0, "damping": 0.3}, n=40, t=20)
    misread = planted({"gain": 0.05}, n=40, t=20, noise=0.02)  # the same actions (seed), hardly any response
    camera = CameraFindings(Camera(), 0.0, 0.0, 0, 0, [], 1e-4, 1e-4, [])
    d = analyse(misread, NOMINAL, DiagnoseConfig(bootstrap=0, fit_starts=False, matched_angles=True, max_effects=1),
                camera=camera, matched=lambda: truth.theta)  # (the damping is the one effect of the dynamics)
    named = {e.effect: e.value for e in d.effects}
    assert "flip" in named and abs(named.get("damping", 0) / 0.3 - 1) < 0.05, d.verdict
    assert any("the selection, the values and the gap are all on those angles" in n for n in d.notes)
    assert d.vision.camera.angles == "matched"
