"""Swing-up with a weak motor: CEM over a damped pendulum with an energy-aware cost.

dm_control's pendulum has a torque limit of 1, while holding the pole horizontal takes m·g·l ≈ 4.9
N·m: no plan that pushes straight up works, and a short horizon never sees the payoff of pumping.
The cost (:class:`agents.cost.EnergyCost`) therefore scores the pendulum's energy as well as its
angle, so that every step that pumps energy toward the upright's is rewarded, and the angle term
takes over near the top:

    cost_t = w_θ·(1 − cos θ_t) + w_E·((E_t − E*) / 2E*)² + w_u·u_t²,
    E = θ̇² / 2 + k_g·cos θ,  E* = k_g (upright at rest),  k_g = 1.5·g (θ̈ = k_g·sin θ + ...).

The planner reads k_g from its dynamics' :class:`agents.dynamics.PendulumModel` interface
(``gravity_gain``), so any pendulum dynamics that says its gravity gain plugs in.

The dynamics (:class:`DampedPendulumDynamics`) are piga's pendulum equation with its damping term
(:mod:`piga.world.effects`), θ̈ = 1.5·g·sin θ + 3·(a·u − b·θ̇), integrated by MuJoCo's semi-implicit Euler (damping implicit) or
by RK4, ``substeps`` per frame with the action held. With the environment's true g, a, b and
MuJoCo's integrator it is the oracle's model; with a piga model's learned values and integrator
it is the piga agent's. Angles are Gymnasium's convention (θ = 0 upright).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import torch
from torch import Tensor

from agents.config import CEMConfig
from piga.world.effects import DAMPING, pendulum_acceleration, pendulum_gains
from piga.world.physics import euler_step, rk4_step
from agents.cost import EnergyCost
from agents.dynamics import PendulumModel, pendulum_state, start_of
from agents.planner import Planner

__all__ = ["DampedPendulumDynamics", "SwingUpConfig", "SwingUpPlanner"]


class DampedPendulumDynamics:
    """θ̈ = k_g·sin θ + 3·(a·u − b·θ̇) on plain arrays (k_g = 1.5·g), for planning.

    The equation and the damping term are piga's (:func:`piga.world.effects.pendulum_acceleration`,
    :data:`piga.world.effects.DAMPING`), stepped by :func:`piga.world.physics.euler_step` (the
    damping taken implicitly, as MuJoCo's Euler does) or :func:`piga.world.physics.rk4_step`.

    Args:
        g, a, b: gravity, actuation gain (its sign included: a flipped actuation has a < 0) and damping,
            in piga's form.
        dt: seconds per frame.
        substeps: integration steps per frame, the action held.
        integrator: "euler" (semi-implicit, damping implicit: MuJoCo's Euler) or "rk4".
    """

    def __init__(self, g: float, a: float, b: float, dt: float, substeps: int = 1, integrator: str = "euler"):
        if not (g > 0 and a != 0 and b >= 0 and dt > 0 and substeps >= 1) or integrator not in ("euler", "rk4"):
            raise ValueError(f"need g > 0, a != 0, b >= 0, dt > 0, substeps >= 1 and integrator euler or rk4, got "
                             f"g={g}, a={a}, b={b}, dt={dt}, substeps={substeps}, integrator={integrator!r}")
        self.g, self.a, self.b = float(g), float(a), float(b)
        gravity_gain, torque_gain = pendulum_gains()
        self.k_g = gravity_gain * self.g
        """k_g = 1.5·g: the upright's energy per unit inertia (the planner's cost)."""
        self.damping_rate = torque_gain * self.b
        """3·b: the θ̇ coefficient of θ̈, taken implicitly by the Euler step."""
        self.dt, self.substeps, self.integrator = float(dt), int(substeps), integrator

    @property
    def gravity_gain(self) -> float:
        """k_g = 1.5·g (the :class:`agents.dynamics.PendulumModel` interface)."""
        return self.k_g

    def rollout(self, state: Tensor, actions: Tensor, generator: torch.Generator | None = None) -> Tensor:
        """States (B, H, 2) = (θ, θ̇) of the H frames after ``state`` (1, 2) under actions (B, H, 1)."""
        theta, theta_dot = start_of(state)
        b, steps = actions.shape[:2]
        h = self.dt / self.substeps
        drive = actions[..., 0].numpy().T.astype(np.float64) * self.a  # (H, B): a·u
        q = np.full(b, theta, np.float64)
        v = np.full(b, theta_dot, np.float64)
        states = np.empty((steps, b, 2), np.float32)  # (H, B, 2)
        for j in range(steps):
            if self.integrator == "euler":  # the damping implicit: MuJoCo's Euler
                undamped = lambda q, v, u=drive[j]: pendulum_acceleration(q, v, self.g, actuation=(1.0, u))  # noqa: E731
                for _ in range(self.substeps):
                    q, v = euler_step(undamped, q, v, h, implicit_damping=self.damping_rate)
            else:
                damped = lambda q, v, u=drive[j]: pendulum_acceleration(q, v, self.g, actuation=(1.0, u),  # noqa: E731
                                                                     passive=[(DAMPING, self.b)])
                for _ in range(self.substeps):
                    q, v = rk4_step(damped, q, v, h)
            states[j, :, 0], states[j, :, 1] = q, v
        return torch.from_numpy(states).transpose(0, 1)  # (B, H, 2)

    def reset(self) -> None:
        """Nothing to forget."""

    def executed(self, action: np.ndarray) -> None:
        """No history."""


@dataclass(frozen=True)
class SwingUpConfig:
    """Settings of the swing-up planner (energy-aware CEM)."""

    cem: CEMConfig = field(default_factory=lambda: CEMConfig(horizon=30, iterations=5, candidates=200, elites=20))
    """CEM settings: a horizon of 30 frames (1.2 s at dt 0.04) sees a swing."""
    max_action: float = 1.0
    """Actions are bounded to [-max_action, max_action] (DMC: 1)."""
    angle_weight: float = 1.0
    """w_θ, weight of 1 − cos θ."""
    energy_weight: float = 1.0
    """w_E, weight of ((E − E*) / 2E*)²: pumps energy while far from upright."""
    action_weight: float = 0.001
    """w_u, weight of u²."""
    warm_start: bool = True
    """Start each plan from the previous one, shifted by a step."""
    seed: int = 0
    """Seed of the planner's RNG."""


class SwingUpPlanner:
    """The shared :class:`~agents.planner.Planner` over a pendulum's dynamics (:class:`DampedPendulumDynamics`
    or any :class:`agents.dynamics.PendulumModel`) with the energy-aware cost of the module docstring,
    whose upright energy is the dynamics' ``gravity_gain``."""

    def __init__(self, dynamics: PendulumModel, config: SwingUpConfig = SwingUpConfig()):
        if not isinstance(dynamics, PendulumModel):
            raise TypeError(f"the swing-up planner needs a pendulum dynamics with a gravity_gain, got {type(dynamics).__name__}")
        self.config = config
        cost = EnergyCost(dynamics.gravity_gain, config.angle_weight, config.energy_weight, config.action_weight)
        self.optimizer = Planner(dynamics, cost, [-config.max_action], [config.max_action], config.cem,
                                 warm_start="repeat" if config.warm_start else "off", seed=config.seed)

    @property
    def dynamics(self) -> PendulumModel:
        """What the plans roll out."""
        return self.optimizer.dynamics  # type: ignore[return-value]

    def reset(self) -> None:
        """Forgets the warm start and reseeds (a new episode)."""
        self.optimizer.reset()

    def plan(self, theta: float, theta_dot: float) -> np.ndarray:
        """The first action (1,) of the plan from (θ, θ̇) (Gymnasium's convention), told to the dynamics as executed."""
        return self.optimizer.act(pendulum_state(theta, theta_dot))
