"""Unmodelled effects: wrappers that turn the nominal pixel pendulum into a "real system".

The nominal model is Gymnasium's Pendulum-v1 as piga's physics engine knows it. The effects below
add what that model lacks: a lazy or weak actuator, friction, a bias, a tighter speed limit, and a
poor camera. They are meant for sim-to-real studies, such as diagnosing a model identified on
nominal data against a recording with effects. Each effect is one small wrapper, and
``PixelPendulumConfig(effects=(("damping", 0.2), ...))`` puts the right ones in the right places
(:func:`envs.pendulum.make_pixel_pendulum`). Write an effect on the command line as ``NAME=VALUE``
(:func:`parse_effect`). :data:`EFFECTS` lists them all.

## Dynamics

The equations are exact. The actuator and passive-torque terms are those of
:mod:`piga.world.effects` (each :class:`EffectSpec` names its ``term``), the one definition that
piga's diagnosis and planners use too (that module is torch-free: it is the only part of piga
that ``envs`` imports).

Let u_t be the commanded action, the one that the agent sends and that a data file stores as
``/actions``. Like Pendulum-v1, it is first clipped to [-2, 2]. The actuator effects turn u into
ũ, applied in the order of the table (delay, then deadzone, then saturation, then gain):

| effect | kind | parameter | equation | wrapper |
|---|---|---|---|---|
| ``delay=k`` | actuator | integer 1 <= k <= 1000 (steps) | ũ_t = u_{t-k}, and ũ_t = 0 for t < k (reset clears it) | :class:`ActionDelay` |
| ``deadzone=d`` | actuator | 1e-6 <= d < 2 (action units) | ũ = sign(u)·max(abs(u) - d, 0) | :class:`ActionDeadzone` |
| ``saturation=s`` | actuator | 1e-6 <= s < 2 (action units) | ũ = clip(u, -s, s) | :class:`ActionSaturation` |
| ``gain=m`` | actuator | 1e-6 <= m <= 100, abs(m - 1) >= 1e-6 (factor) | ũ = m·u (an actuator gain error) | :class:`ActionGainError` |

The applied torque τ_t is ``actuation_gain·ũ_t`` plus the passive torques. These are computed
from the state (θ_t, θ̇_t) *before* the step:

| effect | kind | parameter | passive torque | wrapper |
|---|---|---|---|---|
| ``damping=b`` | passive | 1e-6 <= b <= 100 (N·m·s/rad) | -b·θ̇_t | :class:`ViscousDamping` |
| ``friction=c`` | passive | 1e-6 <= c <= 100 (N·m) | -c·tanh(θ̇_t / 0.1), a smoothed Coulomb friction (:data:`piga.world.effects.FRICTION_SMOOTHING`) | :class:`CoulombFriction` |
| ``bias=τ0`` | passive | 1e-6 <= abs(τ0) <= 100 (N·m) | +τ0 | :class:`TorqueBias` |
| ``cogging=k`` | passive | 1e-6 <= k <= 100 (N·m) | -k·sin(4θ_t), a detent torque; not a candidate of the diagnosis | :class:`CoggingTorque` |
| ``speed_clip=v`` | clip | 1e-4 <= v < 8 (rad/s) | Pendulum-v1's speed clip ±8 becomes ±v | :class:`SpeedClip` |

:class:`~envs.pendulum.PixelPendulumConfig` also refuses a damping, a friction or a cogging that the explicit step
below cannot integrate (:func:`explicit_step_problem`): at g = 10 and dt = 0.05, a damping below 13.2 and a friction
of at most 13.2, lower together or with cogging.

The step is Pendulum-v1's own step, given τ_t as its torque:

| quantity | equation |
|---|---|
| torque | τ_t = actuation_gain·ũ_t - b·θ̇_t - c·tanh(θ̇_t / 0.1) + τ0 - k·sin(4θ_t) (absent effects contribute 0) |
| speed | θ̇_{t+1} = clip(θ̇_t + dt·(1.5·g·sin θ_t + 3·τ_t), -v_max, v_max), with v_max = v, or 8 without ``speed_clip`` |
| angle | θ_{t+1} = θ_t + dt·θ̇_{t+1} |

To get there, the wrappers between :class:`~envs.pendulum.ActuationGain` and Pendulum-v1 pass τ_t
as the action and disable Pendulum-v1's own torque clip (``max_torque = inf``). The command clip
to [-2, 2] still applies. Pendulum-v1's reward uses τ_t, which includes the passive torques. Its
torque arrow shows the *commanded* torque ``actuation_gain·clip(u, -2, 2)``
(:class:`ShowCommandedTorque`), so the frames carry no trace of the effects beyond the motion
itself. ``info["state"]`` is the true state. As in the nominal env, ũ and
``actuation_gain·ũ`` are float32; the gain error, the passive torques and the step are float64.

## Vision

The vision effects act on each gray uint8 (H, W) frame after ``GrayscaleObservation`` and before
``FrameStackObservation``, in the order of the table. Random draws come from the env's
``np_random``, so ``reset(seed=...)`` makes them reproducible. In each step the noise is drawn
first (one normal per pixel), then the drop (one uniform); reset draws only the noise.

| effect | kind | parameter | frame x -> observed frame | wrapper |
|---|---|---|---|---|
| ``blur=σ`` | vision | 1e-6 <= σ <= 1000 (px) | ``cv2.GaussianBlur(x, (0, 0), σ)``: the kernel size follows from σ | :class:`FrameBlur` |
| ``shift=p`` | vision | 1e-6 <= abs(p) <= 1000 (px) | x'[r, c] = x[r - p, c - p]: p px right and p px down, border replicated (``cv2.warpAffine``) | :class:`FrameShift` |
| ``exposure=k`` | vision | 1e-6 <= k <= 100, abs(k - 1) >= 1e-6 (factor) | clip(round(k·x), 0, 255) as uint8: exposure or lighting; black stays black | :class:`FrameExposure` |
| ``noise=s`` | vision | 1e-6 <= s <= 1000 (gray levels) | clip(round(x + s·ε), 0, 255) as uint8, ε ~ N(0, 1) per pixel | :class:`FrameNoise` |
| ``frame_delay=k`` | vision | integer 1 <= k <= 1000 (steps) | at step t, the frame of step t - k; the reset frame for t < k | :class:`FrameDelay` |
| ``frame_drop=p`` | vision | 1e-6 <= p < 1 (probability) | at each step, with probability p, the previous observed frame again (a dropped frame); never on reset | :class:`FrameDrop` |

``env.render()`` still returns Gymnasium's clean full-size picture. The vision effects act only
on the observation.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass
from typing import Any, Literal, SupportsFloat, get_args

import cv2
import gymnasium as gym
import numpy as np

from envs.constants import MAX_ACTION, PENDULUM_MAX_SPEED
from envs.fields import number_text, upper_bound_text
from piga.world.effects import (BIAS, COGGING, COGGING_PERIODS, DAMPING, DEADZONE, DELAY, FRICTION, GAIN, SATURATION,
                                SPEED_CLIP, Effect, pendulum_gains)

# Upper bounds of the effects' parameters: far beyond any real system's (the pendulum's torque is
# at most 2 N·m, its frames 64 px and 255 gray levels), and small enough that a typo such as
# ``delay=1000000000`` is refused instead of allocating a buffer of that many actions.

#: Largest ``delay`` and ``frame_delay``, in steps (five Pendulum-v1 episodes).
MAX_DELAY_STEPS = 1000
#: Largest ``gain`` factor.
MAX_GAIN_ERROR = 100.0
#: Largest ``damping``, ``friction``, ``cogging`` and ``|bias|`` (N·m, or N·m·s/rad for damping).
MAX_PASSIVE = 100.0
#: Largest ``blur`` sigma and ``|shift|``, in pixels.
MAX_PIXELS = 1000.0
#: Largest ``noise`` standard deviation, in gray levels.
MAX_NOISE = 1000.0
#: Smallest ``speed_clip`` (rad/s): slower, the pendulum turns by under a thousandth of a radian in a
#: 200-step episode (10 s), a few hundredths of a pixel at its tip in a 64-pixel frame, as with
#: ``envs.pendulum.MIN_GRAVITY``: no frame shows it move (1e-9 wrote a file of a still pendulum).
MIN_SPEED_CLIP = 1e-4
#: Smallest magnitude of every other continuous effect (and of ``gain - 1``), in the effect's units: a millionth, as
#: the floors of gravity and the actuation gain (``envs.pendulum.MIN_GRAVITY``). A torque this small moves the
#: pendulum's tip by about a hundredth of a pixel in an episode; smaller values are lost to rounding (the command is
#: float32, the frames uint8): 1e-320 was recorded in a file whose frames were the nominal ones, byte for byte.
MIN_EFFECT = 1e-6


# ---------------------------------------------------------------------------------------------
# Parameter checks, shared by the wrappers and the registry
# ---------------------------------------------------------------------------------------------


def _is_number(value: Any) -> bool:
    return isinstance(value, (int, float, np.integer, np.floating)) and not isinstance(value, bool) and math.isfinite(value)


def _validated(name: str, value: Any) -> Any:
    """``value`` checked against :data:`EFFECTS` (defined below; wrappers call this at construction)."""
    return EFFECTS[name].validate(name, value)


def _base_pendulum(env: gym.Env, who: str) -> Any:
    base = env.unwrapped
    if not all(hasattr(base, key) for key in ("max_torque", "max_speed", "dt")):
        raise TypeError(f"{who} wraps Gymnasium's Pendulum (an env with `max_torque` and `max_speed`), got {base}")
    return base


def _check_action_space(env: gym.Env, who: str) -> None:
    if not isinstance(env.action_space, gym.spaces.Box) or env.action_space.shape != (1,):
        raise TypeError(f"{who} needs a Box action space of shape (1,), got {env.action_space}")


def _check_frame_space(env: gym.Env, who: str) -> None:
    space = env.observation_space
    if not isinstance(space, gym.spaces.Box) or space.dtype != np.uint8 or len(space.shape) != 2:
        raise TypeError(f"{who} needs gray uint8 (H, W) frames (after GrayscaleObservation), got {space}")


# ---------------------------------------------------------------------------------------------
# Actuator effects: u -> ũ, outside ActuationGain (delay, deadzone, saturation) or inside it (gain)
# ---------------------------------------------------------------------------------------------


class ActionDelay(gym.ActionWrapper):
    """Dead time: the actuator applies ũ_t = u_{t-k}, and 0 for t < k. ``reset`` clears the buffer.

    The commanded u is clipped to [-2, 2] before it enters the buffer.
    """

    def __init__(self, env: gym.Env, steps: int):
        steps = _validated("delay", steps)
        _check_action_space(env, "ActionDelay")
        super().__init__(env)
        self.steps = steps
        self._queue: deque[np.ndarray] = deque()
        self._clear()

    def _clear(self) -> None:
        zero = np.zeros(self.action_space.shape, np.float32)
        self._queue = deque([zero] * self.steps, maxlen=self.steps + 1)

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        self._clear()
        return self.env.reset(seed=seed, options=options)

    def action(self, action: np.ndarray) -> np.ndarray:
        self._queue.append(np.clip(np.asarray(action, np.float32), -MAX_ACTION, MAX_ACTION))
        return self._queue.popleft()


class ActionDeadzone(gym.ActionWrapper):
    """A deadzone: ũ = sign(u)·max(abs(u) - d, 0), for u clipped to [-2, 2]."""

    def __init__(self, env: gym.Env, width: float):
        width = _validated("deadzone", width)
        _check_action_space(env, "ActionDeadzone")
        super().__init__(env)
        self.width = width

    def action(self, action: np.ndarray) -> np.ndarray:
        u = np.clip(np.asarray(action, np.float32), -MAX_ACTION, MAX_ACTION)
        return DEADZONE.transform(u, self.width).astype(np.float32)


class ActionSaturation(gym.ActionWrapper):
    """A weaker actuator: ũ = clip(u, -s, s), for s < 2."""

    def __init__(self, env: gym.Env, limit: float):
        limit = _validated("saturation", limit)
        _check_action_space(env, "ActionSaturation")
        super().__init__(env)
        self.limit = limit

    def action(self, action: np.ndarray) -> np.ndarray:
        return SATURATION.transform(np.asarray(action, np.float32), self.limit).astype(np.float32)


class ActionGainError(gym.ActionWrapper):
    """An actuator gain error: the torque is m times what it should be.

    It sits *inside* :class:`~envs.pendulum.ActuationGain`, so it scales ``actuation_gain·ũ``.
    That is the same as ũ = m·u, because the gain is the last of the actuator effects and linear.
    Pendulum-v1's own torque clip is disabled, so a gain above 1 is not cut. The command clip to
    [-2, 2] happens in ``ActuationGain``.
    """

    def __init__(self, env: gym.Env, gain: float):
        gain = _validated("gain", gain)
        _check_action_space(env, "ActionGainError")
        base = _base_pendulum(env, "ActionGainError")
        super().__init__(env)
        self.gain = gain
        base.max_torque = math.inf

    def action(self, action: np.ndarray) -> np.ndarray:
        return GAIN.transform(np.asarray(action, np.float64), self.gain)


# ---------------------------------------------------------------------------------------------
# Passive torques and the speed clip, between ActuationGain and Pendulum-v1
# ---------------------------------------------------------------------------------------------


class _PassiveTorque(gym.ActionWrapper):
    """Adds ``torque(θ_t, θ̇_t)``, computed from the state before the step, to the applied torque.

    Pendulum-v1's own torque clip is disabled (``max_torque = inf``). Otherwise it would cut the
    sum, which is a torque and no longer a command.
    """

    def __init__(self, env: gym.Env):
        _check_action_space(env, type(self).__name__)
        base = _base_pendulum(env, type(self).__name__)
        super().__init__(env)
        self._base = base
        base.max_torque = math.inf

    def torque(self, theta: float, theta_dot: float) -> float:
        """The passive torque at state (θ, θ̇)."""
        raise NotImplementedError

    def action(self, action: np.ndarray) -> np.ndarray:
        theta, theta_dot = (float(x) for x in self._base.state)
        return np.asarray(action, np.float64) + self.torque(theta, theta_dot)


class ViscousDamping(_PassiveTorque):
    """Viscous damping: passive torque -b·θ̇."""

    def __init__(self, env: gym.Env, coefficient: float):
        coefficient = _validated("damping", coefficient)
        super().__init__(env)
        self.coefficient = coefficient

    def torque(self, theta: float, theta_dot: float) -> float:
        return DAMPING.torque(theta, theta_dot, self.coefficient)


class CoulombFriction(_PassiveTorque):
    """Smoothed Coulomb friction: passive torque -c·tanh(θ̇ / 0.1) (:data:`piga.world.effects.FRICTION_SMOOTHING`)."""

    def __init__(self, env: gym.Env, level: float):
        level = _validated("friction", level)
        super().__init__(env)
        self.level = level

    def torque(self, theta: float, theta_dot: float) -> float:
        return FRICTION.torque(theta, theta_dot, self.level)


class TorqueBias(_PassiveTorque):
    """A constant torque τ0, for example an unbalanced load or an actuator offset."""

    def __init__(self, env: gym.Env, bias: float):
        bias = _validated("bias", bias)
        super().__init__(env)
        self.bias = bias

    def torque(self, theta: float, theta_dot: float) -> float:
        return BIAS.torque(theta, theta_dot, self.bias)


class CoggingTorque(_PassiveTorque):
    """A position-periodic detent torque -k·sin(4θ), as a motor with 4 pole pairs has.

    It is *not* among the candidates of ``piga-diagnose``: the blind check uses it as the effect
    outside the candidate set, which the diagnosis must report as unexplained.
    """

    def __init__(self, env: gym.Env, level: float):
        level = _validated("cogging", level)
        super().__init__(env)
        self.level = level

    def torque(self, theta: float, theta_dot: float) -> float:
        return COGGING.torque(theta, theta_dot, self.level)


class ShowCommandedTorque(gym.Wrapper):
    """Makes Gymnasium's torque arrow show the *commanded* torque ``actuation_gain·clip(u, -2, 2)``.

    Without it the arrow would show whatever the effects make of the torque: a delayed, dead-zoned,
    amplified or frictional one. That would leak the effect into the picture, and an arrow larger
    than any in the nominal data corrupts the encoder of a model identified on it (measured: 15°
    errors at speed under damping). A real camera shows no arrow at all; showing the command keeps
    the frames of a "real" system exactly as they would be without effects, for the same commands.
    :func:`envs.pendulum.make_pixel_pendulum` puts it outside all action effects when there are any.
    """

    def __init__(self, env: gym.Env, actuation_gain: float):
        self._base = _base_pendulum(env, "ShowCommandedTorque")
        super().__init__(env)
        self.actuation_gain = float(actuation_gain)

    def step(self, action: Any) -> tuple[Any, SupportsFloat, bool, bool, dict[str, Any]]:
        result = self.env.step(action)
        u = float(np.clip(np.asarray(action, np.float64).reshape(-1)[0], -MAX_ACTION, MAX_ACTION))
        self._base.last_u = self.actuation_gain * u  # read by the renderer after this step
        return result


class SpeedClip(gym.Wrapper):
    """Clips θ̇ to ±v after each step instead of Pendulum-v1's ±8 (it sets ``unwrapped.max_speed``).

    The reset draw of θ̇ is not clipped. A reset range wider than v lasts until the first step.
    """

    def __init__(self, env: gym.Env, limit: float):
        limit = _validated("speed_clip", limit)
        base = _base_pendulum(env, "SpeedClip")
        super().__init__(env)
        self.limit = limit
        base.max_speed = limit


# ---------------------------------------------------------------------------------------------
# Vision effects on gray uint8 (H, W) frames
# ---------------------------------------------------------------------------------------------


class FrameBlur(gym.ObservationWrapper):
    """Defocus: ``cv2.GaussianBlur(frame, (0, 0), sigma)``. The kernel size follows from sigma."""

    def __init__(self, env: gym.Env, sigma: float):
        sigma = _validated("blur", sigma)
        _check_frame_space(env, "FrameBlur")
        super().__init__(env)
        self.sigma = sigma

    def observation(self, observation: np.ndarray) -> np.ndarray:
        return cv2.GaussianBlur(observation, (0, 0), self.sigma)


class FrameShift(gym.ObservationWrapper):
    """A misplaced camera: the picture moves p px right and p px down, border replicated.

    ``x'[r, c] = x[r - p, c - p]``, by ``cv2.warpAffine``. The result is exact for an integer p and
    bilinear otherwise.
    """

    def __init__(self, env: gym.Env, pixels: float):
        pixels = _validated("shift", pixels)
        _check_frame_space(env, "FrameShift")
        super().__init__(env)
        self.pixels = pixels
        self._matrix = np.array([[1.0, 0.0, self.pixels], [0.0, 1.0, self.pixels]])  # (2, 3)

    def observation(self, observation: np.ndarray) -> np.ndarray:
        h, w = observation.shape
        return cv2.warpAffine(observation, self._matrix, (w, h), flags=cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)


class FrameExposure(gym.ObservationWrapper):
    """A change of exposure or lighting: every gray level times a factor k, rounded and clipped to 0..255.

    ``x' = clip(rint(k·x), 0, 255)``: black stays black, a white background becomes 255·k (k < 1: a darker
    picture) or stays at 255 (k > 1: only the pendulum brightens).
    """

    def __init__(self, env: gym.Env, factor: float):
        factor = _validated("exposure", factor)
        _check_frame_space(env, "FrameExposure")
        super().__init__(env)
        self.factor = factor

    def observation(self, observation: np.ndarray) -> np.ndarray:
        return np.clip(np.rint(observation * self.factor), 0, 255).astype(np.uint8)


class FrameNoise(gym.ObservationWrapper):
    """Sensor noise: adds N(0, s²) per pixel from the env's ``np_random``, rounds, and clips to 0..255."""

    def __init__(self, env: gym.Env, std: float):
        std = _validated("noise", std)
        _check_frame_space(env, "FrameNoise")
        super().__init__(env)
        self.std = std

    def observation(self, observation: np.ndarray) -> np.ndarray:
        noise = self.np_random.normal(0.0, self.std, size=observation.shape)  # (H, W)
        return np.clip(np.rint(observation + noise), 0, 255).astype(np.uint8)


