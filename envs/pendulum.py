"""The pixel pendulum: Gymnasium's own ``Pendulum-v1``, observed through its own render.

The observation is built from Gymnasium's observation wrappers and involves no hand-made renderer:

``Pendulum-v1 (rgb_array) -> AddRenderObservation -> ResizeObservation -> GrayscaleObservation
-> FrameStackObservation``

Unmodelled effects (``effects``, see :mod:`envs.effects`) add their wrappers around
``ActuationGain`` (actuator, passive torque and speed-clip effects) and after
``GrayscaleObservation`` (vision effects). Without effects none is added.

The frame is resized *before* it is converted to gray. That order is about 3x faster than the
reverse, because the gray conversion then runs on 64x64 pixels instead of 500x500.

## Spaces

| space | shape | dtype | range |
|---|---|---|---|
| observation | (frame_stack, image_size, image_size) | uint8 | 0..255, oldest frame first |
| action | (1,) | float32 | u in [-2, 2] |

## Dynamics (Pendulum-v1, with piga's settings)

| quantity | value |
|---|---|
| angle θ | 0 at upright, positive counter-clockwise as displayed |
| θ̈ | (3 g / 2)·sin θ + 3·(gain·u) |
| integration | semi-implicit Euler, dt = 0.05; θ̇ is clipped to ±8 |
| g | ``gravity × gravity_mult`` |
| applied torque | ``actuation_gain × u``, with u clipped to [-2, 2] before the gain is applied |
| reward | -(θ² + 0.1·θ̇² + 0.001·(gain·u)²), Gymnasium's, using the applied torque |
| reset | θ ~ U(-max_angle, max_angle), θ̇ ~ U(-max_speed, max_speed) |
| truncation | after ``episode_length`` steps |
| effects | none by default; ``effects`` adds delay, deadzone, friction, blur, ... (:mod:`envs.effects`) |

The true state ``(θ, θ̇)`` is put in ``info["state"]`` as float64 ``[θ, θ̇]``, with θ unwrapped as
Gymnasium keeps it. It is there for evaluation only. piga's training code never reads it.

Gymnasium's renderer draws an arrow at the pivot for the last applied torque. piga draws it by
default, to stay faithful to Gymnasium. ``draw_torque_arrow=False`` hides it, so that the frame
shows only the pendulum.
"""

from __future__ import annotations

import math
import os
from dataclasses import asdict, dataclass, replace
from typing import Any, SupportsFloat

import gymnasium as gym
import numpy as np
from gymnasium.wrappers import (
    AddRenderObservation,
    FrameStackObservation,
    GrayscaleObservation,
    ResizeObservation,
)

from envs.constants import MAX_ACTION, MAX_IMAGE_SIZE, PENDULUM_DT, PENDULUM_MAX_SPEED
from envs.effects import EFFECTS, ShowCommandedTorque, explicit_step_problem, normalize_effects, wrap_effects
from envs.fields import check_field_kinds, number_text
from piga.world.effects import scaled_gravity

# pygame opens a display on its first render; on a headless machine it needs the dummy driver
# and otherwise prints an XDG_RUNTIME_DIR complaint. A user's own choice is respected.
os.environ.setdefault("SDL_VIDEODRIVER", "dummy")

__all__ = ["MAX_ACTION", "PENDULUM_DT", "PENDULUM_MAX_SPEED", "ActuationGain", "HideTorqueArrow", "PendulumStateInfo",
           "PixelPendulumConfig", "ResetRange", "make_pixel_pendulum"]


#: Largest actuation gain: torques stay far inside float32.
MAX_ACTUATION_GAIN = 1e6
#: Largest simulated gravity ``gravity * gravity_mult`` (m/s²). Pendulum-v1's semi-implicit Euler step, linearised at the
#: hanging rest (:func:`envs.effects.explicit_step_problem`), is unstable once k_g·g·dt² >= 4, g >= 4 / (1.5 · 0.05²) =
#: 1066.7: the speed then flips sign every step and grows to the ±8 rad/s clip, a recording of the step, not of a
#: pendulum. Rounded down to a number a help line can give.
MAX_GRAVITY = 1066.0
#: Smallest actuation gain, and smallest simulated gravity (m/s²): a millionth of the defaults. Weaker, over a
#: 200-step episode (Gymnasium's, 10 s) the torque (at most 2 x gain) or gravity moves the pendulum by under
#: 3e-4 rad (½ · 3 · 2e-6 · 10²), a hundredth of a pixel at its tip in a 64-pixel frame: no frame shows it, so
#: there is nothing to identify or to control.
MIN_ACTUATION_GAIN = MIN_GRAVITY = 1e-6
#: Why the floors, as the out-of-range errors say it.
_TOO_WEAK = "weaker, it moves the pendulum's tip by under a hundredth of a pixel in a 200-step episode"


