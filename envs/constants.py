"""Gymnasium Pendulum-v1's constants, in one place: the pendulum env and the effect wrappers both use them.

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

__all__ = ["MAX_ACTION", "PENDULUM_DT", "PENDULUM_MAX_SPEED"]