class FrameDelay(gym.Wrapper):
    """Camera latency: the frame observed at step t is the frame of step t - k (the reset frame for t < k)."""

    def __init__(self, env: gym.Env, steps: int):
        steps = _validated("frame_delay", steps)
        _check_frame_space(env, "FrameDelay")
        super().__init__(env)
        self.steps = steps
        self._frames: deque[np.ndarray] = deque(maxlen=self.steps + 1)

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        obs, info = self.env.reset(seed=seed, options=options)
        self._frames = deque([obs] * (self.steps + 1), maxlen=self.steps + 1)
        return obs.copy(), info

    def step(self, action: Any) -> tuple[Any, SupportsFloat, bool, bool, dict[str, Any]]:
        obs, reward, terminated, truncated, info = self.env.step(action)
        self._frames.append(obs)
        return self._frames[0].copy(), reward, terminated, truncated, info


class FrameDrop(gym.Wrapper):
    """Dropped frames: at each step, with probability p, the previous observed frame is observed again.

    The draw comes from the env's ``np_random``. The reset frame is always observed.
    """

    def __init__(self, env: gym.Env, probability: float):
        probability = _validated("frame_drop", probability)
        _check_frame_space(env, "FrameDrop")
        super().__init__(env)
        self.probability = probability
        self._last: np.ndarray | None = None

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        obs, info = self.env.reset(seed=seed, options=options)
        self._last = obs
        return obs.copy(), info

    def step(self, action: Any) -> tuple[Any, SupportsFloat, bool, bool, dict[str, Any]]:
        assert self._last is not None, "FrameDrop.step before reset"
        obs, reward, terminated, truncated, info = self.env.step(action)
        if not self.np_random.random() < self.probability:
            self._last = obs
        return self._last.copy(), reward, terminated, truncated, info