#: The largest ``blur`` sigma is the frame side over this: at σ = side/8 (8 px in 64 px frames) a frame still spans
#: 18 gray levels and its motion moves pixels by 7; at side/4 they were 5 and 2 levels (the frames were nearly blank).
MAX_BLUR_FRACTION = 8


@dataclass(frozen=True)
class PixelPendulumConfig:
    """Settings of the pixel pendulum. Every field has a Gymnasium-faithful default."""

    image_size: int = 64
    """Side of the square gray frame in pixels."""
    frame_stack: int = 1
    """Number of most recent frames in one observation (oldest first)."""
    gravity: float = 10.0
    """Gravity g of Pendulum-v1 before the multiplier (m/s²)."""
    gravity_mult: float = 1.0
    """Multiplier on gravity. The environment simulates ``gravity * gravity_mult``."""
    actuation_gain: float = 1.0
    """Applied torque = actuation_gain × u, for u in [-2, 2]."""
    episode_length: int = 200
    """Steps before truncation (Pendulum-v1's own TimeLimit)."""
    max_angle: float = math.pi
    """Reset draws θ ~ U(-max_angle, max_angle) (Pendulum-v1's ``x_init``)."""
    max_speed: float = 1.0
    """Reset draws θ̇ ~ U(-max_speed, max_speed) (Pendulum-v1's ``y_init``; the paper uses 6)."""
    draw_torque_arrow: bool = True
    """Draw Gymnasium's torque arrow at the pivot. True is Gymnasium's own picture."""
    effects: tuple[tuple[str, float], ...] = ()
    """Unmodelled effects as (name, value) pairs, e.g. (("damping", 0.2),); see :mod:`envs.effects`."""

    def __post_init__(self) -> None:
        check_field_kinds(self)  # a config read from a file's attrs may hold text where a number belongs
        try:
            effects = normalize_effects(self.effects)
        except (TypeError, ValueError) as exc:
            raise type(exc)(f"PixelPendulumConfig.effects: {exc}") from None
        object.__setattr__(self, "effects", effects)  # canonical order, checked values
        if self.actuation_gain > MAX_ACTUATION_GAIN:
            raise ValueError(f"PixelPendulumConfig.actuation_gain={number_text(self.actuation_gain)} is out of range: at most "
                             f"{MAX_ACTUATION_GAIN:g} (a larger torque overflows float32)")
        if self.effective_gravity > MAX_GRAVITY:
            raise ValueError(f"PixelPendulumConfig: gravity x gravity_mult = {number_text(self.effective_gravity)} is out of range: at "
                             f"most {MAX_GRAVITY:g} (stronger, Pendulum-v1's explicit step of {PENDULUM_DT:g} s is unstable)")
        for name, value in effects:
            if name == "blur" and value > self.image_size / MAX_BLUR_FRACTION:
                raise ValueError(f"effect blur={number_text(value)} px would blur the pendulum away in a {self.image_size} px frame; "
                                 f"use a sigma of at most {self.image_size / MAX_BLUR_FRACTION:g} px")
            if name == "shift" and abs(value) >= self.image_size / 2:  # the pivot, at the centre, would leave the frame
                raise ValueError(f"effect shift={number_text(value)} px would move the pendulum out of a {self.image_size} px frame "
                                 f"(its pivot out of view); use |shift| < {self.image_size / 2:g}")
        checks = {  # each field: whether it is in range, and its range in words
            "image_size": (8 <= self.image_size <= MAX_IMAGE_SIZE, f"image_size in [8, {MAX_IMAGE_SIZE}]"),
            "frame_stack": (self.frame_stack >= 1, "frame_stack >= 1"),
            "gravity": (self.gravity > 0 and math.isfinite(self.gravity), "gravity > 0, finite"),
            "gravity_mult": (self.gravity_mult > 0 and math.isfinite(self.gravity_mult), "gravity_mult > 0, finite"),
            "actuation_gain": (self.actuation_gain > 0 and math.isfinite(self.actuation_gain), "actuation_gain > 0, finite"),
            "episode_length": (self.episode_length >= 1, "episode_length >= 1"),
            "max_angle": (0 <= self.max_angle <= math.pi, "max_angle in [0, pi]"),
            "max_speed": (0 <= self.max_speed <= PENDULUM_MAX_SPEED, f"max_speed in [0, {PENDULUM_MAX_SPEED:g}]"),
        }
        for name, (ok, allowed) in checks.items():
            if not ok:
                raise ValueError(f"PixelPendulumConfig.{name}={number_text(getattr(self, name))} is out of range ({allowed})")
        if self.actuation_gain < MIN_ACTUATION_GAIN:
            raise ValueError(f"PixelPendulumConfig.actuation_gain={number_text(self.actuation_gain)} is out of range: at least "
                             f"{MIN_ACTUATION_GAIN:g} ({_TOO_WEAK})")
        if self.effective_gravity < MIN_GRAVITY:
            raise ValueError(f"PixelPendulumConfig: gravity x gravity_mult = {number_text(self.effective_gravity)} is out of range: "
                             f"at least {MIN_GRAVITY:g} m/s² ({_TOO_WEAK})")
        unstable = explicit_step_problem(dict(effects), self.effective_gravity, PENDULUM_DT)
        if unstable:  # damping, friction or cogging that Pendulum-v1's step turns into a shaking, meaningless recording
            raise ValueError(unstable)

    @property
    def effective_gravity(self) -> float:
        """The gravity the simulator uses: ``gravity * gravity_mult`` (:func:`piga.world.effects.scaled_gravity`)."""
        return scaled_gravity(self.gravity, self.gravity_mult)

    def to_dict(self) -> dict[str, Any]:
        """A JSON-able copy of the fields."""
        return asdict(self)


