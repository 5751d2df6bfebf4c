"""The camera side of the diagnosis: its camera model matches the effect wrappers, and its fits recover planted effects."""

from __future__ import annotations

import math

import cv2
import numpy as np
import pytest
import torch

from envs.pendulum import PixelPendulumConfig, make_pixel_pendulum
from piga.diagnostics import fit
from piga.diagnostics import repeats as R
from piga.diagnostics import vision as V
from piga.world.model import ModelConfig, PhysicsModel

SIZE = 32


def rod_model(size: int, gray: float = 0.2) -> PhysicsModel:
    """A pendulum model whose decoder draws a rod of ``gray`` (dark by default) up from the pivot on a white
    background."""
    torch.manual_seed(0)
    m = PhysicsModel(ModelConfig(image_size=size, template_hidden=8))
    ys, xs = torch.meshgrid(torch.arange(size) + 0.5, torch.arange(size) + 0.5, indexing="ij")
    rod = ((xs - size / 2).abs() < 1.6) & (ys > 4) & (ys < size / 2 + 1)  # upright at θ = 0
    mask = torch.where(rod, 8.0, -8.0)[None, None]  # (N, 1, h, h) logits
    m.decoder.load_templates(torch.full((1, 1, size, size), gray), mask, background=torch.ones(1, size, size),
                             background_mask_logit=torch.zeros(1, size, size))
    return m.eval()


@pytest.fixture(scope="module")
def model() -> PhysicsModel:
    return rod_model(SIZE)


def _renders(model: PhysicsModel, theta: torch.Tensor) -> np.ndarray:
    """(M,) angles -> (M, H, W) uint8 frames of the decoder, as a camera would record them."""
    with torch.no_grad():
        x = model.decoder(theta[:, None, None].float())[:, 0]
    return np.rint(x.clamp(0, 1).numpy() * 255).astype(np.uint8)


@pytest.mark.parametrize("sigma", [0.7, 1.5, 2.3])
def test_camera_blur_is_cv2_gaussian_blur(sigma: float) -> None:
    x = np.random.default_rng(0).random((SIZE, SIZE)).astype(np.float32)
    ours = V.Camera(blur=sigma).apply(torch.from_numpy(x)[None, None])[0, 0].numpy()
    np.testing.assert_allclose(ours, cv2.GaussianBlur(x, (0, 0), sigma), atol=2e-5)


@pytest.mark.parametrize("dx, dy", [(1.5, 1.5), (-2.0, -2.0), (0.3, -1.2)])
def test_camera_shift_is_the_warp_of_the_shift_effect(dx: float, dy: float) -> None:
    x = np.random.default_rng(1).random((SIZE, SIZE)).astype(np.float32)
    ours = V.Camera(dx=dx, dy=dy).apply(torch.from_numpy(x)[None, None])[0, 0].numpy()
    theirs = cv2.warpAffine(x, np.array([[1.0, 0.0, dx], [0.0, 1.0, dy]]), (SIZE, SIZE), flags=cv2.INTER_LINEAR,
                            borderMode=cv2.BORDER_REPLICATE)
    np.testing.assert_allclose(ours, theirs, atol=1e-4)


