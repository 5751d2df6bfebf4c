"""What a planner needs from a model: a batched rollout of the pendulum's state under action sequences.

The planner (:mod:`agents.mpc`) knows no model. Whatever predicts (θ, θ̇) plugs in through the
:class:`Dynamics` protocol: the learned physics of a piga model and the oracle's true physics
(both :class:`PendulumDynamics`), the physics corrected by a diagnosis
(:mod:`piga.diagnostics.corrected`), and later a latent model. States are in Gymnasium's
convention (θ = 0 upright), the one the planner scores in.
"""

from __future__ import annotations

from typing import Protocol

import numpy as np
import torch
from torch import Tensor

from piga.physics import Euler, Pendulum


class Dynamics(Protocol):
    """A batched model of the pendulum, in Gymnasium's convention (θ = 0 upright)."""

    def rollout(self, theta: float, theta_dot: float, actions: Tensor) -> tuple[Tensor, Tensor]:
        """Angles and velocities (B, H) of the H steps after (θ, θ̇) under float32 actions (B, H, 1)."""
        ...

    def reset(self) -> None:
        """Starts an episode (forgets any history)."""
        ...

    def executed(self, action: np.ndarray) -> None:
        """Told the action (1,) that was sent to the system (a model with an actuator delay keeps a history)."""
        ...


class PendulumDynamics:
    """The pendulum engine of :class:`piga.physics.Pendulum` on plain arrays, for planning.

    θ̈ = k_g·sin θ + k_u·u with k_g = 3g / 2l and k_u = 3a / m l², integrated by semi-implicit Euler
    with ``substeps`` substeps of dt / substeps per step, the action held over the step: what
    :class:`piga.physics.Euler` does with a :class:`~piga.physics.Pendulum`, up to float32
    rounding (tests/test_control.py compares them). Here θ is Gymnasium's angle: a model's angle
    offset φ is added to the state before planning, not inside the engine.

    Why not :func:`piga.physics.rollout` itself: a planning step rolls 200 candidates x 20 steps x
    5 CEM iterations, and on 200 numbers the fixed cost of each call dominates the arithmetic: an
    ``nn.Module`` call, parameter lookups and ``exp`` of the log-parameters every step, and a torch
    operator costs several times a numpy one on a (200,) float32 array.

    Args:
        g, a: gravity and actuation gain.
        dt: seconds per step.
        substeps: Euler substeps per step.
        length, mass: rod length l and mass m.
    """

    def __init__(self, g: float, a: float, dt: float, substeps: int = 1, length: float = 1.0, mass: float = 1.0):
        if not (g > 0 and a > 0 and dt > 0 and length > 0 and mass > 0) or substeps < 1:
            raise ValueError(f"need g, a, dt, length, mass > 0 and substeps >= 1, got g={g}, a={a}, dt={dt}, "
                             f"length={length}, mass={mass}, substeps={substeps}")
        self.g, self.a, self.dt, self.substeps = float(g), float(a), float(dt), int(substeps)
        self.gravity_gain = 3.0 * self.g / (2.0 * length)
        """k_g = 3g / 2l."""
        self.torque_gain = 3.0 * self.a / (mass * length**2)
        """k_u = 3a / m l²."""

    @classmethod
    def of(cls, system: Pendulum, integrator: Euler, gravity_mult: float = 1.0) -> PendulumDynamics:
        """The dynamics of a (learned) :class:`Pendulum` and its integrator, its g times ``gravity_mult``."""
        p = system.parameters_dict()
        return cls(p["g"] * gravity_mult, p["a"], system.dt, integrator.substeps, system.length, system.mass)

    def rollout(self, theta: float, theta_dot: float, actions: Tensor) -> tuple[Tensor, Tensor]:
        b, steps = actions.shape[:2]
        h = self.dt / self.substeps
        # In the angle increment d = h·θ̇ a substep is five in-place ufuncs on (B,) rows:
        # d <- d + h²·k_g·sin θ + h²·k_u·u, θ <- θ + d (the same semi-implicit Euler step).
        push = np.multiply(actions[..., 0].numpy().T, h * h * self.torque_gain, dtype=np.float32)  # (H, B): h²·k_u·u
        kick = np.float32(h * h * self.gravity_gain)
        angles = np.empty((steps, b), np.float32)
        moves = np.empty((steps, b), np.float32)
        q = np.full(b, theta, np.float32)  # (B,) θ, then a row of ``angles``
        d = np.full(b, h * theta_dot, np.float32)  # (B,) h·θ̇, then a row of ``moves``
        s = np.empty(b, np.float32)
        for j in range(steps):
            for _ in range(self.substeps):
                np.sin(q, out=s)
                s *= kick
                s += push[j]
                d = np.add(d, s, out=moves[j])
                q = np.add(q, d, out=angles[j])
        moves *= np.float32(1.0 / h)  # h·θ̇ -> θ̇
        return torch.from_numpy(angles).T, torch.from_numpy(moves).T  # (B, H) each

    def reset(self) -> None:
        """Nothing to forget."""

    def executed(self, action: np.ndarray) -> None:
        """No history."""