class ActuationGain(gym.ActionWrapper):
    """Applies ``gain × u`` as Pendulum's torque, for an action u in Pendulum's own range.

    Pendulum-v1 clips the torque it receives at ``max_torque`` (2). For a gain above 1 that clip
    would cut the applied torque, so the wrapper raises the inner clip to ``2 × gain``. It never
    lowers a clip that an inner wrapper has already raised (the effects of :mod:`envs.effects`
    disable it). The outer action space stays [-2, 2], and actions outside it are clipped before
    the gain is applied.
    """

    def __init__(self, env: gym.Env, gain: float):
        if not (gain > 0 and math.isfinite(gain)):
            raise ValueError(f"ActuationGain: gain must be finite and > 0, got {gain!r}")
        if not isinstance(env.action_space, gym.spaces.Box) or env.action_space.shape != (1,):
            raise TypeError(f"ActuationGain needs a Box action space of shape (1,), got {env.action_space}")
        super().__init__(env)
        self.gain = float(gain)
        base = env.unwrapped
        if not hasattr(base, "max_torque"):
            raise TypeError("ActuationGain wraps Gymnasium's Pendulum (an env with `max_torque`)")
        base.max_torque = max(base.max_torque, MAX_ACTION * max(self.gain, 1.0))

    def action(self, action: np.ndarray) -> np.ndarray:
        u = np.clip(np.asarray(action, dtype=np.float32), -MAX_ACTION, MAX_ACTION)
        return (self.gain * u).astype(np.float32)


#: The largest torque the arrow is drawn for. Gymnasium scales its arrow picture by |torque|: at 12 it is 680 pixels
#: wide, past the 500-pixel render's edges, and a gain of 1000 asked pygame for an arrow of 10^10 pixels (out of
#: memory; 500 took 100 s for 8 frames). A larger torque is drawn as this one.
ARROW_MAX_TORQUE = 12.0


class BoundedTorqueArrow(gym.Wrapper):
    """Renders Pendulum's torque arrow for at most :data:`ARROW_MAX_TORQUE` (the torque applied is unchanged)."""

    def render(self) -> Any:
        base = self.env.unwrapped
        saved = base.last_u
        if saved is not None:
            base.last_u = float(np.clip(saved, -ARROW_MAX_TORQUE, ARROW_MAX_TORQUE))
        try:
            return self.env.render()
        finally:
            base.last_u = saved


class HideTorqueArrow(gym.Wrapper):
    """Renders Pendulum without its torque arrow. Gymnasium draws the arrow only when ``last_u`` is set."""

    def render(self) -> Any:
        base = self.env.unwrapped
        saved = base.last_u
        base.last_u = None
        try:
            return self.env.render()
        finally:
            base.last_u = saved


