"""Planner settings: plain dataclasses, no torch, so that command lines read their defaults from here quickly."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from piga.io.choices import check_ranges, check_types


#: Most model steps one CEM plan may take (candidates x horizon x iterations): 80 times PlaNet's 1.2e5, 500 times the
#: pendulum's default; beyond, each control step takes minutes and a tensor of candidates x horizon may not fit.
MAX_PLAN_STEPS = 10_000_000


@dataclass(frozen=True)
class CEMConfig:
    """CEM settings. The defaults are PlaNet's (Hafner et al., 2019)."""

    horizon: int = 12
    """H, planning steps."""
    iterations: int = 10
    """Refinement iterations."""
    candidates: int = 1000
    """Action sequences sampled per iteration."""
    elites: int = 100
    """Best sequences that refit the sampling distribution."""
    init_std: float = 1.0
    """Initial standard deviation, as a fraction of the half-width of the action bounds."""
    min_std: float = 0.0
    """Floor on the standard deviation (same units as the actions)."""
    momentum: float = 0.0
    """Weight of the previous mean and std in each refit (0: plain CEM)."""

    def __post_init__(self) -> None:
        check_types(self)  # a value of the wrong kind named here, not met deep inside
        if self.horizon < 1 or self.iterations < 1 or self.candidates < 2:
            raise ValueError(f"CEM needs horizon >= 1, iterations >= 1 and candidates >= 2, got horizon={self.horizon}, "
                             f"iterations={self.iterations}, candidates={self.candidates}")
        if (work := self.candidates * self.horizon * self.iterations) > MAX_PLAN_STEPS:
            raise ValueError(f"CEM candidates x horizon x iterations = {self.candidates} x {self.horizon} x "
                             f"{self.iterations} = {work:.3g} model steps per plan, more than {MAX_PLAN_STEPS:.0e}: a "
                             "control step would take minutes; lower the candidates, the horizon or the iterations")
        if not 1 <= self.elites <= self.candidates:
            raise ValueError(f"CEM elites must be in [1, candidates={self.candidates}], got {self.elites}")
        check_ranges(self, {"init_std": (0, math.inf), "min_std": (0, math.inf)}, above=("init_std",))
        if not (self.init_std > 0 and self.min_std >= 0 and 0 <= self.momentum < 1):
            raise ValueError(f"CEM needs init_std > 0, min_std >= 0 and 0 <= momentum < 1, got init_std={self.init_std}, "
                             f"min_std={self.min_std}, momentum={self.momentum}")


@dataclass(frozen=True)
class MPCConfig:
    """Planner settings. The CEM defaults are tuned for the pendulum (docs/commands/control.md)."""

    cem: CEMConfig = field(default_factory=lambda: CEMConfig(horizon=20, iterations=5, candidates=200, elites=20))
    """CEM settings."""
    goal_angle: float = 0.0
    """θ_goal in Gymnasium's convention (0 = upright)."""
    angle_weight: float = 1.0
    """Weight of wrap(θ - θ_goal)²."""
    velocity_weight: float = 0.1
    """Weight of θ̇²."""
    action_weight: float = 0.001
    """Weight of u²."""
    swing_up_angle: float = math.radians(60)
    """For a goal in the upper half (|θ_goal| < 90°): while the pendulum is farther than this from
    the goal, the planner scores against upright instead. Swinging up toward upright is
    symmetric and reliable; aiming straight at a tilted goal gets CEM stuck pushing one way at
    the torque limit (0 disables)."""
    warm_start: bool = True
    """Start each plan from the previous one, shifted by a step."""
    warm_fill: str = "repeat"
    """How the shifted warm start's new last step is filled: "middle" (0) or "repeat"."""
    warm_init_std: float | None = 0.3
    """CEM's initial std for warm-started plans near the goal, within ``swing_up_angle`` of it (None:
    always the cold start's ``cem.init_std``). Holding needs precise torques; swinging up needs
    exploration, or CEM gets stuck pushing at the torque limit."""
    execute: str = "mean"
    """Which plan acts: "best" (the highest-scoring sample) or "mean" (CEM's final mean, smoother)."""
    seed: int = 0
    """Seed of the planner's RNG."""

    def __post_init__(self) -> None:
        check_types(self)  # a value of the wrong kind named here, not met deep inside
        if not isinstance(self.cem, CEMConfig):
            raise TypeError(f"MPCConfig.cem must be a CEMConfig, got {self.cem!r}")
        check_ranges(self, {"goal_angle": (-2 * math.pi, 2 * math.pi), "angle_weight": (0, math.inf),
                            "velocity_weight": (0, math.inf), "action_weight": (0, math.inf),
                            "swing_up_angle": (0, math.pi), "warm_init_std": (0, math.inf)}, above=("warm_init_std",))
        if self.execute not in ("mean", "best") or self.warm_fill not in ("middle", "repeat"):
            raise ValueError(f"execute must be 'mean' or 'best' and warm_fill 'middle' or 'repeat', got "
                             f"{self.execute!r}, {self.warm_fill!r}")
