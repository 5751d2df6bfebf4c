"""Unmodelled effects: each wrapper against its equation, their combinations, parsing, and piga-collect --effect."""

from __future__ import annotations

import json
import math
import warnings
from dataclasses import replace
from pathlib import Path
from typing import Any

import cv2
import gymnasium as gym
import h5py
import numpy as np
import pytest

from envs import EFFECTS, PixelPendulumConfig, make_pixel_pendulum, parse_effect
from envs.effects import (
    STAGES,
    ActionDelay,
    CoulombFriction,
    EffectSpec,
    FrameBlur,
    ViscousDamping,
    normalize_effects,
)
from piga.data.collect import CollectConfig, collect
from tests.helpers import run_in_process

DT, G = 0.05, 10.0
START = [2.0, 3.0]  # θ, θ̇: fast enough for friction, damping and the speed clip to matter
ACTIONS = [1.5, -0.3, 2.0, 0.1, -1.8, 2.5, -2.0, 0.5]  # 2.5 is outside [-2, 2] and clipped first


def expected_states(effects: dict[str, float], start: list[float], actions: list[float], gain: float = 1.0) -> np.ndarray:
    """The module docstring's equations, written out independently: float64 (T + 1, 2)."""
    th, thd = start
    k = int(effects.get("delay", 0))
    commanded = [float(np.clip(np.float32(u), -2, 2)) for u in actions]
    v_max = effects.get("speed_clip", 8.0)
    out = [(th, thd)]
    for t in range(len(actions)):
        u = commanded[t - k] if t >= k else 0.0
        if "deadzone" in effects:
            u = math.copysign(max(abs(u) - effects["deadzone"], 0.0), u)
        if "saturation" in effects:
            u = min(max(u, -effects["saturation"]), effects["saturation"])
        u *= effects.get("gain", 1.0)
        tau = gain * u
        tau += -effects.get("damping", 0.0) * thd
        tau += -effects.get("friction", 0.0) * math.tanh(thd / 0.1)
        tau += effects.get("bias", 0.0)
        thd = min(max(thd + DT * (1.5 * G * math.sin(th) + 3 * tau), -v_max), v_max)
        th = th + DT * thd
        out.append((th, thd))
    return np.array(out)


def rollout(effects: dict[str, float], start: list[float] = START, actions: list[float] = ACTIONS, seed: int = 0,
            image_size: int = 8, **config: Any) -> tuple[np.ndarray, np.ndarray]:
    """info["state"] (T + 1, 2) and the observed frames (T + 1, H, W) of the wrapped env."""
    env = make_pixel_pendulum(image_size=image_size, effects=effects, **config)
    obs, info = env.reset(seed=seed, options={"state": start})
    states, frames = [info["state"]], [obs[-1]]
    for u in actions:
        obs, _, _, _, info = env.step(np.array([u], np.float32))
        states.append(info["state"])
        frames.append(obs[-1])
    env.close()
    return np.array(states), np.array(frames)


# ---------------------------------------------------------------------------------------------
# Dynamics
# ---------------------------------------------------------------------------------------------

DYNAMICS_CASES = [
    {"delay": 1},
    {"delay": 3},
    {"deadzone": 0.5},
    {"saturation": 0.8},
    {"gain": 1.7},
    {"gain": 0.6},
    {"damping": 0.4},
    {"friction": 0.3},
    {"bias": -0.7},
    {"speed_clip": 3.2},
    {"delay": 2, "deadzone": 0.4, "saturation": 1.2, "gain": 1.4},
    {"damping": 0.3, "friction": 0.2, "bias": 0.5, "speed_clip": 3.5},
    {"delay": 1, "gain": 1.5, "damping": 0.2},
]


