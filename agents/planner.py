"""The trajectory optimiser every agent plans with: CEM over a :class:`~agents.dynamics.Dynamics` and a :class:`~agents.cost.Cost`.

:class:`Planner` owns what no agent writes for itself: the action bounds, the warm start (the
last plan shifted by a step, forgotten at :meth:`Planner.reset`) and the seeded RNG (reseeded at
:meth:`Planner.reset`, so that an episode is deterministic for a seed). It knows no model and no
task: the dynamics predicts states, the cost scores them, and :func:`agents.cem.cem` searches.

Shapes: the start state is (S,) or (1, S); candidates are float32 actions (B, H, A); the dynamics
returns states (B, H, S); the cost gives (B, H) stage costs and an optional (B,) terminal cost. A
dynamics that can score a cost in the same pass (:class:`~agents.dynamics.FusedDynamics`, such as
the pendulum's compiled engine) is asked for that scorer, and the planner uses it instead.

The agents on top: :class:`agents.mpc.PendulumPlanner` (the piga agent and the oracle),
:class:`agents.swingup.SwingUpPlanner` (dm_control's pendulum) and
:class:`agents.planet.planner.PlanetAgent` (a latent state).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Literal

import numpy as np
import torch
from torch import Tensor

from agents.cem import cem, shift_warm_start
from agents.config import CEMConfig
from agents.cost import Cost, returns
from agents.dynamics import Dynamics, FusedDynamics

__all__ = ["Execute", "Planner", "WarmStart"]

WarmStart = Literal["off", "middle", "repeat"]
"""How a plan starts the next: "off" (every plan from the middle of the bounds, PlaNet's), or the
last CEM mean shifted by a step, its new last step filled with the middle of the bounds ("middle")
or the last step again ("repeat")."""

Execute = Literal["mean", "best"]
"""Which plan is returned: CEM's final mean (smoother) or the highest-scoring sample."""


class Planner:
    """CEM over ``dynamics`` and ``cost``, within bounds, warm-started, with its own seeded generator.

    Args:
        dynamics: what predicts the states.
        cost: what scores them (a plan may pass another cost, such as one with a new goal).
        low, high: (A,) action bounds.
        cem: CEM settings (a plan may pass others).
        warm_start: see :data:`WarmStart`.
        execute: see :data:`Execute`.
        seed: seed of :attr:`generator`, reseeded at each :meth:`reset`.
        device: where the candidates are drawn and scored (the dynamics' and the cost's device); a CUDA
            generator draws other numbers than the CPU's for the same seed.
    """

    def __init__(self, dynamics: Dynamics, cost: Cost, low: Sequence[float], high: Sequence[float], cem: CEMConfig,
                 warm_start: WarmStart = "repeat", execute: Execute = "mean", seed: int = 0,
                 device: str | torch.device = "cpu"):
        if warm_start not in ("off", "middle", "repeat") or execute not in ("mean", "best"):
            raise ValueError(f"warm_start must be 'off', 'middle' or 'repeat' and execute 'mean' or 'best', got "
                             f"{warm_start!r}, {execute!r}")
        self.dynamics = dynamics
        self.cost = cost
        self.low = torch.tensor(low, dtype=torch.float32, device=device)  # (A,)
        self.high = torch.tensor(high, dtype=torch.float32, device=device)  # (A,)
        self.cem = cem
        self.warm_start: WarmStart = warm_start
        self.execute: Execute = execute
        self.seed = seed
        self.generator = torch.Generator(device=device).manual_seed(seed)
        """The RNG of CEM's candidates and of a stochastic dynamics' samples (an agent may draw from it too)."""
        self._mean: Tensor | None = None  # (H, A) the next plan's warm start
        self._fusable = isinstance(dynamics, FusedDynamics)  # checked once: a protocol check costs more than a rollout

    @property
    def warm(self) -> bool:
        """Whether the next plan starts from the last one."""
        return self._mean is not None

    def reset(self) -> None:
        """Forgets the warm start and the dynamics' history, and reseeds (a new episode)."""
        self._mean = None
        self.generator.manual_seed(self.seed)
        self.dynamics.reset()

    def objective(self, state: Tensor, cost: Cost | None = None) -> Callable[[Tensor], Tensor]:
        """The closure CEM maximises: actions (B, H, A) -> returns (B,) from ``state`` (1, S)."""
        cost = self.cost if cost is None else cost
        generator = self.generator
        scorer = self.dynamics.fused(state, cost, generator) if self._fusable else None  # type: ignore[attr-defined]
        if scorer is not None:
            return scorer
        dynamics = self.dynamics
        return lambda actions: returns(cost, dynamics.rollout(state, actions, generator), actions)

    @torch.inference_mode()
    def plan(self, state: Tensor, cost: Cost | None = None, cem_config: CEMConfig | None = None) -> np.ndarray:
        """The plan (H, A), float32 within the bounds, from ``state`` ((S,) or (1, S)); advances the warm start.

        Args:
            state: the start state.
            cost: this plan's cost instead of the planner's.
            cem_config: this plan's CEM settings instead of the planner's (the horizon must stay).
        """
        state = state if state.dim() == 2 else state[None]  # (1, S)
        result = cem(self.objective(state, cost), self.low, self.high, self.cem if cem_config is None else cem_config,
                     init_mean=self._mean, generator=self.generator)
        if self.warm_start != "off":
            self._mean = shift_warm_start(result.mean, self.low, self.high, self.warm_start)
        if self.execute == "best":
            plan = result.actions  # a sample: within the bounds
        else:  # the mean of samples within the bounds, which a momentum can move out of them by a rounding
            plan = result.mean.clamp(self.low, self.high) if (cem_config or self.cem).momentum else result.mean
        return plan.cpu().numpy().astype(np.float32)

    def executed(self, action: np.ndarray) -> None:
        """Told the action (A,) that was sent (passed on to the dynamics, which may keep a history)."""
        self.dynamics.executed(action)

    def act(self, state: Tensor) -> np.ndarray:
        """The first action (A,) of the plan from ``state``, told to the dynamics as executed."""
        action = self.plan(state)[0]
        self.executed(action)
        return action
