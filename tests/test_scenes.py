"""The paper's scenes: ground truth against fine references, rendering against /states, collection and its errors."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import h5py
import numpy as np
import pytest
import torch
from scipy.integrate import solve_ivp

from envs.scenes import SceneError, accelerations, draw_start, generate_sequence, render, scene_config, simulate
from piga.cli.collect import main as collect_main
from piga.data.collect_scenes import SceneCollectConfig, collect_scene
from piga.data.schema import inspect_dataset, load_states
from piga.world.physics import Bouncing, Euler, Gravity, Spring, rollout
from tests.helpers import assert_one_line, run_in_process

F64 = torch.float64


def _reference(config, p0: np.ndarray, v0: np.ndarray, steps: int) -> np.ndarray:
    """Positions (T, N, 2) of the exact ODE (scipy's DOP853 at rtol 1e-11), frame 0 = p0."""
    n = len(p0)

    def f(_: float, y: np.ndarray) -> np.ndarray:
        p = y[: 2 * n].reshape(n, 2)
        return np.concatenate([y[2 * n :], accelerations(config, p).ravel()])

    times = np.arange(steps) * config.dt
    sol = solve_ivp(f, (0, times[-1]), np.concatenate([p0.ravel(), v0.ravel()]), t_eval=times, method="DOP853",
                    rtol=1e-11, atol=1e-11)
    return sol.y[: 2 * n].T.reshape(steps, n, 2)


@pytest.mark.parametrize("scene, engine", [
    ("spring", lambda c: Spring(n_objects=2, k=c.params["k"], l=c.params["l"], dt=c.dt, learnable=False)),
    ("gravity", lambda c: Gravity(n_objects=3, g=c.params["g"], dt=c.dt, learnable=False)),
    ("digits-spring", lambda c: Spring(n_objects=2, k=c.params["k"], l=c.params["l"], dt=c.dt, learnable=False)),
])
def test_engine_and_ground_truth_converge_to_the_exact_motion(scene: str, engine) -> None:
    """The data's 10-substep ground truth is the model's engine at 10 substeps, and both approach the exact ODE."""
    config = scene_config(scene)
    steps = 20
    ps, vs = draw_start(config, np.random.default_rng(3), steps)
    exact = _reference(config, ps[0], vs[0], steps)
    system = engine(config).to(F64)
    system.set_parameters(**{k: v for k, v in config.params.items() if k != "m"})  # the logs in float64
    p0, v0 = torch.from_numpy(ps[0])[None], torch.from_numpy(vs[0])[None]
    errors = {}
    for m in (10, 100):
        model_p, _ = rollout(system, Euler(substeps=m), p0, v0, steps=steps - 1)
        model_p = np.concatenate([ps[:1], model_p[0].numpy()])
        truth_p, _ = simulate(config, ps[0], vs[0], steps, substeps=m)
        np.testing.assert_allclose(model_p, truth_p, rtol=0, atol=1e-9)  # the same integrator
        errors[m] = np.abs(truth_p - exact).max()
    np.testing.assert_allclose(ps, simulate(config, ps[0], vs[0], steps)[0])  # the data use 10 substeps
    scale = np.abs(exact - exact[0]).max()
    assert errors[100] < errors[10] / 5, errors  # first order: ~10x closer with 10x the substeps
    assert errors[10] < 0.05 * scale, (errors, scale)  # the data's ground truth is close to the exact motion


def test_bouncing_engine_matches_the_folded_free_flight() -> None:
    """Free flight reflected at [r, H - r] is a triangle wave; the engine and the ground truth both follow it."""
    config = scene_config("bouncing")
    steps = 25
    ps, vs = draw_start(config, np.random.default_rng(4), steps)
    low, high = config.radius, config.image_size - config.radius
    free = ps[0] + vs[0] * (np.arange(steps) * config.dt)[:, None, None] - low  # (T, N, 2)
    span = high - low
    folded = low + span - np.abs(np.mod(free, 2 * span) - span)  # the triangle wave of period 2·span
    np.testing.assert_allclose(ps, folded, atol=1e-9)
    system = Bouncing(n_objects=2, size=float(config.image_size), radius=config.radius, dt=config.dt).to(F64)
    model_p, _ = rollout(system, Euler(substeps=10), torch.from_numpy(ps[0])[None], torch.from_numpy(vs[0])[None],
                         steps=steps - 1)
    np.testing.assert_allclose(model_p[0].numpy(), ps[1:], atol=1e-9)


@pytest.mark.parametrize("scene", ["bouncing", "spring", "gravity"])
def test_rendered_balls_sit_at_their_states(scene: str) -> None:
    """Each ball's colour centroid is its state position, to 0.02 px, wherever the balls are apart."""
    config = scene_config(scene)
    ps, _ = draw_start(config, np.random.default_rng(5), 30)
    frames = render(config, ps).astype(float) / 255  # (T, H, W, 3)
    centres = np.arange(config.image_size) + 0.5
    d = np.sqrt(((ps[:, :, None] - ps[:, None]) ** 2).sum(-1)) + 1e9 * np.eye(config.n_objects)
    apart = (d.min(axis=(1, 2)) > 2 * config.radius + 2) & (ps > config.radius + 0.5).all(axis=(1, 2)) & (
        ps < config.image_size - config.radius - 0.5).all(axis=(1, 2))
    assert apart.sum() >= 5
    for j in range(config.n_objects):
        w = frames[apart][..., 2 - j]  # ball j is drawn in channel 2 - j
        total = w.sum(axis=(1, 2))
        x = (w * centres[None, None, :]).sum(axis=(1, 2)) / total
        y = (w * centres[None, :, None]).sum(axis=(1, 2)) / total
        np.testing.assert_allclose(np.stack([x, y], -1), ps[apart, j], atol=0.02)
        area = total.mean()
        assert abs(area - np.pi * config.radius**2) < 0.5  # anti-aliased: the coverage is the disk's area


def test_rendered_digits_move_with_their_states() -> None:
    """A digit's foreground centroid moves exactly as its state, to 0.3 px (digits are pasted on a 1/4 px grid)."""
    pytest.importorskip("sklearn", reason="the digits need the 'scenes' extra (scikit-learn)")
    config = scene_config("digits-spring")
    ps, _ = draw_start(config, np.random.default_rng(6), 12)
    frames = render(config, ps).astype(float) / 255
    background = render(replace(config, n_objects=2), np.full((1, 2, 2), -100.0))[0].astype(float) / 255
    centres = np.arange(config.image_size) + 0.5
    for j in range(2):
        alone = ps.copy()
        alone[:, 1 - j] = -100.0  # the other digit off the picture
        w = np.abs(render(config, alone).astype(float) / 255 - background).sum(-1)  # (T, H, W)
        total = w.sum(axis=(1, 2))
        c = np.stack([(w * centres[None, None]).sum((1, 2)) / total, (w * centres[None, :, None]).sum((1, 2)) / total], -1)
        inside = ((ps[:, j] > config.radius + 1) & (ps[:, j] < config.image_size - config.radius - 1)).all(-1)
        assert inside.sum() >= 3
        offset = c[inside] - ps[inside, j]  # the glyph's own centroid offset, the same in every frame
        np.testing.assert_allclose(offset, np.broadcast_to(np.median(offset, 0), offset.shape), atol=0.3)
    assert np.abs(frames - background).max() > 0.5  # the digits show


def test_scene_collection_is_the_schema_and_independent_of_workers(tmp_path: Path) -> None:
    config = SceneCollectConfig(scene=scene_config("spring", params={"k": 3.0}), sequences=5, steps=8, seed=2,
                                split=(3, 1, 1), workers=1)
    one = collect_scene(config, tmp_path / "a.h5", progress=False, command="t")
    two = collect_scene(replace(config, workers=2, batch=2), tmp_path / "b.h5", progress=False, command="t")
    info = inspect_dataset(one)
    assert (info.n_sequences, info.steps, info.image_shape, info.action_dim) == (5, 8, (32, 32, 3), 0)
    assert info.system == "spring" and info.dt == 0.3 and info.params == {"k": 3.0, "l": 6.0}
    assert info.attrs["n_objects"] == 2 and info.attrs["scene"] == "spring"
    assert info.attrs["state_names"] == ["x0", "y0", "x1", "y1", "vx0", "vy0", "vx1", "vy1"]
    with h5py.File(one) as a, h5py.File(two) as b:
        for key in ("frames", "states", "actions", "split"):
            assert a[key][()].tobytes() == b[key][()].tobytes(), key
    states = load_states(one, "train")  # positions follow the file's own physics
    ps = states[:, :, :4].reshape(3, 8, 2, 2)
    vs = states[:, :, 4:].reshape(3, 8, 2, 2)
    again, _ = simulate(config.scene, ps[0, 0], vs[0, 0], 8)
    np.testing.assert_allclose(ps[0], again, atol=1e-4)


@pytest.mark.parametrize("argv, needles", [
    (["--k", "3"], ["--k", "pendulum"]),
    (["--system", "gravity", "--k", "3"], ["gravity", "k"]),
    (["--system", "spring", "--image-size", "12"], ["too small", "2 objects"]),
    (["--system", "gravity", "--image-size", "16"], ["too small", "3 objects"]),
    (["--system", "spring", "--gravity", "3"], ["--gravity", "pendulum"]),
])
def test_collect_errors_are_one_line(argv: list[str], needles: list[str], tmp_path: Path,
                                     capsys: pytest.CaptureFixture[str]) -> None:
    code, _, err = run_in_process("piga-collect", collect_main, "--out", str(tmp_path / "x.h5"), *argv, capsys=capsys)
    assert_one_line(code, err, *needles)
    assert not (tmp_path / "x.h5").exists()


def test_a_start_that_cannot_avoid_the_walls_is_one_clear_error() -> None:
    config = scene_config("spring", speed=400.0, max_tries=64)
    with pytest.raises(SceneError, match="no start"):
        draw_start(config, np.random.default_rng(0), 30)


def test_force_shift_measures_the_forces_against_straight_lines() -> None:
    from envs.scenes import force_shift

    rng = np.random.default_rng(0)
    config = scene_config("gravity")
    _, states = generate_sequence(config, rng, 8)  # (T, 4N)
    assert force_shift(config, states[None]) > 1.0  # the scene's own g bends the paths by pixels in 8 frames
    n, t = config.n_objects, 8
    v = np.tile([2.0, -1.0], n)  # (2N,) one velocity per ball, kept
    p = 10 + v * config.dt * np.arange(t)[:, None]  # (T, 2N): straight lines
    straight = np.concatenate([p, np.tile(v, (t, 1))], axis=1)[None].astype(np.float32)
    assert force_shift(config, straight) < 1e-5
    assert force_shift(scene_config("bouncing"), straight[..., : 8]) == 0.0


def test_a_scene_too_fast_for_its_frames_is_warned_of(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """--k 2222 (under the substeps' limit) turned the spring 20 rad a frame: frames that alias the motion, written
    without a word. Beyond π rad a frame one warning line says the k that keeps under it."""
    from envs.scenes import aliasing_warning

    argv = ["--system", "spring", "--sequences", "3", "--steps", "6", "--split", "1,1,1", "--workers", "1", "--quiet"]
    code, out, err = run_in_process("piga-collect", collect_main, "--out", str(tmp_path / "k.h5"), "--k", "100", *argv,
                                    capsys=capsys)
    assert code == 0 and out.startswith("wrote ") and err.count("\n") == 1, err
    assert err.startswith("piga-collect: warning: spring: with k = 100, l = 6 the balls oscillate at 14.1 rad/s, 4.24 "
                          "rad per frame of 0.3 s, beyond the π rad per frame"), err
    assert "give k below 54.83 (the scene's own: k = 4, l = 6)" in err
    code, _, err = run_in_process("piga-collect", collect_main, "--out", str(tmp_path / "own.h5"), "--k", "54", *argv,
                                  capsys=capsys)
    assert code == 0 and err == ""  # 3.12 rad a frame
    gravity = scene_config("gravity")
    _, states = generate_sequence(gravity, np.random.default_rng(0), 8)  # (T, 4N)
    assert aliasing_warning(gravity, states[None]) is None  # the scene's own g: well under a rad a frame
    close = states[None].copy()
    close[..., 2:4] = close[..., 0:2] + 0.5  # two balls 0.71 px apart: √(2·60/0.71³) = 18.4 rad/s
    assert "the balls orbit each other at up to 18.4 rad/s, 9.21 rad per frame of 0.5 s" in aliasing_warning(gravity, close)
    assert "give g below 6.979 (the scene's own: g = 60, m = 1)" in aliasing_warning(gravity, close)