@pytest.mark.parametrize("effects", DYNAMICS_CASES, ids=lambda e: ",".join(f"{k}={v}" for k, v in e.items()))
def test_dynamics_follow_the_equations(effects: dict[str, float]) -> None:
    states, _ = rollout(effects)
    want = expected_states(effects, START, ACTIONS)
    np.testing.assert_allclose(states, want, rtol=0, atol=1e-5)
    # the effect changes the motion: it is not the nominal trajectory
    assert np.abs(want - expected_states({}, START, ACTIONS)).max() > 1e-3


def test_effects_with_actuation_gain_above_one_are_not_cut_by_pendulum_clip() -> None:
    effects = {"gain": 1.3, "damping": 0.3}
    env = make_pixel_pendulum(image_size=8, actuation_gain=1.5, effects=effects)
    assert env.unwrapped.max_torque == math.inf  # ActuationGain did not lower what the inner wrappers raised
    states, _ = rollout(effects, actuation_gain=1.5)
    np.testing.assert_allclose(states, expected_states(effects, START, ACTIONS, gain=1.5), atol=1e-5)
    assert env.unwrapped.max_speed == 8  # no speed clip asked for


def test_delay_acts_as_zero_for_the_first_steps_and_reset_clears_it() -> None:
    k = 3
    delayed, _ = rollout({"delay": k})
    idle, _ = rollout({}, actions=[0.0] * k)
    np.testing.assert_allclose(delayed[: k + 1], idle, atol=1e-12)
    env = make_pixel_pendulum(image_size=8, effects={"delay": 1})
    env.reset(seed=0, options={"state": [0.0, 0.0]})
    env.step(np.array([2.0], np.float32))
    env.reset(seed=0, options={"state": [0.0, 0.0]})  # the queued 2.0 is forgotten
    _, _, _, _, info = env.step(np.array([0.0], np.float32))
    assert info["state"].tolist() == [0.0, 0.0]


def test_no_effects_is_the_plain_env() -> None:
    plain = make_pixel_pendulum(image_size=16)
    assert repr(plain) == repr(make_pixel_pendulum(image_size=16, effects=()))
    assert not any(spec.wrapper.__name__ in repr(plain) for spec in EFFECTS.values())
    assert plain.unwrapped.max_torque == 2.0 and plain.unwrapped.max_speed == 8
    obs, info = plain.reset(seed=0, options={"state": START})
    states, frames = [info["state"]], [obs[-1]]
    for u in ACTIONS:
        obs, _, _, _, info = plain.step(np.array([u], np.float32))
        states.append(info["state"])
        frames.append(obs[-1])
    got_states, got_frames = rollout({}, image_size=16)
    assert got_states.tobytes() == np.array(states).tobytes() and got_frames.tobytes() == np.array(frames).tobytes()
    np.testing.assert_allclose(got_states, expected_states({}, START, ACTIONS), atol=1e-5)


# ---------------------------------------------------------------------------------------------
# Vision
# ---------------------------------------------------------------------------------------------

SIZE = 32


@pytest.fixture(scope="module")
def plain() -> tuple[np.ndarray, np.ndarray]:
    """The nominal run that the vision effects see: states (T + 1, 2) and frames (T + 1, 32, 32)."""
    return rollout({}, image_size=SIZE)


def test_blur(plain: tuple[np.ndarray, np.ndarray]) -> None:
    states, frames = rollout({"blur": 1.5}, image_size=SIZE)
    assert states.tobytes() == plain[0].tobytes()
    for got, clean in zip(frames, plain[1]):
        assert got.tobytes() == cv2.GaussianBlur(clean, (0, 0), 1.5).tobytes()


class _StillFrame(gym.Env):
    """A camera looking at a fixed picture: observation = ``picture`` (uint8 (H, W))."""

    def __init__(self, picture: np.ndarray):
        self.picture = picture
        self.observation_space = gym.spaces.Box(0, 255, picture.shape, np.uint8)
        self.action_space = gym.spaces.Box(-2, 2, (1,), np.float32)

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        super().reset(seed=seed)
        return self.picture.copy(), {}

    def step(self, action: Any):
        return self.picture.copy(), 0.0, False, False, {}


