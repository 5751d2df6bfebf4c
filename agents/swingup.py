"""Swing-up with a weak motor: CEM over a damped pendulum with an energy-aware cost.

dm_control's pendulum has a torque limit of 1, while holding the pole horizontal takes m·g·l ≈ 4.9
N·m: no plan that pushes straight up works, and a short horizon never sees the payoff of pumping.
The cost therefore scores the pendulum's energy as well as its angle, so that every step that
pumps energy toward the upright's is rewarded, and the angle term takes over near the top:

    cost_t = w_θ·(1 − cos θ_t) + w_E·((E_t − E*) / 2E*)² + w_u·u_t²,
    E = θ̇² / 2 + k_g·cos θ,  E* = k_g (upright at rest),  k_g = 1.5·g (θ̈ = k_g·sin θ + ...).

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

from agents.cem import cem, shift_warm_start
from agents.config import CEMConfig
from piga.world.effects import DAMPING, pendulum_acceleration, pendulum_gains
from piga.world.physics import euler_step, rk4_step

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

    def rollout(self, theta: float, theta_dot: float, actions: Tensor) -> tuple[Tensor, Tensor]:
        """Angles and velocities (B, H) of the H frames after (θ, θ̇) under actions (B, H, 1)."""
        b, steps = actions.shape[:2]
        h = self.dt / self.substeps
        drive = actions[..., 0].numpy().T.astype(np.float64) * self.a  # (H, B): a·u
        q = np.full(b, theta, np.float64)
        v = np.full(b, theta_dot, np.float64)
        angles = np.empty((steps, b), np.float32)
        speeds = np.empty((steps, b), np.float32)
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
            angles[j], speeds[j] = q, v
        return torch.from_numpy(angles).T, torch.from_numpy(speeds).T  # (B, H) each

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
    """CEM over a dynamics (:class:`DampedPendulumDynamics` or any :class:`agents.dynamics.Dynamics`)
    with the energy-aware cost of the module docstring. ``k_g`` (1.5·g) sets the upright's energy."""

    def __init__(self, dynamics: DampedPendulumDynamics, config: SwingUpConfig = SwingUpConfig()):
        self.dynamics = dynamics
        self.config = config
        self.low = torch.tensor([-config.max_action])
        self.high = torch.tensor([config.max_action])
        self.generator = torch.Generator().manual_seed(config.seed)
        self._mean: Tensor | None = None

    def reset(self) -> None:
        """Forgets the warm start and reseeds (a new episode)."""
        self._mean = None
        self.generator.manual_seed(self.config.seed)
        self.dynamics.reset()

    def objective(self, theta: float, theta_dot: float):  # noqa: ANN201 - a closure (B, H, 1) -> (B,)
        cfg = self.config
        k_g = self.dynamics.k_g

        def value(actions: Tensor) -> Tensor:
            q, v = self.dynamics.rollout(theta, theta_dot, actions)  # (B, H) each
            energy = 0.5 * v * v + k_g * torch.cos(q)  # (B, H)
            e = (energy - k_g) / (2 * k_g)
            u = actions[..., 0]
            cost = cfg.angle_weight * (1 - torch.cos(q)) + cfg.energy_weight * e * e + cfg.action_weight * u * u
            return -cost.sum(1)  # (B,)

        return value

    @torch.inference_mode()
    def plan(self, theta: float, theta_dot: float) -> np.ndarray:
        """The first action (1,) of the best plan from (θ, θ̇) (Gymnasium's convention)."""
        result = cem(self.objective(theta, theta_dot), self.low, self.high, self.config.cem, init_mean=self._mean,
                     generator=self.generator)
        if self.config.warm_start:
            self._mean = shift_warm_start(result.mean, self.low, self.high, "repeat")
        action = result.mean[0].numpy().astype(np.float32)
        self.dynamics.executed(action)
        return action

