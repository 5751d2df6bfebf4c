"""The pixel pendulum: checkers, settings, dynamics in info, and the torque arrow."""

from __future__ import annotations

import math
import warnings

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import envs
from envs import PixelPendulumConfig, make_pixel_pendulum


def test_gymnasium_check_env() -> None:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        check_env(gym.make("piga/PixelPendulum-v0"), skip_render_check=False)
        # as Gymnasium recommends, on the base env: it makes the env again in each render mode the metadata lists
        # (Pendulum-v1's said "human" too, which the pixel pendulum refuses)
        check_env(gym.make("piga/PixelPendulum-v0").unwrapped, skip_render_check=False)


def test_sb3_check_env() -> None:
    from stable_baselines3.common.env_checker import check_env as sb3_check_env

    env = gym.make("piga/PixelPendulumStack4-v0")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        sb3_check_env(env)


def test_observation_is_gray_uint8_stack() -> None:
    env = make_pixel_pendulum(PixelPendulumConfig(frame_stack=3, image_size=48))
    obs, info = env.reset(seed=0)
    assert obs.shape == (3, 48, 48) and obs.dtype == np.uint8
    assert info["state"].shape == (2,)
    assert obs.min() < 128 < obs.max()  # a dark pendulum on a white background


def test_state_follows_pendulum_equation_with_gravity_and_gain() -> None:
    g, mult, gain = 8.0, 1.5, 0.7
    env = gym.make("piga/PixelPendulum-v0", gravity=g, gravity_mult=mult, actuation_gain=gain, max_speed=0.5)
    _, info = env.reset(seed=5)
    rng = np.random.default_rng(0)
    for _ in range(20):
        th, thdot = info["state"]
        u = rng.uniform(-2, 2)
        _, _, _, _, info = env.step(np.array([u], np.float32))
        new_thdot = np.clip(thdot + (1.5 * g * mult * math.sin(th) + 3 * gain * np.float32(u)) * 0.05, -8, 8)
        assert info["state"][1] == pytest.approx(new_thdot, abs=1e-5)
        assert info["state"][0] == pytest.approx(th + new_thdot * 0.05, abs=1e-5)


def test_gain_above_one_is_not_cut_by_pendulum_clip() -> None:
    env = make_pixel_pendulum(actuation_gain=1.5, max_speed=0.0, max_angle=0.0)
    env.reset(seed=0)
    env.step(np.array([2.0], np.float32))
    assert env.unwrapped.last_u == pytest.approx(3.0)
    env.step(np.array([5.0], np.float32))  # outside [-2, 2]: clipped to 2 before the gain
    assert env.unwrapped.last_u == pytest.approx(3.0)


def test_reset_ranges_are_respected() -> None:
    env = make_pixel_pendulum(max_angle=0.3, max_speed=6.0)
    states = np.array([env.reset(seed=s)[1]["state"] for s in range(200)])
    assert np.abs(states[:, 0]).max() <= 0.3 and np.abs(states[:, 1]).max() <= 6.0
    assert np.abs(states[:, 1]).max() > 4.0  # the paper's wide speed range is actually used


def test_torque_arrow_can_be_hidden() -> None:
    frames = {}
    for arrow in (True, False):
        env = make_pixel_pendulum(draw_torque_arrow=arrow, max_angle=0.0, max_speed=0.0)
        env.reset(seed=0)
        frames[arrow] = env.step(np.array([2.0], np.float32))[0][-1]
    env = make_pixel_pendulum(draw_torque_arrow=False, max_angle=0.0, max_speed=0.0)
    env.reset(seed=0)
    no_arrow_no_torque = env.step(np.array([0.0], np.float32))[0][-1]
    assert (frames[True] != frames[False]).sum() > 20  # the arrow is drawn by default
    # Without the arrow, the frame depends only on the state, which barely moved in one step.
    assert np.abs(frames[False].astype(int) - no_arrow_no_torque).max() < 60


@pytest.mark.parametrize(
    "field, value",
    [("gravity", 0.0), ("gravity", -1.0), ("gravity_mult", 0.0), ("actuation_gain", -2.0), ("frame_stack", 0),
     ("max_speed", 9.0), ("max_angle", 4.0), ("image_size", 4), ("gravity", float("nan"))],
)
def test_bad_config_names_the_field(field: str, value: float) -> None:
    with pytest.raises(ValueError, match=field):
        PixelPendulumConfig(**{field: value})


def test_only_rgb_array_render_mode() -> None:
    with pytest.raises(ValueError, match="render_mode"):
        make_pixel_pendulum(render_mode="human")


def test_registered_ids() -> None:
    assert "piga/PixelPendulum-v0" in gym.registry and "piga/PixelPendulumStack4-v0" in gym.registry
    assert gym.make("piga/PixelPendulumStack4-v0").observation_space.shape == (4, 64, 64)
    # the torque limit piga samples and clips with is Gymnasium's own
    assert envs.MAX_ACTION == gym.make("Pendulum-v1").unwrapped.max_torque


def test_reset_to_an_exact_state_shows_it_in_the_first_frame() -> None:
    env = make_pixel_pendulum(draw_torque_arrow=False)
    hanging, info = env.reset(seed=0, options={"state": [math.pi, 0.0]})
    assert info["state"].tolist() == [math.pi, 0.0]
    upright, _ = env.reset(seed=0, options={"state": [0.0, 0.0]})
    rows = np.flatnonzero((255 - hanging[-1].astype(int)).sum(1) > 100)
    rows_up = np.flatnonzero((255 - upright[-1].astype(int)).sum(1) > 100)
    assert rows.mean() > 32 > rows_up.mean()  # the rod hangs below the pivot, or stands above it
    with pytest.raises(ValueError, match="state"):
        env.reset(options={"state": [1.0]})
