"""The composed model: shapes, loss, gradients into the physics."""

from __future__ import annotations

import pytest
import torch

from piga.world.model import ModelConfig, PhysicsModel, frames_to_float


@pytest.mark.parametrize("rec_frames", ["all", "input"])
def test_forward_shapes_and_gradients_reach_physics(rec_frames: str) -> None:
    torch.manual_seed(0)
    model = PhysicsModel(ModelConfig(rec_frames=rec_frames))
    frames = torch.randint(0, 256, (2, 14, 64, 64), dtype=torch.uint8)
    actions = torch.rand(2, 14, 1) * 4 - 2
    out = model(frames, actions)
    n_rec = 14 if rec_frames == "all" else 4
    assert out.pred.shape == (2, 10, 1, 64, 64) and out.rec.shape == (2, n_rec, 1, 64, 64)
    assert out.coords_pred.shape == (2, 10, 1, 1) and torch.isfinite(out.loss)
    out.loss.backward()
    assert model.system.log_g.grad is not None and model.system.log_g.grad.abs() > 0
    assert model.system.log_a.grad is not None and model.system.log_a.grad.abs() > 0


def test_starts_far_from_truth() -> None:
    params = PhysicsModel(ModelConfig()).physical_parameters()
    assert params["g"] == pytest.approx(1.0) and params["a"] == pytest.approx(0.3)


def test_shorter_horizon_and_actions_alignment() -> None:
    model = PhysicsModel(ModelConfig())
    frames = torch.zeros(1, 14, 64, 64, dtype=torch.uint8)
    actions = torch.zeros(1, 14, 1)
    assert model(frames, actions, pred_frames=3).pred.shape[1] == 3
    # the action after input frame L (index L-1) drives the first predicted frame
    coords = torch.zeros(1, 4, 1, 1)
    a1 = model.predict(coords, torch.ones(1, 2, 1), 2)
    a0 = model.predict(coords, torch.zeros(1, 2, 1), 2)
    assert (a1 - a0)[0, 0].item() == pytest.approx(3 * 0.3 * 0.05 * 0.05, rel=1e-4)


def test_frames_to_float_layouts() -> None:
    gray = torch.full((2, 3, 8, 8), 255, dtype=torch.uint8)
    assert frames_to_float(gray, 1).shape == (2, 3, 1, 8, 8) and frames_to_float(gray, 1).max() == 1.0
    colour = torch.zeros(2, 3, 8, 8, 3, dtype=torch.uint8)
    assert frames_to_float(colour, 3).shape == (2, 3, 3, 8, 8)
    with pytest.raises(ValueError, match="frames must be"):
        frames_to_float(colour, 1)


def test_config_validation() -> None:
    with pytest.raises(ValueError, match="unknown system"):
        ModelConfig(system="rocket")
    with pytest.raises(ValueError, match="rec_frames"):
        ModelConfig(rec_frames="some")


def test_trimmed_prediction_loss_ignores_the_worst_windows() -> None:
    torch.manual_seed(0)
    model = PhysicsModel(ModelConfig(pred_trim=0.25))
    frames = torch.randint(0, 256, (4, 14, 64, 64), dtype=torch.uint8)
    actions = torch.zeros(4, 14, 1)
    model.train()
    trimmed = model(frames, actions).loss_pred
    model.eval()  # evaluation reports the plain mean
    plain = model(frames, actions).loss_pred
    assert trimmed < plain
    with pytest.raises(ValueError, match="pred_trim"):
        ModelConfig(pred_trim=1.0)


def test_checkpoint_config_without_pivot_gate_reads_as_trained() -> None:
    """A checkpoint from before the gate existed was trained without it: it loads with the gate off."""
    legacy = {k: v for k, v in ModelConfig().to_dict().items() if k != "pivot_gate"}
    assert ModelConfig.from_dict(legacy).pivot_gate == (0.0, 0.0)
    assert ModelConfig.from_dict(ModelConfig().to_dict()) == ModelConfig()
