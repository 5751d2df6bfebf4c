"""Gymnasium Pendulum-v1's constants, and piga's largest frame, in one place: the pendulum env, the effect wrappers and
the scenes use them.

This module imports nothing from :mod:`envs`, so that :mod:`envs.pendulum` can import
:mod:`envs.effects` (which needs these constants) without a cycle.
"""

from __future__ import annotations

#: Gymnasium's Pendulum-v1 torque limit: the action u lies in [-MAX_ACTION, MAX_ACTION].
MAX_ACTION = 2.0
#: Gymnasium's Pendulum-v1 integration step (s).
PENDULUM_DT = 0.05
#: Gymnasium's Pendulum-v1 speed clip (rad/s): θ̇ is clipped to ±PENDULUM_MAX_SPEED after each step.
PENDULUM_MAX_SPEED = 8.0

#: Largest frame side (pixels) that piga-collect draws, for either pendulum and every scene: MuJoCo renders it
#: off-screen, Gymnasium's render (500 px) is resized to it, and far larger frames would not fit a replay buffer (5000
#: px frames were collected, upscaled), nor train (2000 px frames of the spring scene needed 147 GiB).
MAX_IMAGE_SIZE = 1024

__all__ = ["MAX_ACTION", "MAX_IMAGE_SIZE", "PENDULUM_DT", "PENDULUM_MAX_SPEED"]