def test_blur_is_a_gaussian_of_that_sigma() -> None:
    sigma = 2.0
    edge = np.zeros((9, 40), np.uint8)
    edge[:, 20:] = 255  # a step between columns 19 and 20
    blurred, _ = FrameBlur(_StillFrame(edge), sigma).reset()
    x = np.arange(40) - 19.5
    profile = 255 * 0.5 * (1 + np.vectorize(math.erf)(x / (sigma * math.sqrt(2))))  # 255 Φ(x / σ)
    assert np.abs(blurred[4].astype(float) - profile).max() <= 2.5  # uint8 rounding, 3σ kernel cut


@pytest.mark.parametrize("p", [3, -2])
def test_shift_moves_the_picture_right_and_down(plain: tuple[np.ndarray, np.ndarray], p: int) -> None:
    _, frames = rollout({"shift": p}, image_size=SIZE)
    rows = np.clip(np.arange(SIZE) - p, 0, SIZE - 1)  # x'[r, c] = x[r - p, c - p], border replicated
    for got, clean in zip(frames, plain[1]):
        assert got.tobytes() == clean[np.ix_(rows, rows)].tobytes()


@pytest.mark.parametrize("k", [0.85, 1.3])
def test_exposure_multiplies_every_level_and_clips_at_white(plain: tuple[np.ndarray, np.ndarray], k: float) -> None:
    states, frames = rollout({"exposure": k}, image_size=SIZE)
    assert states.tobytes() == plain[0].tobytes()  # a camera effect leaves the motion alone
    expected = np.clip(np.rint(plain[1].astype(np.float64) * k), 0, 255).astype(np.uint8)
    assert frames.tobytes() == expected.tobytes()


def test_noise_is_gaussian_from_np_random_and_reproducible(plain: tuple[np.ndarray, np.ndarray]) -> None:
    std = 6.0
    states, frames = rollout({"noise": std}, image_size=SIZE)
    assert states.tobytes() == plain[0].tobytes()
    # the same draws, made by hand from the nominal env's np_random after the same seeded reset
    env = make_pixel_pendulum(image_size=SIZE)
    obs, _ = env.reset(seed=0, options={"state": START})
    want = []
    for u in [None, *ACTIONS]:
        if u is not None:
            obs, *_ = env.step(np.array([u], np.float32))
        noise = env.unwrapped.np_random.normal(0.0, std, size=(SIZE, SIZE))
        want.append(np.clip(np.rint(obs[-1] + noise), 0, 255).astype(np.uint8))
    assert frames.tobytes() == np.array(want).tobytes()
    residual = frames.astype(float) - plain[1]
    inside = (plain[1] > 40) & (plain[1] < 215)  # away from the 0 / 255 clip
    assert abs(residual[inside].std() - std) < 0.5 and abs(residual[inside].mean()) < 0.5
    assert rollout({"noise": std}, image_size=SIZE)[1].tobytes() == frames.tobytes()
    assert rollout({"noise": std}, image_size=SIZE, seed=1)[1].tobytes() != frames.tobytes()


def test_frame_drop_repeats_the_previous_observed_frame(plain: tuple[np.ndarray, np.ndarray]) -> None:
    p = 0.5
    actions = ACTIONS * 2
    states, frames = rollout({"frame_drop": p}, image_size=SIZE, actions=actions)
    clean_states, clean = rollout({}, image_size=SIZE, actions=actions)
    assert states.tobytes() == clean_states.tobytes()
    env = make_pixel_pendulum(image_size=SIZE)
    env.reset(seed=0, options={"state": START})
    rng = env.unwrapped.np_random  # the draws, by hand, after the same seeded reset
    want, dropped = [clean[0]], 0
    for t in range(1, len(clean)):
        drop = rng.random() < p
        dropped += drop
        want.append(want[-1] if drop else clean[t])
    assert 0 < dropped < len(actions)
    assert frames.tobytes() == np.array(want).tobytes()


