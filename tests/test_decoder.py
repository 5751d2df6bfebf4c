"""Tests of piga.world.decoder: shapes, coordinate consistency (the property that matters), gradients."""

from __future__ import annotations

import math

import pytest
import torch

from piga.world.decoder import Decoder, DecoderConfig


def _pixel_centres(size: int) -> tuple[torch.Tensor, torch.Tensor]:
    """x and y of every pixel centre, each (size, size); pixel i spans [i, i + 1]."""
    centres = torch.arange(size, dtype=torch.float32) + 0.5
    ys, xs = torch.meshgrid(centres, centres, indexing="ij")
    return xs, ys


def _blob_logits(size: int, centre: tuple[float, float], sigma: float = 1.5, peak: float = 4.0) -> torch.Tensor:
    """A round mask-logit blob in template pixels, (1, size, size): high at centre, low at the edge."""
    xs, ys = _pixel_centres(size)
    r2 = (xs - centre[0]) ** 2 + (ys - centre[1]) ** 2
    return (peak - r2 / (2 * sigma**2)).unsqueeze(0)


def _centroid(weight: torch.Tensor) -> tuple[float, float]:
    """(x, y) centroid in pixel coordinates of a non-negative (H, W) map."""
    xs, ys = _pixel_centres(weight.shape[-1])
    total = weight.sum()
    return float((weight * xs).sum() / total), float((weight * ys).sum() / total)


def _decoder(cfg: DecoderConfig, contents: torch.Tensor, masks: torch.Tensor) -> Decoder:
    """A decoder with the given object templates and a flat background (content 0.1, logit 0)."""
    torch.manual_seed(0)
    decoder = Decoder(cfg)
    size = cfg.image_size
    decoder.load_templates(
        contents,
        masks,
        background=torch.full((cfg.channels, size, size), 0.1),
        background_mask_logit=torch.zeros(1, size, size),
    )
    return decoder


def _flip_angle(dx: float, dy: float) -> float:
    """Angle of a display vector (dx right, dy down), 0 pointing up, counter-clockwise positive."""
    return math.atan2(-dx, -dy)


def test_output_shape_and_range() -> None:
    torch.manual_seed(0)
    cfg = DecoderConfig(image_size=32, channels=3, n_objects=2, coord_dim=2, template_size=16)
    decoder = Decoder(cfg)
    coords = torch.rand(5, 2, 2) * 32
    image = decoder(coords)
    assert image.shape == (5, 3, 32, 32)
    assert image.min() >= 0 and image.max() <= 1
    # Free leading axes: (B, T, N, D) -> (B, T, C, H, W), the same images.
    seq = decoder(coords.view(5, 1, 2, 2).expand(5, 4, 2, 2))
    assert seq.shape == (5, 4, 3, 32, 32)
    torch.testing.assert_close(seq[:, 2], image)

    parts = decoder.render_parts(coords)
    assert parts.contents.shape == (5, 2, 3, 32, 32)
    assert parts.masks.shape == (5, 3, 1, 32, 32)
    torch.testing.assert_close(parts.masks.sum(dim=1), torch.ones(5, 1, 32, 32))
    tpl = decoder.templates()
    assert tpl.contents.shape == (2, 3, 16, 16) and tpl.mask_logits.shape == (2, 1, 16, 16)
    assert tpl.background.shape == (3, 32, 32) and tpl.background_mask_logit.shape == (1, 32, 32)


def test_angle_decoder_shape_and_default_template_size() -> None:
    torch.manual_seed(0)
    decoder = Decoder(DecoderConfig(image_size=64, channels=1, n_objects=1, coord_dim=1))
    image = decoder(torch.randn(3, 1, 1))
    assert image.shape == (3, 1, 64, 64)
    assert decoder.templates().contents.shape == (1, 1, 64, 64)