# ---------------------------------------------------------------------------------------------
# Registry, parsing and placement
# ---------------------------------------------------------------------------------------------


#: Where an effect acts: on u ("actuator"), as an added torque ("passive"), as the speed clip ("clip"), on frames ("vision").
EffectKind = Literal["actuator", "passive", "clip", "vision"]


#: The stage of :mod:`piga.world.effects` that each kind of dynamics effect is a term of.
TERM_STAGE: dict[str, str] = {"actuator": "command", "passive": "torque", "clip": "velocity"}


@dataclass(frozen=True)
class EffectSpec:
    """One entry of :data:`EFFECTS`."""

    kind: EffectKind
    """One of "actuator" (acts on u), "passive" (adds a torque), "clip" (the speed clip), "vision" (acts on frames)."""
    meaning: str
    """What the value means, in a few words."""
    unit: str
    """The value's unit."""
    requirement: str
    """The allowed values, in words."""
    validator: Callable[[float], bool]
    """True for an allowed value."""
    wrapper: type[gym.Wrapper]
    """The wrapper class; ``wrapper(env, value)`` adds the effect."""
    integer: bool = False
    """Whether the value is a count (stored as int)."""
    term: Effect | None = None
    """The typed term of :mod:`piga.world.effects` whose equation the wrapper applies (None for a vision
    effect): the one definition that the diagnosis fits and the corrected planner simulates. Its unit is
    the engine's (per m·l²); :attr:`unit` is the environment's."""

    def __post_init__(self) -> None:
        if self.kind not in get_args(EffectKind):
            raise ValueError(f"EffectSpec.kind must be one of {', '.join(map(repr, get_args(EffectKind)))}; got {self.kind!r}")
        if (self.term is None) != (self.kind == "vision") or (
                self.term is not None and self.term.stage != TERM_STAGE[self.kind]):
            raise ValueError(f"EffectSpec: a {self.kind} effect needs a term of stage {TERM_STAGE.get(self.kind)!r}, "
                             f"got {self.term!r}")

    def validate(self, name: str, value: Any) -> int | float:
        """The value as stored (int for counts, else float); raises ValueError naming the effect and the range."""
        ok = _is_number(value) and (not self.integer or float(value).is_integer()) and self.validator(float(value))
        if not ok:
            raise ValueError(f"effect {name}={number_text(value)} is out of range: {name} must be {self.requirement} "
                             f"({self.meaning})")
        return int(value) if self.integer else float(value)


