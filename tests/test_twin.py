"""The twin that measures the floor of the gap: its physics, its pictures, its repeats; and the ridge fit."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from envs.pendulum import PixelPendulumConfig, make_pixel_pendulum
from piga.diagnostics import fit
from piga.diagnostics.residuals import ridge
from piga.diagnostics.twin import gap_closure, matched_angles, mean_gap_closure, render_angles, repeat_stale, twin_angles
from piga.diagnostics.vision import Camera
from piga.world.effects import CANDIDATES
from tests.test_diagnostics import NOMINAL, planted


@pytest.mark.parametrize("effects", [{}, {"damping": 0.2, "delay": 2}])
def test_the_twin_of_exact_data_is_the_data(effects: dict) -> None:
    obs = planted(effects, n=6, t=20, noise=0.0)
    values = {"g": 10.0, "a": 1.0, **({"b": 0.2} if "damping" in effects else {})}
    model = fit.Model(tuple(e for e in CANDIDATES if e in effects), effects.get("delay", 0), values)
    np.testing.assert_allclose(twin_angles(model, NOMINAL, obs.theta, obs.actions), obs.theta, atol=1e-9)
    # a wrong model's twin departs from the data
    wrong = fit.Model((), 0, {"g": 10.0, "a": 0.5})
    assert np.abs(twin_angles(wrong, NOMINAL, obs.theta, obs.actions) - obs.theta).max() > 0.05


def test_the_twin_is_rendered_as_the_env_renders() -> None:
    env = make_pixel_pendulum(PixelPendulumConfig())
    first, _ = env.reset(seed=0, options={"state": [2.5, 0.0]})
    second, _, _, _, info = env.step(np.array([1.5], np.float32))
    env.close()
    angles = np.array([[2.5, info["state"][0]]]) - 0.1  # model convention with φ = 0.1
    actions = np.array([[1.5, 0.0]])
    frames = render_angles(angles, actions, 0.1, 64, arrow=True)  # (1, 2, 64, 64)
    np.testing.assert_array_equal(frames[0, 0], first[0])
    np.testing.assert_array_equal(frames[0, 1], second[0])  # the arrow shows u_0
    no_arrow = render_angles(angles, actions, 0.1, 64, arrow=False)
    np.testing.assert_array_equal(no_arrow[0, 0], first[0])
    assert (no_arrow[0, 1] != second[0]).any()


def test_the_twin_draws_the_arrow_at_the_recordings_actuation_gain() -> None:
    """Gymnasium draws its torque arrow at the actuation gain times the command: a twin drawn at the training file's
    (gain 1) beside a recording at a gain of 2.5 matched its angles more cleanly than the recording's."""
    env = make_pixel_pendulum(PixelPendulumConfig(actuation_gain=2.5))
    first, _ = env.reset(seed=0, options={"state": [2.5, 0.0]})
    second, _, _, _, info = env.step(np.array([1.5], np.float32))
    env.close()
    angles, actions = np.array([[2.5, info["state"][0]]]), np.array([[1.5, 0.0]])
    frames = render_angles(angles, actions, 0.0, 64, arrow=True, arrow_gain=2.5)
    np.testing.assert_array_equal(frames[0, 1], second[0])
    assert (render_angles(angles, actions, 0.0, 64, arrow=True)[0, 1] != second[0]).any()


def test_a_twin_filmed_through_a_camera_is_matched_back_through_it() -> None:
    """The twin of angles matched through a fitted camera is filmed through that camera and matched as the recording
    was: its angles come back; the sensor noise is drawn from the seed (the same seed, the same angles) and blurs them."""
    from tests.test_vision import rod_model

    network = rod_model(32)
    angles = np.linspace(-2.5, 2.5, 12).reshape(2, 6)  # (n, T)
    with torch.no_grad():
        drawn = network.decoder(torch.as_tensor(angles, dtype=torch.float32)[..., None, None])[:, :, 0]  # (n, T, H, W)
    frames = (drawn.clamp(0, 1) * 255).round().to(torch.uint8).numpy()
    camera = Camera(blur=1.2, dx=0.7)
    clean = matched_angles(network, frames, camera, 0.0, seed=0)
    np.testing.assert_allclose(clean, angles, atol=0.06)  # (a 32 px rod: its matching is coarse)
    noisy = matched_angles(network, frames, camera, 20.0, seed=0)
    np.testing.assert_array_equal(noisy, matched_angles(network, frames, camera, 20.0, seed=0))
    assert np.abs(noisy - clean).mean() > 1e-3  # the noise moves the matched angles
    assert np.abs(matched_angles(network, frames, camera, 20.0, seed=1) - noisy).mean() > 1e-3