class PendulumStateInfo(gym.Wrapper):
    """Adds ``info["state"] = [θ, θ̇]`` (float64) after reset and every step. For evaluation only."""

    def _state(self) -> np.ndarray:
        return np.asarray(self.env.unwrapped.state, dtype=np.float64).copy()

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        obs, info = self.env.reset(seed=seed, options=options)
        return obs, {**info, "state": self._state()}

    def step(self, action: Any) -> tuple[Any, SupportsFloat, bool, bool, dict[str, Any]]:
        obs, reward, terminated, truncated, info = self.env.step(action)
        return obs, reward, terminated, truncated, {**info, "state": self._state()}


class ResetRange(gym.Wrapper):
    """Fills Pendulum-v1's reset options ``x_init`` (angle range) and ``y_init`` (speed range).

    Options that the caller passes to ``reset`` take precedence. ``options={"state": [θ, θ̇]}``
    starts from exactly that state (for example hanging down, [π, 0]). The wrapper sits inside
    ``AddRenderObservation``, so the first frame shows it.
    """

    def __init__(self, env: gym.Env, max_angle: float, max_speed: float):
        if max_angle < 0 or max_speed < 0:
            raise ValueError(f"ResetRange: ranges must be >= 0, got max_angle={max_angle}, max_speed={max_speed}")
        super().__init__(env)
        self.defaults = {"x_init": float(max_angle), "y_init": float(max_speed)}

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        options = dict(options or {})
        state = options.pop("state", None)
        obs, info = self.env.reset(seed=seed, options={**self.defaults, **options})
        if state is not None:
            state = np.asarray(state, dtype=np.float64)
            if state.shape != (2,) or not np.isfinite(state).all():
                raise ValueError(f"reset option 'state' must be a finite [theta, theta_dot], got {state!r}")
            self.env.unwrapped.state = state.copy()
            obs = self.env.unwrapped._get_obs()
        return obs, info


def make_pixel_pendulum(
    config: PixelPendulumConfig | None = None, render_mode: str | None = "rgb_array", **overrides: Any
) -> gym.Env:
    """Builds the pixel pendulum from Gymnasium's Pendulum-v1 and Gymnasium's wrappers.

    Args:
        config: the settings; None means the defaults.
        render_mode: only "rgb_array" (or None, which means the same): the frames *are* the render,
            so ``env.render()`` returns Gymnasium's full-size colour picture.
        **overrides: fields of :class:`PixelPendulumConfig` that replace those of ``config``.
            ``gym.make("piga/PixelPendulum-v0", gravity_mult=1.4)`` passes its keywords here.

    Returns:
        An env whose observation is uint8 (frame_stack, image_size, image_size).
    """
    if render_mode not in (None, "rgb_array"):
        raise ValueError(f"the pixel pendulum renders only as 'rgb_array', got render_mode={render_mode!r}")
    if config is not None and not isinstance(config, PixelPendulumConfig):  # (dataclasses' replace() named no argument)
        raise TypeError(f"config must be a PixelPendulumConfig or None, got {type(config).__name__}; give fields as "
                        "keywords (make_pixel_pendulum(gravity=3.0)) or build the config")
    config = replace(config or PixelPendulumConfig(), **overrides)
    env = gym.make(
        "Pendulum-v1",
        render_mode="rgb_array",
        g=config.effective_gravity,
        max_episode_steps=config.episode_length,
    )
    env = ResetRange(env, config.max_angle, config.max_speed)
    env = wrap_effects(env, config.effects, "torque")  # speed clip, passive torques, gain error
    env = ActuationGain(env, config.actuation_gain)
    env = wrap_effects(env, config.effects, "command")  # saturation, deadzone, delay (outermost)
    if any(EFFECTS[name].kind != "vision" for name, _ in config.effects):
        env = ShowCommandedTorque(env, config.actuation_gain)  # the arrow shows the command, not the effects
    env = PendulumStateInfo(env)
    env = HideTorqueArrow(env) if not config.draw_torque_arrow else BoundedTorqueArrow(env)
    env = AddRenderObservation(env, render_only=True)
    env = ResizeObservation(env, (config.image_size, config.image_size))
    env = GrayscaleObservation(env, keep_dim=False)
    env = wrap_effects(env, config.effects, "frame")  # blur, shift, noise, frame delay, frame drop
    env = FrameStackObservation(env, config.frame_stack)
    env.metadata = {**env.metadata, "render_modes": ["rgb_array"]}
    # Gymnasium's Pendulum-v1 advertises "human" too, and check_env(env.unwrapped) makes the env again in each mode
    # its metadata lists: the base env's copy says what this env renders
    env.unwrapped.metadata = {**env.unwrapped.metadata, "render_modes": ["rgb_array"]}
    return env