#: Every effect: name -> spec. The order is the canonical one, in which the effects are applied.
EFFECTS: dict[str, EffectSpec] = {
    "delay": EffectSpec("actuator", "actuator dead time", "steps", f"an integer >= 1 and <= {MAX_DELAY_STEPS}",
                        lambda v: 1 <= v <= MAX_DELAY_STEPS, ActionDelay, integer=True, term=DELAY),
    "deadzone": EffectSpec("actuator", "actuator deadzone half-width", "action units", f"in [{MIN_EFFECT:g}, {MAX_ACTION:g})",
                           lambda v: MIN_EFFECT <= v < MAX_ACTION, ActionDeadzone, term=DEADZONE),
    "saturation": EffectSpec("actuator", "actuator limit below 2", "action units", f"in [{MIN_EFFECT:g}, {MAX_ACTION:g})",
                             lambda v: MIN_EFFECT <= v < MAX_ACTION, ActionSaturation, term=SATURATION),
    "gain": EffectSpec("actuator", "actuator gain error factor", "factor",
                       f"in [{MIN_EFFECT:g}, {MAX_GAIN_ERROR:g}] and at least {MIN_EFFECT:g} from 1",
                       lambda v: MIN_EFFECT <= v <= MAX_GAIN_ERROR and abs(v - 1) >= MIN_EFFECT, ActionGainError, term=GAIN),
    "damping": EffectSpec("passive", "viscous damping coefficient", "N·m·s/rad", f"in [{MIN_EFFECT:g}, {MAX_PASSIVE:g}]",
                          lambda v: MIN_EFFECT <= v <= MAX_PASSIVE, ViscousDamping, term=DAMPING),
    "friction": EffectSpec("passive", "smoothed Coulomb friction torque", "N·m", f"in [{MIN_EFFECT:g}, {MAX_PASSIVE:g}]",
                           lambda v: MIN_EFFECT <= v <= MAX_PASSIVE, CoulombFriction, term=FRICTION),
    "bias": EffectSpec("passive", "constant torque bias", "N·m", f"a number within ±{MAX_PASSIVE:g}, at least {MIN_EFFECT:g} from 0",
                       lambda v: MIN_EFFECT <= abs(v) <= MAX_PASSIVE, TorqueBias, term=BIAS),
    "cogging": EffectSpec("passive", "cogging (detent) torque amplitude", "N·m", f"in [{MIN_EFFECT:g}, {MAX_PASSIVE:g}]",
                          lambda v: MIN_EFFECT <= v <= MAX_PASSIVE, CoggingTorque, term=COGGING),
    "speed_clip": EffectSpec("clip", "speed limit below Pendulum-v1's 8", "rad/s",
                             f"in [{MIN_SPEED_CLIP:g}, {PENDULUM_MAX_SPEED:g})",
                             lambda v: MIN_SPEED_CLIP <= v < PENDULUM_MAX_SPEED, SpeedClip, term=SPEED_CLIP),
    "blur": EffectSpec("vision", "Gaussian blur sigma", "px", f"in [{MIN_EFFECT:g}, {MAX_PIXELS:g}]",
                       lambda v: MIN_EFFECT <= v <= MAX_PIXELS, FrameBlur),
    "shift": EffectSpec("vision", "image shift right and down", "px", f"a number within ±{MAX_PIXELS:g}, at least {MIN_EFFECT:g} from 0",
                        lambda v: MIN_EFFECT <= abs(v) <= MAX_PIXELS, FrameShift),
    "exposure": EffectSpec("vision", "factor on every gray level (exposure, lighting)", "factor",
                           f"in [{MIN_EFFECT:g}, {MAX_GAIN_ERROR:g}] and at least {MIN_EFFECT:g} from 1",
                           lambda v: MIN_EFFECT <= v <= MAX_GAIN_ERROR and abs(v - 1) >= MIN_EFFECT, FrameExposure),
    "noise": EffectSpec("vision", "pixel noise standard deviation", "gray levels", f"in [{MIN_EFFECT:g}, {MAX_NOISE:g}]",
                        lambda v: MIN_EFFECT <= v <= MAX_NOISE, FrameNoise),
    "frame_delay": EffectSpec("vision", "camera latency", "steps", f"an integer >= 1 and <= {MAX_DELAY_STEPS}",
                              lambda v: 1 <= v <= MAX_DELAY_STEPS, FrameDelay, integer=True),
    "frame_drop": EffectSpec("vision", "probability of a dropped frame", "probability", f"in [{MIN_EFFECT:g}, 1)",
                             lambda v: MIN_EFFECT <= v < 1, FrameDrop),
}