@pytest.mark.parametrize("k", [1, 3])
def test_frame_delay_shows_the_frame_of_k_steps_ago(plain: tuple[np.ndarray, np.ndarray], k: int) -> None:
    states, frames = rollout({"frame_delay": k}, image_size=SIZE)
    assert states.tobytes() == plain[0].tobytes()  # the state is the true, current one
    for t, got in enumerate(frames):
        assert got.tobytes() == plain[1][max(t - k, 0)].tobytes()


def test_dynamics_and_vision_effects_combine() -> None:
    effects = {"damping": 0.3, "frame_delay": 1, "shift": 2}
    states, frames = rollout(effects, image_size=SIZE)
    np.testing.assert_allclose(states, expected_states(effects, START, ACTIONS), atol=1e-5)
    _, damped = rollout({"damping": 0.3}, image_size=SIZE)
    rows = np.clip(np.arange(SIZE) - 2, 0, SIZE - 1)
    for t, got in enumerate(frames):
        assert got.tobytes() == damped[max(t - 1, 0)][np.ix_(rows, rows)].tobytes()


def test_gymnasium_check_env_with_effects() -> None:
    from gymnasium.utils.env_checker import check_env

    effects = {"delay": 1, "friction": 0.2, "noise": 3.0, "frame_drop": 0.3, "frame_delay": 1}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        check_env(gym.make("piga/PixelPendulum-v0", image_size=16, effects=effects), skip_render_check=True)


def test_frame_stack_and_gym_make_carry_effects() -> None:
    env = gym.make("piga/PixelPendulumStack4-v0", image_size=16, effects=(("frame_delay", 2), ("bias", 0.2)))
    obs, _ = env.reset(seed=0)
    assert obs.shape == (4, 16, 16) and obs.dtype == np.uint8
    assert "FrameDelay" in repr(env) and "TorqueBias" in repr(env)


# ---------------------------------------------------------------------------------------------
# Registry, parsing and validation
# ---------------------------------------------------------------------------------------------


def test_every_effect_is_documented_and_has_one_place_in_the_env() -> None:
    assert all(spec.kind in {"actuator", "passive", "clip", "vision"} for spec in EFFECTS.values())
    assert all(spec.meaning and spec.unit and spec.requirement for spec in EFFECTS.values())
    placed = [name for stage in STAGES.values() for name in stage]
    assert sorted(placed) == sorted(EFFECTS)  # each effect has exactly one place in the env


def test_parse_effect() -> None:
    assert parse_effect("damping=0.2") == ("damping", 0.2)
    assert parse_effect(" Speed-Clip = 6 ") == ("speed_clip", 6.0)
    delay = parse_effect("delay=2")
    assert delay == ("delay", 2) and isinstance(delay[1], int)
    assert parse_effect("bias=-0.5") == ("bias", -0.5)


@pytest.mark.parametrize(
    "text, needle",
    [
        ("damping", "NAME=VALUE"),
        ("=0.2", "NAME=VALUE"),
        ("dampng=0.2", "valid effects: delay, deadzone"),
        ("damping=abc", "expected a number"),
        ("damping=", "expected a number"),
        ("damping=nan", "damping must be in [1e-06, 100]"),
        ("damping=inf", "damping must be in [1e-06, 100]"),
        ("damping=0", "damping must be in [1e-06, 100]"),
        ("friction=-0.1", "friction must be in [1e-06, 100]"),
        ("bias=0", "at least 1e-06 from 0"),
        ("delay=0", "integer >= 1"),
        ("delay=1.5", "integer >= 1"),
        ("deadzone=2", "in [1e-06, 2)"),
        ("saturation=0", "in [1e-06, 2)"),
        ("gain=1", "at least 1e-06 from 1"),
        ("gain=-1", "in [1e-06, 100]"),
        ("speed_clip=8", "in [0.0001, 8)"),
        ("blur=0", "blur must be in [1e-06, 1000]"),
        ("noise=-1", "noise must be in [1e-06, 1000]"),
        ("shift=0", "at least 1e-06 from 0"),
        ("frame_drop=1", "in [1e-06, 1)"),
        ("frame_delay=0.5", "integer >= 1"),
    ],
)
def test_parse_effect_errors(text: str, needle: str) -> None:
    with pytest.raises(ValueError) as info:
        parse_effect(text)
    assert needle in str(info.value), str(info.value)


