"""Gymnasium environments and wrappers that piga observes and controls.

Importing this package registers the env ids:

| id | what |
|---|---|
| ``piga/PixelPendulum-v0`` | Pendulum-v1 seen as 64x64 gray frames, one frame per observation |
| ``piga/PixelPendulumStack4-v0`` | the same with the last 4 frames stacked (for RL agents) |

``gym.make(id, **fields)`` accepts any field of :class:`PixelPendulumConfig`, including
``effects``, the unmodelled effects of :mod:`envs.effects`.
"""

import gymnasium as gym

from envs.constants import MAX_ACTION, PENDULUM_DT, PENDULUM_MAX_SPEED
from envs.effects import EFFECTS, FRICTION_SMOOTHING, normalize_effects, parse_effect
from envs.pendulum import (
    ActuationGain,
    HideTorqueArrow,
    PendulumStateInfo,
    PixelPendulumConfig,
    ResetRange,
    make_pixel_pendulum,
)

__all__ = [
    "EFFECTS",
    "FRICTION_SMOOTHING",
    "MAX_ACTION",
    "PENDULUM_DT",
    "PENDULUM_MAX_SPEED",
    "ActuationGain",
    "HideTorqueArrow",
    "PendulumStateInfo",
    "PixelPendulumConfig",
    "ResetRange",
    "make_pixel_pendulum",
    "normalize_effects",
    "parse_effect",
]

_IDS = {
    "piga/PixelPendulum-v0": {},
    "piga/PixelPendulumStack4-v0": {"frame_stack": 4},
}
for _id, _kwargs in _IDS.items():
    if _id not in gym.registry:
        # The truncation comes from Pendulum-v1's own TimeLimit inside the factory, so no
        # max_episode_steps here; disable_env_checker because check_env is run by the tests.
        gym.register(id=_id, entry_point="envs.pendulum:make_pixel_pendulum", kwargs=_kwargs,
                     disable_env_checker=True)
