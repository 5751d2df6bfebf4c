"""Encoder readouts and the velocity estimator."""

from __future__ import annotations

import math

import pytest
import torch

from piga.world.encoder import Encoder, EncoderConfig, estimate_background
from piga.world.velocity import VelocityConfig, VelocityEstimator, wrap_angle


def _rod_image(theta: float, size: int = 64, length: float = 14.0) -> torch.Tensor:
    """A dark anti-aliased rod from the centre, counter-clockwise θ from straight up, on white. (1, H, W)"""
    ys, xs = torch.meshgrid(torch.arange(size) + 0.5, torch.arange(size) + 0.5, indexing="ij")
    c = size / 2
    dx, dy = -math.sin(theta), -math.cos(theta)  # unit vector of the rod in image coordinates
    px, py = xs - c, ys - c
    along = (px * dx + py * dy).clamp(0, length)
    dist = ((px - along * dx) ** 2 + (py - along * dy) ** 2).sqrt()
    return (1 - 0.7 * (1.5 - dist).clamp(0, 1))[None]


@pytest.mark.parametrize("theta", [0.0, 0.7, math.pi / 2, 2.5, -1.2, -3.0])
def test_centroid_reads_angle_counter_clockwise_from_up(theta: float) -> None:
    enc = Encoder(EncoderConfig(), background=torch.ones(1, 64, 64))
    with torch.no_grad():
        enc.masks.out.weight.zero_()  # uniform masks: the readout alone
        enc.masks.out.bias.zero_()
        got = enc(_rod_image(theta)[None])[0, 0, 0].item()
    assert abs(math.remainder(got - theta, 2 * math.pi)) < math.radians(1.0)


def test_angle_reference_shifts_the_zero() -> None:
    enc = Encoder(EncoderConfig(angle_reference=1.0), background=torch.ones(1, 64, 64))
    got = enc(_rod_image(0.3)[None])[0, 0, 0].item()
    assert got == pytest.approx(0.3 - 1.0, abs=0.02)


def test_centroid_cartesian_finds_blob() -> None:
    enc = Encoder(EncoderConfig(image_size=32, channels=3, n_objects=1, coord_dim=2))
    with torch.no_grad():
        enc.masks.out.weight.zero_()
        enc.masks.out.bias.zero_()
    img = torch.zeros(1, 3, 32, 32)
    img[0, :, 10:13, 20:23] = 1.0  # centre at x = 21.5, y = 11.5
    assert enc(img)[0, 0].tolist() == pytest.approx([21.5, 11.5], abs=1e-3)


@pytest.mark.parametrize("readout, dim", [("centroid", 1), ("centroid", 2), ("regress", 1), ("regress", 2)])
def test_shapes_and_gradients(readout: str, dim: int) -> None:
    enc = Encoder(EncoderConfig(image_size=32, channels=3, n_objects=2, coord_dim=dim, readout=readout))
    x = torch.rand(5, 3, 32, 32)
    coords, masks = enc.encode(x)
    assert coords.shape == (5, 2, dim) and masks.shape == (5, 3, 32, 32)
    assert torch.allclose(masks.sum(1), torch.ones(5, 32, 32), atol=1e-5)
    coords.sum().backward()
    assert all(p.grad is not None for p in enc.parameters() if p.requires_grad)
    if readout == "regress" and dim == 2:
        assert coords.min() >= 0 and coords.max() <= 32


def test_bad_config() -> None:
    with pytest.raises(ValueError, match="readout"):
        EncoderConfig(readout="argmax")
    with pytest.raises(ValueError, match="background"):
        Encoder(EncoderConfig(), background=torch.ones(3, 64, 64))


def test_background_is_the_median() -> None:
    frames = torch.full((9, 1, 8, 8), 0.8)
    for i in range(9):  # a blob that moves never occupies a pixel in most frames
        frames[i, 0, i % 8, (2 * i) % 8] = 0.0
    assert torch.allclose(estimate_background(frames), torch.full((1, 8, 8), 0.8))


def test_velocity_starts_as_backward_difference_and_wraps() -> None:
    est = VelocityEstimator(VelocityConfig(input_frames=4, dt=0.05))
    theta = torch.tensor([3.05, 3.10, 3.15, 3.20 - 2 * math.pi]).view(1, 4, 1, 1)  # crossing +π
    assert est(theta).item() == pytest.approx(0.05 / 0.05, abs=1e-4)
    assert wrap_angle(torch.tensor([math.pi + 0.1])).item() == pytest.approx(-math.pi + 0.1, abs=1e-6)
    cart = VelocityEstimator(VelocityConfig(input_frames=3, n_objects=2, coord_dim=2, dt=0.5, image_size=32))
    p = torch.tensor([[0.0, 1.0], [5.0, 5.0]]).view(1, 1, 2, 2) + torch.arange(3.0).view(1, 3, 1, 1)
    assert torch.allclose(cart(p), torch.full((1, 2, 2), 2.0))  # 1 px per frame / 0.5 s
    with pytest.raises(ValueError, match="expects"):
        est(torch.zeros(1, 3, 1, 1))


def _gymnasium_frames(states_actions: list[tuple[float, float]], arrow: bool) -> torch.Tensor:
    """Gymnasium's pendulum, rendered at θ after one step of u from (θ, 0): (B, 1, 64, 64) in [0, 1] and true θ (B,)."""
    import numpy as np

    from envs.pendulum import PixelPendulumConfig, make_pixel_pendulum

    env = make_pixel_pendulum(PixelPendulumConfig(draw_torque_arrow=arrow))
    env.reset(seed=0)
    frames, thetas = [], []
    for theta, u in states_actions:
        env.unwrapped.state = np.array([theta, 0.0])
        obs, *_ = env.step(np.array([u], dtype=np.float32))
        frames.append(torch.from_numpy(obs[-1].astype(np.float32) / 255))
        thetas.append(float(env.unwrapped.state[0]))
    env.close()
    return torch.stack(frames)[:, None], torch.tensor(thetas)


def test_pivot_gate_makes_the_reading_blind_to_the_torque_arrow() -> None:
    """Near upright, full torque: with the gate the arrow changes nothing; without it, degrees."""
    cases = [(theta, u) for theta in (-0.2, -0.05, 0.0, 0.1, 0.25) for u in (-2.0, -1.0, 1.0, 2.0)]
    with_arrow, thetas = _gymnasium_frames(cases, arrow=True)
    without, _ = _gymnasium_frames(cases, arrow=False)
    background = torch.ones(1, 64, 64)
    background[:, 28:36, 28:36] = without[:, :, 28:36, 28:36].median(0).values  # the pivot's disc
    shifts = {}
    for gate in ((0.125, 0.16), (0.0, 0.0)):
        enc = Encoder(EncoderConfig(pivot_gate=gate), background=background)
        with torch.no_grad():
            enc.masks.out.weight.zero_()  # uniform masks: the readout alone
            enc.masks.out.bias.zero_()
            a, b = enc(with_arrow)[:, 0, 0], enc(without)[:, 0, 0]
        shifts[gate] = (a - b).abs().max().item()
        assert (b - thetas).abs().max().item() < math.radians(1.0)  # both read the rod right without an arrow
    assert shifts[(0.125, 0.16)] < 1e-5
    assert shifts[(0.0, 0.0)] > math.radians(1.0)


def test_pivot_gate_is_validated() -> None:
    with pytest.raises(ValueError, match="pivot_gate"):
        EncoderConfig(pivot_gate=(0.2, 0.1))