def test_config_effects_are_checked_and_canonical() -> None:
    config = PixelPendulumConfig(effects=[("noise", 2), "delay=1", ("Speed-Clip", 5)])
    assert config.effects == (("delay", 1), ("speed_clip", 5.0), ("noise", 2.0))
    assert PixelPendulumConfig(effects={"noise": 2, "delay": 1, "speed_clip": 5}) == config
    assert json.loads(json.dumps(config.to_dict()))["effects"] == [["delay", 1], ["speed_clip", 5.0], ["noise", 2.0]]
    for bad, needle in [({"wind": 1.0}, "wind"), ([("damping", 0.1), ("damping", 0.2)], "twice"),
                        ({"damping": -1.0}, "damping"), ({"delay": 0}, "delay")]:
        with pytest.raises(ValueError, match="PixelPendulumConfig.effects") as info:
            PixelPendulumConfig(effects=bad)  # type: ignore[arg-type]
        assert needle in str(info.value)
    with pytest.raises(TypeError, match="pair"):
        normalize_effects([("damping",)])  # type: ignore[list-item]


def test_wrappers_validate_their_arguments() -> None:
    env = gym.make("Pendulum-v1")
    with pytest.raises(ValueError, match="damping"):
        ViscousDamping(env, -1.0)
    with pytest.raises(TypeError, match="gray uint8"):
        FrameBlur(env, 1.0)  # Pendulum-v1's own observation is not a frame
    with pytest.raises(TypeError, match="Box action space"):
        ActionDelay(gym.make("CartPole-v1"), 2)
    with pytest.raises(TypeError, match="Pendulum"):
        ViscousDamping(_StillFrame(np.zeros((8, 8), np.uint8)), 0.1)
    assert env.unwrapped.max_torque == 2.0  # a refused wrapper changed nothing


# ---------------------------------------------------------------------------------------------
# piga-collect --effect
# ---------------------------------------------------------------------------------------------


def _read(path: Path) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
    with h5py.File(path, "r") as f:
        return {k: f[k][()] for k in ("frames", "actions", "states")}, dict(f.attrs)


def test_collect_with_effects(tmp_path: Path) -> None:
    env = PixelPendulumConfig(effects={"delay": 1, "damping": 0.3, "noise": 4.0})
    config = CollectConfig(sequences=2, steps=6, seed=5, workers=1, split=(1, 1, 0), env=env)
    one = collect(config, tmp_path / "a.h5", progress=False, command="t")
    two = collect(replace(config, workers=2), tmp_path / "b.h5", progress=False, command="t")
    plain = collect(CollectConfig(sequences=2, steps=6, seed=5, workers=1, split=(1, 1, 0)), tmp_path / "p.h5",
                    progress=False, command="t")
    (a, attrs), (b, _), (p, plain_attrs) = _read(one), _read(two), _read(plain)
    for key in a:
        assert a[key].tobytes() == b[key].tobytes(), key  # same seed, same data, whatever the workers
    assert a["actions"].tobytes() == p["actions"].tobytes()  # the stored actions are the commanded u
    assert not np.array_equal(a["frames"], p["frames"])
    assert json.loads(attrs["effects"]) == {"delay": 1, "damping": 0.3, "noise": 4.0}
    assert json.loads(attrs["env_config"])["effects"] == [["delay", 1], ["damping", 0.3], ["noise", 4.0]]
    assert json.loads(plain_attrs["effects"]) == {}
    assert json.loads(attrs["params"]) == json.loads(plain_attrs["params"])
    for n in range(2):  # the stored states follow the equations from the stored, commanded actions
        start = a["states"][n, 0].astype(float).tolist()
        want = expected_states({"delay": 1, "damping": 0.3}, start, a["actions"][n, :-1, 0].tolist())
        np.testing.assert_allclose(a["states"][n], want, atol=1e-4)