#: Where :func:`wrap_effects` puts each effect in the pixel pendulum, innermost wrapper first.
#: "torque" lies between Pendulum-v1 and ActuationGain; "command" lies outside ActuationGain, so
#: that an action meets delay, deadzone, then saturation; "frame" lies after GrayscaleObservation.
STAGES: dict[str, tuple[str, ...]] = {
    "torque": ("speed_clip", "cogging", "bias", "friction", "damping", "gain"),
    "command": ("saturation", "deadzone", "delay"),
    "frame": ("blur", "shift", "exposure", "noise", "frame_delay", "frame_drop"),
}

Effects = tuple[tuple[str, float], ...]


def _canonical_name(name: Any) -> str:
    if not isinstance(name, str):
        raise TypeError(f"an effect name must be a string, got {name!r}")
    key = name.strip().lower().replace("-", "_")
    if key not in EFFECTS:
        raise ValueError(f"unknown effect {name!r}; valid effects: {', '.join(EFFECTS)}")
    return key


def parse_effect(text: str) -> tuple[str, int | float]:
    """Parses ``"NAME=VALUE"`` (for example ``"damping=0.2"``) into a checked ``(name, value)``.

    Names are those of :data:`EFFECTS`; ``-`` may stand for ``_`` (``speed-clip=6``).

    Raises:
        ValueError: no ``=``, an unknown name (the message lists the valid ones), a value that is
            not a number, or one out of range (the message gives the range).
    """
    name, sep, value_text = text.partition("=")
    if not sep or not name.strip():
        raise ValueError(f"expected an effect as NAME=VALUE, like damping=0.2, got {text!r}")
    key = _canonical_name(name)
    try:
        value = float(value_text)
    except ValueError:
        raise ValueError(f"effect {key}: expected a number after '=', got {value_text.strip()!r}") from None
    return key, EFFECTS[key].validate(key, value)


