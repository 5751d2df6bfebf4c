"""dm_control's pendulum as a Gymnasium env (envs/dmc.py): the env checker, the picture against the
state, the physics against piga's form, the XML variants, collection, and the missing extra."""

from __future__ import annotations

import math
import subprocess
import sys

import numpy as np
import pytest

from envs.dmc import VIEW_HALF_SIDE, DMCPendulumConfig, MissingExtraError, make_dmc_pendulum

try:
    import dm_control  # noqa: F401
    HAVE_DMC = True
except ImportError:
    HAVE_DMC = False

needs_dmc = pytest.mark.skipif(not HAVE_DMC, reason="needs the optional extra piga[dmc]")


def pole_angle(env, frame: np.ndarray, background: np.ndarray) -> float:
    """The pole's angle as the frame shows it: the direction, from the pivot (the image centre), of
    the centroid of the pixels that differ from the background; 0 up, positive counter-clockwise."""
    diff = np.abs(frame.astype(np.float64) - background.astype(np.float64))  # (H, W)
    size = frame.shape[0]
    ys, xs = np.mgrid[0:size, 0:size] + 0.5
    weight = np.where(diff > 10, diff, 0.0)
    cx, cy = (weight * xs).sum() / weight.sum(), (weight * ys).sum() / weight.sum()
    return math.atan2(-(cx - size / 2), -(cy - size / 2))


def background_frame(env) -> np.ndarray:
    """The frame without the pendulum (its geoms made transparent), in gray as the env converts it."""
    import cv2

    physics = env.unwrapped.physics
    saved = physics.model.geom_rgba.copy()
    physics.model.geom_rgba[1:, 3] = 0.0  # every geom but the floor
    rgb = env.unwrapped.render()
    physics.model.geom_rgba[:] = saved
    return cv2.cvtColor(rgb, cv2.COLOR_RGB2GRAY)


def angle_error(a: float, b: float) -> float:
    return abs((a - b + math.pi) % (2 * math.pi) - math.pi)


@needs_dmc
def test_env_checker_passes():
    import gymnasium as gym
    from gymnasium.utils.env_checker import check_env

    import envs  # noqa: F401 - registers the ids

    env = gym.make("piga/DMCPendulum-v0", episode_length=5)
    check_env(env.unwrapped)
    obs, info = env.reset(seed=0)
    assert obs.shape == (1, 64, 64) and obs.dtype == np.uint8
    assert env.action_space.low[0] == -1 and env.action_space.high[0] == 1


@needs_dmc
@pytest.mark.parametrize("flip", ["none", "camera"])
def test_episode_renders_the_pendulum_where_the_state_says(flip):
    env = make_dmc_pendulum(flip=flip, episode_length=40)
    obs, info = env.reset(seed=3)
    background = background_frame(env)
    rng = np.random.default_rng(0)
    sign = -1.0 if flip == "camera" else 1.0
    errors, truncated, rewards = [], False, []
    while not truncated:
        seen = pole_angle(env, obs[-1], background)
        errors.append(angle_error(seen, sign * info["state"][0]))
        obs, reward, terminated, truncated, info = env.step(rng.uniform(-1, 1, size=1).astype(np.float32))
        assert not terminated and reward == info["dmc_reward"]
        rewards.append(reward)
    assert len(errors) == 40
    assert np.degrees(max(errors)) < 4.0, np.degrees(errors)


@needs_dmc
def test_reward_is_dmc_and_upright_scores_one_per_physics_step():
    env = make_dmc_pendulum(action_repeat=2)
    env.reset(seed=0, options={"state": [0.0, 0.0]})
    _, reward, _, _, _ = env.step(np.zeros(1, np.float32))
    assert reward == pytest.approx(2.0)  # two physics steps within 8 degrees of upright
    env.reset(seed=0, options={"state": [math.pi, 0.0]})
    _, reward, _, _, _ = env.step(np.zeros(1, np.float32))
    assert reward == 0.0
    assert DMCPendulumConfig().frames_per_episode * DMCPendulumConfig().action_repeat == 1000