def test_collect_cli_effect_writes_attrs(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    from piga.cli import collect as cli

    out = tmp_path / "d.h5"
    code, stdout, err = run_in_process("piga-collect", cli.main, "--out", str(out), "--sequences", "2", "--steps", "3", "--workers", "1",
                             "--quiet", "--effect", "friction=0.2", "--effect", "frame-drop=0.3", capsys=capsys)
    assert code == 0, err
    assert "effects friction=0.2 frame_drop=0.3" in stdout
    _, attrs = _read(out)
    assert json.loads(attrs["effects"]) == {"friction": 0.2, "frame_drop": 0.3}
    assert "--effect friction=0.2" in attrs["command"]


@pytest.mark.parametrize(
    "value, needle, code",
    [
        ("wind=1", "valid effects", 1),
        ("damping", "NAME=VALUE", 1),
        ("damping=x", "expected a number", 1),
        ("delay=0", "integer >= 1", 1),
        ("frame_drop=1.5", "in [1e-06, 1)", 1),
    ],
)
def test_collect_cli_bad_effect(tmp_path: Path, capsys: pytest.CaptureFixture[str], value: str, needle: str, code: int) -> None:
    from piga.cli import collect as cli

    out = tmp_path / "d.h5"
    got, _, err = run_in_process("piga-collect", cli.main, "--out", str(out), "--sequences", "2", "--effect", value, capsys=capsys)
    assert got == code and len(err.strip().splitlines()) == 1 and needle in err and "Traceback" not in err, err
    assert not out.exists()


def test_collect_cli_effect_given_twice(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    from piga.cli import collect as cli

    code, _, err = run_in_process("piga-collect", cli.main, "--out", str(tmp_path / "d.h5"), "--effect", "bias=0.1",
                        "--effect", "bias=0.2", capsys=capsys)
    assert code == 1 and err.strip() == "piga-collect: error: --effect: effect 'bias' is given twice"


@pytest.mark.parametrize("effects", [{"gain": 1.3}, {"delay": 2, "damping": 0.3}, {"saturation": 0.5, "bias": 0.4}])
def test_torque_arrow_shows_the_commanded_torque(effects: dict) -> None:
    """The picture must not leak the effect (nor show an arrow larger than the nominal data's)."""
    env = make_pixel_pendulum(PixelPendulumConfig(image_size=16, effects=tuple(effects.items())))
    env.reset(seed=0, options={"state": [0.5, 2.0]})
    for u in (1.7, -2.5, 0.3):
        env.step(np.array([u], np.float32))
        assert env.unwrapped.last_u == pytest.approx(float(np.clip(np.float32(u), -2, 2)))
    env.close()


def test_every_dynamics_effect_of_the_envs_is_a_term_of_piga_world_effects() -> None:
    """One definition: each actuator, passive or clip wrapper names the typed term whose equation it applies,
    under the same name, and every candidate of the diagnosis can be made by a wrapper (within_frame aside:
    it is how a simulator integrates, not a wrapper)."""
    from piga.world.effects import CANDIDATES
    from piga.world.effects import EFFECTS as TERMS

    for name, spec in EFFECTS.items():
        assert (spec.term is None) == (spec.kind == "vision"), name
        if spec.term is not None:
            assert spec.term is TERMS[name] and spec.term.name == name
    assert set(CANDIDATES) - {"within_frame"} <= {n for n, s in EFFECTS.items() if s.term is not None}
    with pytest.raises(ValueError, match="term of stage 'torque'"):
        EffectSpec("passive", "x", "N·m", "any", lambda v: True, CoulombFriction, term=TERMS["delay"])