@pytest.mark.parametrize("delta", [(3, -2), (-5, 4), (1, 0)])
def test_integer_shift_of_the_latent_shifts_the_image_exactly(delta: tuple[int, int]) -> None:
    cfg = DecoderConfig(image_size=32, channels=3, n_objects=2, coord_dim=2, template_size=10)
    gen = torch.Generator().manual_seed(1)
    contents = torch.rand(2, 3, 10, 10, generator=gen)
    masks = torch.randn(2, 1, 10, 10, generator=gen) * 3
    decoder = _decoder(cfg, contents, masks)

    dx, dy = delta
    coords = torch.tensor([[[12.37, 14.81], [18.2, 15.5]]])  # not on the pixel grid
    shifted = coords + torch.tensor([float(dx), float(dy)])
    with torch.no_grad():
        before = decoder(coords)[0]
        after = decoder(shifted)[0]
    # Both renderings keep the objects inside this crop, the rest is the flat background.
    rows, cols = slice(6, 26), slice(6, 26)
    rows_after = slice(rows.start + dy, rows.stop + dy)
    cols_after = slice(cols.start + dx, cols.stop + dx)
    torch.testing.assert_close(after[:, rows_after, cols_after], before[:, rows, cols], rtol=0, atol=1e-5)
    assert (before[:, rows, cols] - 0.1).abs().max() > 0.3  # the objects are really in the crop


@pytest.mark.parametrize("delta", [(0.3, -0.45), (2.71, 1.25), (-0.5, 0.5)])
def test_fractional_shift_moves_the_mask_centroid_by_exactly_delta(delta: tuple[float, float]) -> None:
    cfg = DecoderConfig(image_size=32, channels=1, n_objects=1, coord_dim=2, template_size=16)
    decoder = _decoder(cfg, torch.ones(1, 1, 16, 16), _blob_logits(16, (8.0, 8.0)).unsqueeze(0))
    coords = torch.tensor([[[13.1, 17.6]]])
    with torch.no_grad():
        before = _centroid(decoder.render_parts(coords).masks[0, 0, 0])
        after = _centroid(decoder.render_parts(coords + torch.tensor(delta)).masks[0, 0, 0])
    # The template's centre lands at the coordinates ...
    assert before == pytest.approx((13.1, 17.6), abs=0.05)
    # ... and moving the latent by delta moves the object by delta.
    assert after[0] - before[0] == pytest.approx(delta[0], abs=0.05)
    assert after[1] - before[1] == pytest.approx(delta[1], abs=0.05)


def test_object_is_absent_outside_its_template() -> None:
    cfg = DecoderConfig(image_size=32, channels=1, n_objects=1, coord_dim=2, template_size=8)
    # A template whose mask logit is high everywhere, right up to its edge.
    decoder = _decoder(cfg, torch.ones(1, 1, 8, 8), torch.full((1, 1, 8, 8), 5.0))
    with torch.no_grad():
        parts = decoder.render_parts(torch.tensor([[[16.0, 16.0]]]))
    mask = parts.masks[0, 0, 0]  # (H, W)
    assert mask[12:20, 12:20].min() > 0.99  # the 8x8 template covers pixels 12..19
    outside = mask.clone()
    outside[12:20, 12:20] = 0
    assert outside.max() < 1e-6


def test_rotation_is_counter_clockwise_as_displayed_about_the_image_centre() -> None:
    # A bright blob above the pivot at θ = 0 (the pendulum upright), pivot = image centre.
    cfg = DecoderConfig(image_size=32, channels=1, n_objects=1, coord_dim=1)
    masks = _blob_logits(32, (16.0, 8.0)).unsqueeze(0)
    decoder = _decoder(cfg, torch.ones(1, 1, 32, 32), masks)
    with torch.no_grad():
        up = _centroid(decoder.render_parts(torch.tensor([[[0.0]]])).masks[0, 0, 0])
        left = _centroid(decoder.render_parts(torch.tensor([[[math.pi / 2]]])).masks[0, 0, 0])
    assert up == pytest.approx((16.0, 8.0), abs=0.05)
    # θ = +π/2 puts it to the LEFT of the pivot (smaller x), as Gymnasium's pendulum.
    assert left == pytest.approx((8.0, 16.0), abs=0.05)

    # A quarter turn maps the pixel grid onto itself: rendering at θ + π/2 is the rendering at θ
    # rotated by 90° counter-clockwise (torch.rot90 from rows towards columns), pixel for pixel.
    theta = torch.tensor([[[0.37]]])
    with torch.no_grad():
        base = decoder(theta)
        turned = decoder(theta + math.pi / 2)
    torch.testing.assert_close(turned, torch.rot90(base, 1, dims=(-2, -1)), rtol=0, atol=1e-5)


