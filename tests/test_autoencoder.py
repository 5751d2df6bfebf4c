"""The frame autoencoder behind "DDPG from a latent": its codes must carry the pendulum, not collapse."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import torch

from agents.sb3.autoencoder import (
    AutoencoderConfig,
    autoencoder_seconds,
    load_autoencoder,
    train_autoencoder,
)
from piga.data.schema import read_sequences


@pytest.mark.slow  # 400 steps of training (15 s alone); by default the collapsing layout is refused
# (test_an_autoencoder_of_the_collapsing_layout_is_refused) and a latent run trains on the codes (tests/test_ddpg.py)
def test_codes_carry_the_pendulum_instead_of_collapsing_to_the_mean_frame(tiny_data: Path, tmp_path: Path) -> None:
    """The textbook layout (tanh bottleneck, sigmoid decoder) stalls at drawing the mean frame (MSE
    equal to the pixel variance) with every code saturated at +-1: DDPG would see a constant."""
    torch.set_num_threads(1)
    path = tmp_path / "ae.pt"
    train_autoencoder(tiny_data, AutoencoderConfig(steps=400, depth=8, batch_size=32), path, progress=False)
    model = load_autoencoder(path)
    frames, _ = read_sequences(tiny_data, "train")
    x = torch.from_numpy(frames.reshape(-1, 1, 64, 64)).float() / 255.0  # (N·T, 1, 64, 64)
    with torch.no_grad():
        codes = model.encode(x).numpy()  # (N·T, Z) in [-1, 1]
        mse = float(((model(x) - x) ** 2).mean())
    mean_frame_mse = float(((x - x.mean(0)) ** 2).mean())
    assert mse < 0.5 * mean_frame_mse, (mse, mean_frame_mse)
    assert codes.std(0).min() > 0.2, codes.std(0)  # standardised, then tanh(. / 2): about 0.4 per dimension
    assert np.abs(codes).max() < 1 and np.abs(codes.mean(0)).max() < 0.2, codes.mean(0)
    assert np.allclose(model.encode_frame(frames[0, 0]), codes[0], atol=1e-5)
    assert 0 < autoencoder_seconds(path) < 600  # recorded for the DDPG run's compute


@pytest.mark.slow
def test_an_autoencoder_of_the_collapsing_layout_is_refused(tiny_data: Path, tmp_path: Path) -> None:
    path = tmp_path / "ae.pt"
    train_autoencoder(tiny_data, AutoencoderConfig(steps=1, depth=4, batch_size=2), path, progress=False)
    payload = torch.load(path, weights_only=False)
    del payload["model"]["code_std"]
    torch.save(payload, path)
    with pytest.raises(ValueError, match="old, collapsing layout"):
        load_autoencoder(path)


def test_a_file_larger_than_memory_is_streamed_with_the_same_batches(tiny_data: Path, tmp_path: Path,
                                                                     monkeypatch: pytest.MonkeyPatch) -> None:
    from agents.sb3 import autoencoder
    from piga.data.windows import SequenceReader

    torch.set_num_threads(1)
    config = AutoencoderConfig(steps=30, depth=4, batch_size=8)
    whole, _ = train_autoencoder(tiny_data, config, tmp_path / "whole.pt", progress=False, device="cpu")
    reads: list[int] = []
    monkeypatch.setattr(autoencoder, "loads_whole", lambda frame_bytes, available: False)
    read = SequenceReader._read
    monkeypatch.setattr(SequenceReader, "_read", lambda self, i: reads.append(i) or read(self, i))
    streamed, _ = train_autoencoder(tiny_data, config, tmp_path / "streamed.pt", progress=False, device="cpu")
    assert reads, "the streamed run read no sequence through the cache"
    for (name, a), b in zip(whole.state_dict().items(), streamed.state_dict().values()):
        assert torch.equal(a, b), name