@needs_dmc
@pytest.mark.parametrize("overrides", [{}, {"mass": 1.5, "length": 0.4, "damping": 0.3}, {"flip": "motor"}])
def test_physics_matches_pigas_form(overrides):
    """Free swing and torque response of MuJoCo against θ̈ = 1.5·g·sin θ + 3·a·s·u − 3·b·θ̇ in piga's units."""
    config = DMCPendulumConfig(action_repeat=1, **overrides)
    env = make_dmc_pendulum(config)
    params = config.piga_params()
    physics = env.unwrapped.physics
    for theta, speed, u in [(0.7, 0.0, 0.0), (-2.0, 3.0, 0.0), (1.0, -1.0, 1.0), (2.5, 0.5, -0.6)]:
        env.reset(seed=0, options={"state": [theta, speed]})
        env.step(np.array([u], np.float32))
        acc = (physics.data.qvel[0] - speed) / 0.02
        # MuJoCo's Euler treats damping implicitly: v' = v + h·(f - d·v') / I.
        sign = -1.0 if config.flip == "motor" else 1.0
        expected = (1.5 * params["g"] * math.sin(theta) + 3 * params["actuation_gain"] * sign * u
                    - 3 * params["damping"] * speed) / (1 + 0.02 * 3 * params["damping"])
        assert acc == pytest.approx(expected, rel=1e-6, abs=1e-6)


@needs_dmc
def test_length_variant_moves_the_tip_in_the_picture():
    tips = []
    for length in (0.3, 0.55):
        env = make_dmc_pendulum(length=length)
        obs, _ = env.reset(seed=0, options={"state": [math.pi / 2, 0.0]})  # horizontal, tip to the left
        background = background_frame(env)
        columns = np.nonzero((np.abs(obs[-1].astype(int) - background.astype(int)) > 10).any(axis=0))[0]
        tips.append(32 - columns.min())
    expected = [length * 32 / VIEW_HALF_SIDE for length in (0.3, 0.55)]
    assert tips[1] - tips[0] == pytest.approx(expected[1] - expected[0], abs=1.5)


@needs_dmc
def test_collect_from_the_dmc_env(tmp_path):
    from piga.cli.collect import main
    from piga.data.schema import inspect_dataset, load_states

    out = tmp_path / "dmc.h5"
    assert main(["--env", "piga/DMCPendulum-v0", "--out", str(out), "--sequences", "2", "--steps", "5",
                 "--workers", "1", "--quiet", "--env-option", "damping=0.2"]) == 0
    info = inspect_dataset(out)
    assert info.dt == pytest.approx(0.04)
    assert info.params["damping"] == pytest.approx(DMCPendulumConfig(damping=0.2).piga_params()["damping"])
    import h5py

    with h5py.File(out) as f:
        actions = f["actions"][:]
        assert f.attrs["env_id"] == "piga/DMCPendulum-v0"
    assert np.abs(actions).max() <= 1.0 and np.abs(actions).max() > 0.5
    assert np.isfinite(load_states(out, "train")).all()


@needs_dmc
def test_collect_with_its_default_workers_finishes_and_matches_one_worker(tmp_path):
    """piga-collect --env piga/DMCPendulum-v0 at its default --workers 2 waited for ever: Gymnasium's AsyncVectorEnv
    makes one env in the parent first, which renders through EGL, and workers forked after that hung in their first
    render. (Every other test here passes --workers 1.)"""
    import h5py

    frames = {}
    for workers in ("2", "1"):
        out = tmp_path / f"w{workers}.h5"
        done = subprocess.run([sys.executable, "-m", "piga.cli.collect", "--env", "piga/DMCPendulum-v0", "--out", str(out),
                               "--sequences", "4", "--steps", "5", "--split", "2,1,1", "--workers", workers, "--quiet"],
                              capture_output=True, text=True, timeout=120)
        assert done.returncode == 0 and done.stderr == "", done.stderr
        with h5py.File(out) as f:
            frames[workers] = f["frames"][:]
    assert np.array_equal(frames["2"], frames["1"])


def test_missing_extra_gives_one_clear_line(tmp_path):
    """With dm_control unimportable, the env raises MissingExtraError and piga-collect prints one line."""
    code = (
        "import sys; sys.modules['dm_control'] = None\n"
        "from piga.cli.collect import entry\n"
        f"sys.argv = ['piga-collect', '--env', 'piga/DMCPendulum-v0', '--out', {str(tmp_path / 'x.h5')!r}, '--workers', '1']\n"
        "entry()\n"
    )
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert result.returncode == 1
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and "install piga[dmc]" in lines[0], result.stderr
    assert not (tmp_path / "x.h5").exists()
    with pytest.MonkeyPatch.context() as mp:
        mp.setitem(sys.modules, "dm_control", None)
        mp.setitem(sys.modules, "dm_control.suite", None)
        mp.setitem(sys.modules, "dm_control.rl", None)
        with pytest.raises(MissingExtraError, match=r"install piga\[dmc\]"):
            make_dmc_pendulum()


