"""What the diagnosis says about the picture: sensor noise against a change of the picture, and frames that the model
cannot read."""

from __future__ import annotations

import math
from pathlib import Path
from types import SimpleNamespace

import h5py
import numpy as np
import pytest
import torch

from piga.diagnostics import vision as V
from piga.diagnostics.diagnose import DiagnoseConfig, summarise_vision
from tests.test_vision import SIZE, _renders, rod_model

N, T = 24, 16


@pytest.fixture(scope="module")
def model():
    return rod_model(SIZE)


def _recording(path: Path, model, change: str) -> Path:
    """A file of N swinging sequences of T frames from the rod model's decoder, with sensor noise or a shadow drawn on."""
    rng = np.random.default_rng(3)
    t = np.arange(T)
    theta = rng.uniform(-math.pi, math.pi, (N, 1)) + 0.3 * np.sin(0.5 * t + rng.uniform(0, 6, (N, 1)))  # (N, T)
    frames = _renders(model, torch.from_numpy(theta.ravel())).astype(np.float64).reshape(N, T, SIZE, SIZE)
    if change == "noise":
        frames += 3.0 * rng.normal(size=frames.shape)
    else:  # a soft dark blob that drifts across the picture, as a moving shadow does
        ys, xs = np.mgrid[0:SIZE, 0:SIZE]
        cx = rng.uniform(0, SIZE, (N, 1)) + 1.5 * t  # (N, T)
        blob = np.exp(-((xs - cx[..., None, None] % SIZE) ** 2 + (ys - SIZE / 4) ** 2) / (2 * 3.0**2))
        frames -= 40 * blob
    with h5py.File(path, "w") as f:
        f["frames"] = np.clip(np.rint(frames), 0, 255).astype(np.uint8)
    return path


@pytest.mark.parametrize("change", ["noise", "shadow"])
def test_a_moving_shadow_is_not_named_sensor_noise(model, tmp_path: Path, change: str) -> None:
    """The still pixels' spread is named noise only where it does not persist from frame to frame: dm_control with
    shadows on read "noise 2.5 gray levels", from a shadow that crosses the pixels the pendulum never reaches."""
    path = _recording(tmp_path / "rec.h5", model, change)
    fit = np.arange(N) < 16
    found = V.camera_stage(model, str(path), np.zeros((N, T)), fit, None)
    assert found.noise > V.CameraConfig().min_noise  # both spread the still pixels
    named = {e["effect"] for e in found.effects}
    config = DiagnoseConfig()
    _, notes = summarise_vision(SimpleNamespace(rec_mse=np.ones(3)), 1.0, found, None,
                                [SimpleNamespace(effect=e) for e in named], config)
    persist = [n for n in notes if "persist from frame to frame" in n]
    if change == "noise":
        assert abs(found.noise_correlation) < 0.1 and found.noise == pytest.approx(3.0, rel=0.1)
        assert named == {"noise"} and found.rematched and not persist
    else:
        assert found.noise_correlation > config.camera.max_noise_correlation
        assert "noise" not in named and not found.rematched
        assert len(persist) == 1 and "not sensor noise" in persist[0] and f"{found.noise:.2f} gray levels" in persist[0]


def test_repeated_frames_do_not_hide_sensor_noise(model, tmp_path: Path) -> None:
    """A repeated frame (a dropped frame) repeats its noise: the repeats are left out of the correlation."""
    path = _recording(tmp_path / "rec.h5", model, "noise")
    with h5py.File(path, "a") as f:
        frames = f["frames"][...]
        stale = (np.arange(T) % 3 != 0)[None].repeat(N, 0)  # (N, T) two frames in three repeat the one before
        for t in range(1, T):
            frames[stale[:, t], t] = frames[stale[:, t], t - 1]
        f["frames"][...] = frames
    found = V.camera_stage(model, str(path), np.zeros((N, T)), np.arange(N) < 16, stale)
    assert abs(found.noise_correlation) < 0.1 and "noise" in {e["effect"] for e in found.effects}