@pytest.mark.parametrize("theta, delta", [(0.0, 0.3), (1.0, -0.7), (-2.5, 1.9)])
def test_changing_theta_rotates_by_exactly_delta_about_an_off_centre_pivot(theta: float, delta: float) -> None:
    pivot = (14.0, 19.0)
    cfg = DecoderConfig(image_size=36, channels=1, n_objects=1, coord_dim=1, template_size=24, pivot=pivot)
    masks = _blob_logits(24, (12.0, 5.0)).unsqueeze(0)  # 7 template pixels above the centre
    decoder = _decoder(cfg, torch.ones(1, 1, 24, 24), masks)

    def angle_and_radius(value: float) -> tuple[float, float]:
        with torch.no_grad():
            x, y = _centroid(decoder.render_parts(torch.tensor([[[value]]])).masks[0, 0, 0])
        dx, dy = x - pivot[0], y - pivot[1]
        return _flip_angle(dx, dy), math.hypot(dx, dy)

    a0, r0 = angle_and_radius(theta)
    a1, r1 = angle_and_radius(theta + delta)
    assert a0 == pytest.approx(math.remainder(theta, 2 * math.pi), abs=0.01)
    assert math.remainder(a1 - a0 - delta, 2 * math.pi) == pytest.approx(0.0, abs=0.01)
    assert r0 == pytest.approx(7.0, abs=0.05) and r1 == pytest.approx(r0, abs=0.05)  # the pivot is fixed


def test_scale_multiplies_distances_from_the_reference_point() -> None:
    cfg = DecoderConfig(image_size=32, channels=1, n_objects=1, coord_dim=1, init_scale=2.0)
    # 4 template pixels above the centre; narrow, so that at s = 2 it stays clear of the image edge.
    masks = _blob_logits(32, (16.0, 12.0), sigma=1.0).unsqueeze(0)
    decoder = _decoder(cfg, torch.ones(1, 1, 32, 32), masks)
    assert decoder.scale.item() == pytest.approx(2.0)
    with torch.no_grad():
        x, y = _centroid(decoder.render_parts(torch.tensor([[[0.0]]])).masks[0, 0, 0])
    assert (x, y) == pytest.approx((16.0, 8.0), abs=0.05)


def test_gradients_flow_to_coords_templates_and_scale() -> None:
    torch.manual_seed(0)
    for coord_dim in (1, 2):
        cfg = DecoderConfig(image_size=16, channels=3, n_objects=2, coord_dim=coord_dim, template_size=8)
        decoder = Decoder(cfg)
        coords = (torch.rand(3, 2, coord_dim) * 8 + 4).requires_grad_(True)
        target = torch.rand(3, 3, 16, 16)
        loss = (decoder(coords) - target).square().mean()
        loss.backward()
        assert coords.grad is not None and coords.grad.abs().sum() > 0
        assert decoder.log_scale.grad is not None and decoder.log_scale.grad.abs().sum() > 0
        for name, param in decoder.named_parameters():
            assert param.grad is not None and torch.isfinite(param.grad).all(), name
            assert param.grad.abs().sum() > 0, name


def test_config_and_input_validation() -> None:
    with pytest.raises(ValueError, match="coord_dim must be 1 \\(angle\\) or 2 \\(x, y\\), got 3"):
        DecoderConfig(image_size=32, channels=1, n_objects=1, coord_dim=3)
    with pytest.raises(ValueError, match="image_size must be an int >= 1, got 0"):
        DecoderConfig(image_size=0, channels=1, n_objects=1, coord_dim=2)
    with pytest.raises(ValueError, match="init_scale must be finite and > 0, got -1"):
        DecoderConfig(image_size=32, channels=1, n_objects=1, coord_dim=2, init_scale=-1.0)
    decoder = Decoder(DecoderConfig(image_size=16, channels=1, n_objects=2, coord_dim=2, template_size=8))
    with pytest.raises(ValueError, match=r"coords must have shape \(\.\.\., N=2, D=2\), got \(4, 3, 2\)"):
        decoder(torch.zeros(4, 3, 2))
    with pytest.raises(ValueError, match=r"contents must have shape \(2, 1, 8, 8\)"):
        decoder.load_templates(torch.zeros(2, 1, 16, 16), torch.zeros(2, 1, 8, 8))