@needs_dmc
def test_an_unknown_mujoco_gl_is_one_line_to_fix(tmp_path):
    """dm_control refuses MUJOCO_GL=garbage with a RuntimeError as it imports its renderer: an internal error (70)."""
    import os

    env = {**os.environ, "MUJOCO_GL": "garbage", "OMP_NUM_THREADS": "1"}
    result = subprocess.run(["piga-collect", "--env", "piga/DMCPendulum-v0", "--sequences", "4", "--steps", "6",
                             "--workers", "1", "--split", "2,1,1", "--out", str(tmp_path / "x.h5"), "--quiet"],
                            capture_output=True, text=True, timeout=120, env=env)
    assert result.returncode == 1
    assert result.stderr.strip() == ("piga-collect: error: MUJOCO_GL='garbage' names no renderer dm_control knows; unset "
                                     "it (piga then renders with egl) or set egl, osmesa or glfw"), result.stderr
    assert not (tmp_path / "x.h5").exists()


def test_config_refuses_bad_values():
    with pytest.raises(ValueError, match="flip"):
        DMCPendulumConfig(flip="sideways")
    with pytest.raises(ValueError, match="length"):
        DMCPendulumConfig(length=2.0)
    assert DMCPendulumConfig(action_repeat=4).dt == pytest.approx(0.08)
    with pytest.raises(ValueError, match="color"):
        DMCPendulumConfig(color="blue")
    with pytest.raises(ValueError, match="mass=1e\\+300 is out of range .*too weak for a frame to show"):
        DMCPendulumConfig(mass=1e300)  # a file whose actions are 0 in float32 was written
    for name in ("image_size", "frame_stack", "episode_length"):
        with pytest.raises(ValueError, match=f"{name}=1000000000000000000000000000000 is out of range"):
            DMCPendulumConfig(**{name: 10**30})
    with pytest.raises(ValueError, match="camera=fixed is dm_control's own camera"):
        DMCPendulumConfig(camera="fixed", flip="camera")
    from piga.data.collect import CollectConfig

    with pytest.raises(ValueError, match="piga's data files hold gray frames"):
        CollectConfig(env=DMCPendulumConfig(color="rgb"))


@needs_dmc
def test_the_fixed_camera_in_rgb_stacks_each_frames_channels_and_sees_the_swing():
    """camera="fixed" renders dm_control's camera 0, color="rgb" stacks each frame's R, G, B channel-first (oldest
    frame first), and the pole moves in that view as the hinge turns."""
    env = make_dmc_pendulum(camera="fixed", color="rgb", image_size=32, frame_stack=2)
    assert env.observation_space.shape == (6, 32, 32)
    obs, _ = env.reset(seed=0, options={"state": [0.0, 0.0]})
    assert obs.shape == (6, 32, 32) and obs.dtype == np.uint8
    np.testing.assert_array_equal(obs[3:], env.unwrapped.render().transpose(2, 0, 1))  # the newest frame, as rendered
    assert not np.array_equal(obs[3], obs[4])  # colour: the channels differ
    obs2, *_ = env.step(np.zeros(1, np.float32))
    np.testing.assert_array_equal(obs2[:3], obs[3:])  # the stack moved on by one frame
    upright = env.unwrapped.render()
    env.reset(options={"state": [math.pi / 2, 0.0]})
    assert np.abs(env.unwrapped.render().astype(int) - upright).max() > 50  # the swing is in view
    face = make_dmc_pendulum(color="rgb", image_size=32)
    face.reset(options={"state": [math.pi / 2, 0.0]})
    assert not np.array_equal(face.unwrapped.render(), env.unwrapped.render())  # another camera
    env.close()
    face.close()


def test_env_option_help_lists_every_key_and_refusals_name_the_flag(capsys: pytest.CaptureFixture[str]) -> None:
    """The help listed 6 of the 9 keys (not camera, camera_distance, color); a bad value was refused in the config's
    words ("DMCPendulumConfig.flip='sideways' is out of range")."""
    from piga.cli.collect import build_parser, dmc_config, env_option_keys

    assert {"camera", "camera_distance", "color", "flip", "mass"} <= set(env_option_keys())
    text = " ".join(build_parser().format_help().split())
    assert ", ".join(env_option_keys()) in text
    with pytest.raises(ValueError, match=r"^--env-option flip='sideways' is out of range"):
        dmc_config([("flip", "sideways")])


@pytest.mark.parametrize("episodes, said", [(1, "1 episode of 1000 physics steps of 0.02 s (score: sum of DMC's reward, "
                                                "max 1000), seed 4."),
                                            (3, "3 episodes of 1000 physics steps of 0.02 s (score: sum of DMC's "
                                                "reward, max 1000), seeds 4..6.")])
def test_the_dmc_table_counts_one_episode_and_its_seed_in_the_singular(episodes: int, said: str) -> None:
    """It read "1 episodes ..., seeds 0..0"."""
    from piga.control.dmc import DMCControlConfig, dmc_markdown

    assert said in dmc_markdown([], DMCControlConfig(episodes=episodes, seed=4), "c")