def test_stale_frames_repeat_in_the_twin() -> None:
    frames = np.arange(8, dtype=np.uint8).reshape(2, 4, 1, 1).repeat(2, 2)
    stale = np.array([[False, True, True, False], [False, False, False, True]])
    out = repeat_stale(frames.copy(), stale)
    assert out[0, :, 0, 0].tolist() == [0, 0, 0, 3] and out[1, :, 0, 0].tolist() == [4, 5, 6, 6]


def test_gap_closure_is_the_share_above_the_floor() -> None:
    assert gap_closure(1.0, 0.2, 0.1) == pytest.approx(0.8 / 0.9)
    assert gap_closure(0.1, 0.1, 0.2) is None  # no gap above the floor


def test_the_means_closure_is_not_a_ratio_of_noise() -> None:
    assert mean_gap_closure(1.0, 0.2, 0.1) == pytest.approx(0.8 / 0.9)
    assert mean_gap_closure(0.00073, 0.000626, 0.000729) is None  # was "13192%": no gap above the floor
    assert mean_gap_closure(1.0, 0.05, 0.1) == 1.0  # the corrected model at or below the floor: the gap is closed


def test_ridge_matches_least_squares_when_well_posed_and_stays_bounded_when_not() -> None:
    rng = np.random.default_rng(0)
    x = np.c_[rng.normal(size=(500, 3)), np.ones(500)]
    y = x @ np.array([1.0, -2.0, 0.5, 0.3]) + 0.1 * rng.normal(size=500)
    np.testing.assert_allclose(ridge(x, y), np.linalg.lstsq(x, y, rcond=None)[0], atol=0.02)
    # cos(kθ) of angles that only visit the bottom of the circle: nearly collinear columns
    th_fit, th_new = rng.uniform(2.6, 3.7, 400), rng.uniform(-np.pi, np.pi, 400)
    feats = lambda th: np.stack([np.cos(k * th) for k in range(1, 7)] + [np.ones_like(th)], 1)  # noqa: E731
    y_fit = 0.3 * np.sin(4 * th_fit) + rng.normal(size=400)
    coef = ridge(feats(th_fit), y_fit)
    y_new = 0.3 * np.sin(4 * th_new) + rng.normal(size=400)
    assert ((y_new - feats(th_new) @ coef) ** 2).mean() < 2 * (y_new**2).mean()


def test_the_floor_of_another_camera_is_drawn_by_the_decoder_only_when_it_re_renders_that_camera() -> None:
    from piga.diagnostics import DiagnoseConfig
    from piga.diagnostics.diagnose import twin_renderer

    config = DiagnoseConfig()
    assert twin_renderer(True, True, False, 5.0, config) == ("simulator", None)
    assert twin_renderer(False, True, False, 1.2, config) == ("decoder", None)
    for args in ((False, True, False, 3.0), (False, True, False, None), (False, False, False, 1.0), (False, True, True, 1.0)):
        source, note = twin_renderer(*args, config)
        assert source is None and note.startswith("no valid floor") and "raw" in note
    assert "3.0x worse" in twin_renderer(False, True, False, 3.0, config)[1]
    assert twin_renderer(True, False, False, None, config) == (None, None)


def test_the_decoder_twin_is_the_decoders_picture_in_8_bits() -> None:
    import torch

    from piga.diagnostics.twin import decoder_render, twin_floor
    from piga.world.model import ModelConfig, PhysicsModel
    from piga.io.runs import Nominal

    torch.manual_seed(0)
    network = PhysicsModel(ModelConfig(image_size=32)).eval()
    angles = np.linspace(-3, 3, 10).reshape(2, 5)
    frames = decoder_render(network, angles)
    assert frames.shape == (2, 5, 32, 32) and frames.dtype == np.uint8
    with torch.no_grad():
        expected = network.decoder(torch.tensor(angles, dtype=torch.float32)[..., None, None]).clamp(0, 1)[:, :, 0]
    np.testing.assert_allclose(frames / 255.0, expected.numpy(), atol=0.5 / 255 + 1e-6)
    with pytest.raises(ValueError, match="renderer"):
        twin_floor(network, fit.Model((), 0, {"g": 10.0, "a": 1.0}), Nominal(10.0, 1.0, 0.0, 0.05), angles,
                   np.zeros((2, 5)), None, 1, renderer="camera")


def test_the_decoder_twin_is_scaled_down_to_the_recordings_own_one_step_error() -> None:
    from piga.diagnostics.twin import TwinFloor, calibrate_floor

    floor = TwinFloor(np.array([2e-5, 8e-5, 1e-4]), np.array([5e-5, 1e-4]))
    half = calibrate_floor(floor, 1e-5)  # the recording's one-step error is half the twin's
    np.testing.assert_allclose(half.horizon, floor.horizon / 2)
    np.testing.assert_allclose(half.windows, floor.windows / 2)
    same = calibrate_floor(floor, 4e-5)  # never scaled up
    np.testing.assert_array_equal(same.windows, floor.windows)
