"""The unseen-region ablation's black-box decoders: ``--decoder deconv`` and ``--decoder broadcast``."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import h5py
import pytest
import torch

from envs.scenes import scene_config
from piga.cli import train as cli
from piga.data.collect_scenes import SceneCollectConfig, collect_scene
from piga.training.train import SCENE_PRESETS
from piga.world.conv_decoders import BroadcastDecoder, DeconvDecoder
from piga.world.variants import build_model
from tests.helpers import run_in_process


@pytest.fixture(scope="module")
def half_spring(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """6 half-spring sequences x 30 frames, split 4/1/1."""
    path = tmp_path_factory.mktemp("half") / "half.h5"
    config = SceneCollectConfig(scene=scene_config("spring", half=True), sequences=6, steps=30, seed=5, workers=1,
                                split=(4, 1, 1))
    return collect_scene(config, path, command="test", progress=False)


@pytest.mark.parametrize("cls", [DeconvDecoder, BroadcastDecoder])
def test_draws_frames_in_range_from_coordinates_of_any_leading_shape(cls: type) -> None:
    torch.manual_seed(0)
    decoder = cls(16, 3, 2, 2)
    coords = torch.rand(4, 5, 2, 2) * 16  # (B, T, N, D)
    frames = decoder(coords).detach()
    assert frames.shape == (4, 5, 3, 16, 16)
    assert 0 <= float(frames.min()) and float(frames.max()) <= 1
    assert not torch.allclose(frames[0, 0], frames[0, 1])  # the drawing depends on the coordinates
    assert decoder(coords[0, 0]).shape == (3, 16, 16)  # no leading axes
    background = torch.rand(3, 16, 16) * 0.8 + 0.1
    decoder.init_background(background)
    assert torch.allclose(torch.sigmoid(decoder.background_logit), background, atol=1e-5)


@pytest.mark.parametrize("name", ["deconv", "broadcast"])
def test_one_training_step_lowers_the_loss_on_a_tiny_file(name: str, half_spring: Path) -> None:
    torch.manual_seed(0)
    model_config = replace(SCENE_PRESETS["spring"]["fast"].model, decoder=name, image_size=32, channels=3,
                           n_objects=2, dt=0.3, template_size=16)
    model = build_model(model_config)
    with h5py.File(half_spring, "r") as f:
        frames = torch.from_numpy(f["frames"][:4, : model_config.window])  # (4, L+T, H, W, 3) uint8
    actions = torch.zeros(4, model_config.window, 0)
    optimiser = torch.optim.Adam(model.parameters(), lr=1e-3)
    before = model(frames, actions).loss
    optimiser.zero_grad()
    before.backward()
    optimiser.step()
    with torch.no_grad():
        after = model(frames, actions).loss
    assert after.item() < before.item()


def test_decoder_choices_come_from_the_model_config(capsys: pytest.CaptureFixture[str]) -> None:
    help_text = cli.build_parser().format_help()
    assert "{st,mlp,deconv,broadcast}" in help_text
    code, _, err = run_in_process("piga-train-model", cli.main, "data.h5", "--out", "run", "--decoder", "dense",
                                  capsys=capsys)
    lines = err.strip().splitlines()
    assert code == 1 and len(lines) == 1 and "invalid choice: 'dense'" in lines[0], err