def normalize_effects(effects: Mapping[str, float] | Iterable[tuple[str, float]] | None) -> Effects:
    """Checked effects as ``((name, value), ...)`` in the canonical order of :data:`EFFECTS`.

    Accepts a mapping, pairs, or ``"NAME=VALUE"`` strings; each name may appear once.

    Raises:
        ValueError / TypeError: an unknown name, a bad value, or a name given twice.
    """
    if effects is None:
        return ()
    items: Iterable[Any] = effects.items() if isinstance(effects, Mapping) else effects
    if isinstance(items, (str, bytes)):
        raise TypeError(f"effects must be (name, value) pairs, got the string {items!r}")
    checked: dict[str, int | float] = {}
    for item in items:
        if isinstance(item, str):
            key, value = parse_effect(item)
        else:
            try:
                name, raw = item
            except (TypeError, ValueError):
                raise TypeError(f"an effect must be a (name, value) pair, got {item!r}") from None
            key = _canonical_name(name)
            value = EFFECTS[key].validate(key, raw)
        if key in checked:
            raise ValueError(f"effect {key!r} is given twice")
        checked[key] = value
    return tuple((name, checked[name]) for name in EFFECTS if name in checked)


def wrap_effects(env: gym.Env, effects: Effects, stage: str) -> gym.Env:
    """Wraps ``env`` in the wrappers of ``effects`` that belong to ``stage`` (see :data:`STAGES`)."""
    if stage not in STAGES:
        raise ValueError(f"unknown stage {stage!r}; expected one of {sorted(STAGES)}")
    given = dict(effects)
    for name in STAGES[stage]:
        if name in given:
            env = EFFECTS[name].wrapper(env, given[name])
    return env


