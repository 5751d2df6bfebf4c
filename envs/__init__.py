"""Gymnasium environments and wrappers that piga observes and controls.

Importing this package registers the env ids:

| id | what |
|---|---|
| ``piga/PixelPendulum-v0`` | Pendulum-v1 seen as 64x64 gray frames, one frame per observation |
| ``piga/PixelPendulumStack4-v0`` | the same with the last 4 frames stacked (for RL agents) |
| ``piga/DMCPendulum-v0`` | dm_control's MuJoCo pendulum-swingup through a face-on camera (:mod:`envs.dmc`; needs ``piga[dmc]``) |

``gym.make(id, **fields)`` accepts any field of :class:`PixelPendulumConfig`, including
``effects``, the unmodelled effects of :mod:`envs.effects`; ``piga/DMCPendulum-v0`` any field of
:class:`envs.dmc.DMCPendulumConfig`.
"""

from typing import Literal, get_args

import gymnasium as gym

from envs.constants import MAX_ACTION, PENDULUM_DT, PENDULUM_MAX_SPEED
from envs.dmc import DMCPendulumConfig, MissingExtraError, make_dmc_pendulum
from envs.effects import EFFECTS, normalize_effects, parse_effect
from envs.pendulum import (
    ActuationGain,
    HideTorqueArrow,
    PendulumStateInfo,
    PixelPendulumConfig,
    ResetRange,
    make_pixel_pendulum,
)

__all__ = [
    "DMC_PENDULUM",
    "ENV_IDS",
    "PIXEL_PENDULUM",
    "EnvId",
    "DMCPendulumConfig",
    "MissingExtraError",
    "make_dmc_pendulum",
    "EFFECTS",
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

EnvId = Literal["piga/PixelPendulum-v0", "piga/DMCPendulum-v0"]
"""The pendulums that piga's commands collect from and control (and the SB3 baselines train on)."""
#: The envs of :data:`EnvId`, in order: Gymnasium's pixel pendulum first (the default).
ENV_IDS: tuple[EnvId, ...] = get_args(EnvId)
PIXEL_PENDULUM, DMC_PENDULUM = ENV_IDS

_IDS = {
    "piga/PixelPendulum-v0": ("envs.pendulum:make_pixel_pendulum", {}),
    "piga/PixelPendulumStack4-v0": ("envs.pendulum:make_pixel_pendulum", {"frame_stack": 4}),
    "piga/DMCPendulum-v0": ("envs.dmc:make_dmc_pendulum", {}),
}
for _id, (_entry, _kwargs) in _IDS.items():
    if _id not in gym.registry:
        # The truncation comes from the factory (Pendulum-v1's own TimeLimit, the DMC env's
        # episode), so no max_episode_steps here; disable_env_checker because check_env is run by the tests.
        gym.register(id=_id, entry_point=_entry, kwargs=_kwargs, disable_env_checker=True)