@pytest.mark.parametrize("zoom, dx, dy", [(0.9, 0.0, 0.0), (1.15, 0.0, 0.0), (0.85, 1.5, -0.5)])
def test_camera_zoom_is_the_warp_about_the_image_centre(zoom: float, dx: float, dy: float) -> None:
    """A zoom about the image centre, then the shift: cv2's warp of a camera nearer or farther (the frame-edit's)."""
    x = np.random.default_rng(1).random((SIZE, SIZE)).astype(np.float32)
    ours = V.Camera(zoom=zoom, dx=dx, dy=dy).apply(torch.from_numpy(x)[None, None])[0, 0].numpy()
    c = SIZE / 2 - 0.5
    warp = cv2.getRotationMatrix2D((c, c), 0, zoom) + np.array([[0.0, 0.0, dx], [0.0, 0.0, dy]])
    theirs = cv2.warpAffine(x, warp, (SIZE, SIZE), flags=cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
    np.testing.assert_allclose(ours, theirs, atol=1e-4)


@pytest.mark.parametrize("camera", [V.Camera(blur=4.0, zoom=1.2, dx=-4.5, dy=2.3, exposure=1.3),
                                    V.Camera(blur=0.6, dx=0.4), V.Camera(zoom=0.8, dy=-1.7), V.Camera(blur=9.0)])
def test_camera_matrices_are_the_2d_convolution_and_warp(camera: V.Camera) -> None:
    """Every axis as one matrix (the rows, then the columns) gives what the depthwise convolutions with reflected
    padding and affine_grid + grid_sample give, on a batch of RGB frames, at the borders too (σ 9: the radius held at
    the 11 px image's 10)."""
    import torch.nn.functional as F

    x = torch.from_numpy(np.random.default_rng(4).random((3, 3, 11 if camera.blur > 5 else SIZE, SIZE)).astype(np.float32))
    n, c, h, w = x.shape
    ref = x
    for axis, size in ((-1, w), (-2, h)):
        r = max(1, min(math.ceil(4 * camera.blur), size - 1))
        k = torch.exp(-0.5 * (torch.arange(-r, r + 1, dtype=x.dtype) / camera.blur) ** 2)
        kernel = (k / k.sum()).view(1, 1, *((1, -1) if axis == -1 else (-1, 1))).expand(c, 1, -1, -1)
        pad = (r, r, 0, 0) if axis == -1 else (0, 0, r, r)
        ref = F.conv2d(F.pad(ref, pad, mode="reflect"), kernel, groups=c) if camera.blur else ref
    z = 1 / camera.zoom
    omega = torch.tensor([[z, 0.0, -2 * z * camera.dx / w], [0.0, z, -2 * z * camera.dy / h]])
    grid = F.affine_grid(omega.expand(n, 2, 3), [n, c, h, w], align_corners=False)
    ref = F.grid_sample(ref, grid, mode="bilinear", padding_mode="border", align_corners=False)
    ref = (ref * camera.exposure).clamp(max=1.0)
    torch.testing.assert_close(camera.apply(x), ref, atol=2e-6, rtol=0)


def test_matching_recovers_the_angle_of_each_frame() -> None:
    model = rod_model(64)
    theta = torch.rand(64, generator=torch.Generator().manual_seed(2)) * 2 * math.pi - math.pi
    found, err = V.match(V.angle_table(model), V._flat(_renders(model, theta)))
    miss = torch.remainder(found - theta + math.pi, 2 * math.pi) - math.pi
    # a 0.5° table refined by a parabola: the hard-edged rod's distance is V-shaped near its minimum
    assert miss.abs().max() < math.radians(0.5) and miss.abs().mean() < math.radians(0.15), miss
    assert float(err.mean()) < 5e-4


@pytest.mark.parametrize("camera", [V.Camera(blur=1.3), V.Camera(dx=1.5, dy=1.5), V.Camera(dx=-2.0, dy=-2.0)])
def test_fit_camera_recovers_a_planted_blur_or_shift(model: PhysicsModel, camera: V.Camera) -> None:
    theta = torch.rand(150, generator=torch.Generator().manual_seed(3)) * 2 * math.pi - math.pi
    frames = _renders(model, theta)
    if camera.blur:  # the effect wrappers' own operations, on uint8 frames
        frames = np.stack([cv2.GaussianBlur(f, (0, 0), camera.blur) for f in frames])
    else:
        shift = np.array([[1.0, 0.0, camera.dx], [0.0, 1.0, camera.dy]])
        frames = np.stack([cv2.warpAffine(f, shift, (SIZE, SIZE), flags=cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
                           for f in frames])
    x = V._flat(frames)
    fitted = V.fit_camera(model, x, blur=bool(camera.blur), shift=not camera.blur)
    for name in ("blur", "dx", "dy"):
        assert getattr(fitted, name) == pytest.approx(getattr(camera, name), abs=0.08), fitted
    assert V.matched_error(model, fitted, x) < 0.2 * V.matched_error(model, V.Camera(), x)


@pytest.mark.parametrize("zoom", [0.9, 1.1])
def test_fit_camera_recovers_a_planted_zoom(model: PhysicsModel, zoom: float) -> None:
    theta = torch.rand(150, generator=torch.Generator().manual_seed(3)) * 2 * math.pi - math.pi
    c = SIZE / 2 - 0.5
    frames = np.stack([cv2.warpAffine(f, cv2.getRotationMatrix2D((c, c), 0, zoom), (SIZE, SIZE), flags=cv2.INTER_LINEAR,
                                      borderMode=cv2.BORDER_REPLICATE) for f in _renders(model, theta)])
    x = V._flat(frames)
    fitted = V.fit_camera(model, x, blur=False, shift=False, zoom=True, rounds=1)
    assert fitted.zoom == pytest.approx(zoom, abs=0.01) and fitted.material(V.CameraConfig()) == {"zoom"}
    assert V.matched_error(model, fitted, x) < 0.3 * V.matched_error(model, V.Camera(), x)
    clean = V.fit_camera(model, V._flat(_renders(model, theta)), blur=False, shift=False, zoom=True, rounds=1)
    assert abs(clean.zoom - 1) < V.CameraConfig().min_zoom, clean


def test_a_clean_recording_gains_nothing_from_a_camera(model: PhysicsModel) -> None:
    theta = torch.rand(150, generator=torch.Generator().manual_seed(4)) * 2 * math.pi - math.pi
    x = V._flat(_renders(model, theta))
    fitted = V.fit_camera(model, x, rounds=1)
    assert abs(fitted.dx) < 0.3 and abs(fitted.dy) < 0.3, fitted
    # a hard-edged rod likes a touch of blur against aliasing, but far below the 10% the diagnosis asks
    assert V.matched_error(model, fitted, x) > (1 - V.CameraConfig().min_drop) * V.matched_error(model, V.Camera(), x)


@pytest.mark.parametrize("std", [0.0, 3.0, 12.0])
def test_noise_level_recovers_planted_noise_clipped_at_white(model: PhysicsModel, std: float) -> None:
    theta = torch.rand(200, generator=torch.Generator().manual_seed(5)) * 2 * math.pi - math.pi
    frames = _renders(model, theta).astype(np.float64)
    noisy = np.clip(np.rint(frames + std * np.random.default_rng(6).normal(size=frames.shape)), 0, 255).astype(np.uint8)
    still = V.static_pixels(model, margin=1)
    assert still.sum() > 50 and not still[SIZE // 2, SIZE // 2]
    s, ci = V.noise_level(noisy, still, interval=True)
    assert s == pytest.approx(std, rel=0.05, abs=0.05)
    if std:
        assert ci[0] < s < ci[1]


def test_still_pixels_survive_a_decoder_that_leaks_a_few_gray_levels(model: PhysicsModel, monkeypatch) -> None:
    """A decoder that leaks up to 2 gray levels of its template across the image (as trained models do)
    still leaves pixels "at its background" for the noise estimate, and the noise is still measured."""
    clean = V.angle_table(model, V.Camera(), 180)
    rng = np.random.default_rng(0)
    on = (np.arange(180) % 3 == 0)[:, None]  # a third of the angles leak 1-2 gray levels on every pixel
    leak = torch.as_tensor(on * rng.uniform(1 / 255, 2 / 255, (1, clean.renders.shape[1])), dtype=clean.renders.dtype)
    monkeypatch.setattr(V, "angle_table", lambda *args, **kwargs: V.AngleTable(clean.angles, clean.renders + leak))
    still = V.static_pixels(model, margin=1)
    assert still.sum() > 50 and not still[SIZE // 2, SIZE // 2]
    assert not V.static_pixels(model, margin=1, tolerance=0.5 / 255).any()  # the old rule found none
    theta = torch.rand(200, generator=torch.Generator().manual_seed(5)) * 2 * math.pi - math.pi
    frames = _renders(model, theta).astype(np.float64)
    noisy = np.clip(np.rint(frames + 12 * np.random.default_rng(6).normal(size=frames.shape)), 0, 255).astype(np.uint8)
    assert V.noise_level(noisy, still) == pytest.approx(12, rel=0.05)


@pytest.mark.slow
def test_stale_frames_come_from_the_drop_and_delay_wrappers() -> None:
    def frames(effects: dict) -> np.ndarray:
        env = make_pixel_pendulum(PixelPendulumConfig(image_size=32, effects=tuple(effects.items())))
        rng = np.random.default_rng(0)
        out = []
        for ep in range(12):
            obs, _ = env.reset(seed=ep)
            seq = [obs[-1]]
            for _ in range(29):
                obs, *_ = env.step(rng.uniform(-2, 2, 1).astype(np.float32))
                seq.append(obs[-1])
            out.append(np.stack(seq))
        env.close()
        return np.stack(out)  # (N, T, H, W)

    clean = R.stale_frames(frames({}))
    assert not clean.any()
    dropped = R.stale_frames(frames({"frame_drop": 0.3}))
    assert 0.2 < dropped[:, 1:].mean() < 0.4 and R.leading_repeats(dropped) == 0
    delayed = R.stale_frames(frames({"frame_delay": 2}))
    assert R.leading_repeats(delayed) == 2 and not delayed[:, 3:].any()


def test_repeat_sources_and_windows_over_repeated_frames() -> None:
    stale = np.zeros((2, 20), bool)
    stale[0, [8, 9]] = True
    np.testing.assert_array_equal(R.repeat_sources(stale)[0, 6:11], [6, 7, 7, 7, 10])
    theta = np.arange(20.0)[None].repeat(2, 0)
    actions = np.zeros((2, 20))
    w = fit.make_windows(theta, actions, np.arange(2), None, 20, 0.05, stale, repeat=True)
    # frames 5..19 after the start at 4: frames 8 and 9 repeat frame 7 (the third prediction)
    np.testing.assert_array_equal(w.source[0, :6].numpy(), [1, 2, 3, 3, 3, 6])
    one = fit.make_windows(theta, actions, np.arange(2), 1, 1, 0.05, stale)
    starts = one.theta0[one.sequence == 0].numpy()
    assert not {8.0, 9.0, 10.0} & set(starts)  # a start needs frames s - 1 and s fresh
    assert float(one.mask[(one.sequence == 0) & (one.theta0 == 7.0)].sum()) == 0  # its target, frame 8, is stale


def test_wilson_interval_covers_the_proportion() -> None:
    lo, hi = R.wilson(30, 300)
    assert lo < 0.1 < hi and hi - lo < 0.08


def test_an_agent_with_a_camera_reads_angles_through_it(model: PhysicsModel) -> None:
    from agents.mpc import PigaMPCAgent
    from piga.control.corrected import CameraReader

    theta = torch.tensor([0.30, 0.34, 0.38, 0.42, 0.46])  # 0.04 rad per 0.05 s step
    frames = np.stack([cv2.GaussianBlur(f, (0, 0), 1.5) for f in _renders(model, theta)])
    agent = PigaMPCAgent(model, reader=CameraReader(model, V.Camera(blur=1.5)))
    angle, speed = agent.estimate_state(frames[:4])  # L = 4 frames
    assert angle == pytest.approx(0.42, abs=0.02)
    assert speed == pytest.approx(0.8, abs=0.4)
    moved_on = agent.estimate_state(frames[1:])  # the next step: only the new frame is read
    assert moved_on[0] == pytest.approx(0.46, abs=0.02)
    fresh = PigaMPCAgent(model, reader=CameraReader(model, V.Camera(blur=1.5))).estimate_state(frames[1:])
    assert moved_on == pytest.approx(fresh, abs=1e-4)  # float32 matching, one frame vs a batch


def test_noise_level_on_a_gray_background() -> None:
    rng = np.random.default_rng(7)
    frames = np.clip(np.rint(120 + 6.0 * rng.normal(size=(400, 8, 8))), 0, 255).astype(np.uint8)
    frames[:, :, :4] = np.clip(np.rint(3 + 6.0 * rng.normal(size=(400, 8, 4))), 0, 255)  # clipped at black
    assert V.noise_level(frames, np.ones((8, 8), bool)) == pytest.approx(6.0, rel=0.05)


def test_a_codec_copy_is_a_repeat_but_motion_is_not() -> None:
    rng = np.random.default_rng(8)
    first = rng.integers(10, 240, (1, 1, 16, 16)).astype(np.uint8)
    copy = (first.astype(int) + rng.integers(-1, 2, first.shape)).astype(np.uint8)  # re-encoded: off by 1 level
    moved = first.copy()
    moved[..., 3, 4] += 12  # one pixel of a moving edge
    stale = R.stale_frames(np.concatenate([first, copy, moved], axis=1))
    np.testing.assert_array_equal(stale[0], [False, True, False])