def format_effects(effects: Effects) -> str:
    """``"damping=0.2 delay=2"``, or ``"none"``: each value as short as ``g`` writes it, unless that rounds it
    (``deadzone=1.999999`` is not 2, which the effect refuses): then in full."""
    return " ".join(f"{name}={number_text(value)}" for name, value in effects) or "none"


# ---------------------------------------------------------------------------------------------
# Passive torques that the explicit step cannot integrate
# ---------------------------------------------------------------------------------------------

#: Largest speed amplitude (rad/s) of the chatter that a strong ``friction`` makes where the pendulum would stick.
#: Pendulum-v1's explicit step cannot stop at θ̇ = 0: once k_τ·c·dt / 0.1 > 2 (c > 1.32 N·m at dt = 0.05) the speed
#: flips sign every step, with an amplitude of at most k_τ·c·dt / D (D = 2 at no stiffness; see
#: :func:`explicit_step_problem`). Measured over 40 sequences of 40 steps at g = 10 (its median chatter): 0.07 rad/s at
#: c = 2, 0.39 at 7, 0.74 at 10, 1.5 at 20, 3.8 at 50 (the speed then touches the ±8 clip), and 7.3 at 100, on the clip
#: in 42% of the steps, a video of a pendulum shaking between two angles. At 1 rad/s the angle jitters by
#: dt·1 = 0.05 rad, under a pixel at the tip of a 64 px frame (the rod is 14.5 px long): the frames show a pendulum
#: that sticks. The bound it gives, c <= 13.2 N·m at g = 10, lies above g/2 + 2 = 7 N·m, the most torque that gravity
#: and the motor exert together, beyond which a real pendulum sticks at every angle: no friction that changes what
#: the pendulum does is refused.
MAX_FRICTION_CHATTER = 1.0


