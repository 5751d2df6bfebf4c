"""What every controller is to an episode runner (:mod:`piga.control.episodes`): one :class:`Agent` protocol."""

from __future__ import annotations

from typing import Protocol, runtime_checkable

import numpy as np

__all__ = ["Agent"]


@runtime_checkable
class Agent(Protocol):
    """A controller, for the pixel pendulum and dm_control's pendulum alike.

    The runner calls :meth:`reset` at each episode's start, then :meth:`act` once per env step.
    An agent that plans only at some steps (one that holds an action for several) may say so with a
    ``planned`` attribute, true at the steps where it planned: the runner then times only those.
    An agent that needs its own number of stacked frames says so with ``input_frames``.
    """

    def reset(self) -> None:
        """Starts an episode: forgets the last one's history and warm start."""
        ...

    def act(self, frames: np.ndarray, state: np.ndarray) -> np.ndarray:
        """The action (A,) after the observation: the last L frames uint8 (L, H, W) and the true state
        (S,), which only an oracle may read."""
        ...