def explicit_step_problem(effects: Mapping[str, float], gravity: float, dt: float) -> str | None:
    """Why Pendulum-v1's explicit step makes no meaningful recording of these passive effects, or None.

    Linearised at the hanging rest θ = π, where gravity (k_g·g) and the cogging detents (k_τ·4·k) both pull back
    hardest, the step θ̇' = θ̇ + dt·(-s·x - k_τ·b·θ̇), x' = x + dt·θ̇' (x = θ - π, s = k_g·g + 4·k_τ·k) has the
    matrix [[1 - s·dt², dt·(1 - k_τ·b·dt)], [-s·dt, 1 - k_τ·b·dt]]. Its eigenvalues stay inside the unit circle
    (the Jury test) while D = 2 - k_τ·b·dt - s·dt²/2 > 0: at g = 10 and dt = 0.05, damping b < 13.21 N·m·s/rad.
    Beyond it the speed flips sign every step and grows to the ±8 clip (measured with no action: b = 13.2 stays
    under 0.8 rad/s in 400 steps, 13.25 reaches the clip, 14 sits on it in 45% of the steps).

    Friction's slope at θ̇ = 0 (c / 0.1) is no such limit: past it the speed settles into a bounded chatter of
    amplitude at most k_τ·c·dt / D (the period-2 orbit of the same step with the friction torque saturated at ±c),
    refused above :data:`MAX_FRICTION_CHATTER`. Gravity so strong that the step is unstable without any effect
    (k_g·g·dt² >= 4, refused by :class:`envs.pendulum.PixelPendulumConfig`) is not blamed on the effects.
    """
    damping, friction, cogging = (float(effects.get(name, 0.0)) for name in ("damping", "friction", "cogging"))
    if not (damping or friction or cogging):
        return None
    gravity_gain, torque_gain = pendulum_gains()
    margin_free = 2.0 - gravity_gain * gravity * dt**2 / 2  # D with no effect
    if margin_free <= 0:
        return None
    stiffness = gravity_gain * gravity + COGGING_PERIODS * torque_gain * cogging
    stiff_margin = 2.0 - stiffness * dt**2 / 2  # D without damping
    margin = stiff_margin - torque_gain * damping * dt
    step = f"Pendulum-v1's explicit step (dt = {dt:g} s, gravity {number_text(gravity)})"
    if margin <= 0:
        if stiff_margin <= 0:  # cogging alone is too stiff: its detents would need dt·ω < 2
            limit = (4.0 / dt**2 - gravity_gain * gravity) / (COGGING_PERIODS * torque_gain)
            return (f"effect cogging={number_text(cogging)} N·m is too stiff for {step}: the pendulum's speed flips sign "
                    f"each step and grows to the speed clip; use cogging below {upper_bound_text(limit, 4)}")
        limit = stiff_margin / (torque_gain * dt)
        also = f" with cogging={number_text(cogging)} (or a weaker cogging)" if cogging else ""
        return (f"effect damping={number_text(damping)} N·m·s/rad is unstable in {step}: the pendulum's speed flips sign "
                f"each step and grows to the speed clip; use damping below {upper_bound_text(limit, 4)}{also}")
    chatter = torque_gain * friction * dt / margin
    if chatter > MAX_FRICTION_CHATTER:
        limit = MAX_FRICTION_CHATTER * margin / (torque_gain * dt)
        others = [(name, value) for name, value in (("damping", damping), ("cogging", cogging)) if value]
        also = " and ".join(f"{name}={number_text(value)}" for name, value in others)
        lower = " or ".join(name for name, _ in others)
        return (f"effect friction={number_text(friction)} N·m makes {step} chatter where the pendulum would stick: its "
                f"speed flips sign each step, by up to {chatter:.3g} rad/s; use friction of at most "
                f"{upper_bound_text(limit, 4)} (a chatter of {MAX_FRICTION_CHATTER:g} rad/s)"
                f"{f' with {also}, or lower {lower}' if also else ''}")
    return None


__all__ = [
    "EFFECTS",
    "PENDULUM_MAX_SPEED",
    "STAGES",
    "ActionDeadzone",
    "CoggingTorque",
    "ShowCommandedTorque",
    "ActionDelay",
    "ActionGainError",
    "ActionSaturation",
    "CoulombFriction",
    "EffectSpec",
    "FrameBlur",
    "FrameDelay",
    "FrameDrop",
    "FrameExposure",
    "FrameNoise",
    "FrameShift",
    "SpeedClip",
    "TorqueBias",
    "ViscousDamping",
    "MAX_FRICTION_CHATTER",
    "explicit_step_problem",
    "format_effects",
    "normalize_effects",
    "parse_effect",
    "wrap_effects",
]
