"""What a planner needs from a model: a batched rollout of the pendulum's state under action sequences.

The planner (:mod:`agents.mpc`) knows no model. Whatever predicts (θ, θ̇) plugs in through the
:class:`Dynamics` protocol: the learned physics of a piga model and the oracle's true physics
(both :class:`PendulumDynamics`), the physics corrected by a diagnosis
(:mod:`piga.control.corrected`), and later a latent model. States are in Gymnasium's
convention (θ = 0 upright), the one the planner scores in.

A dynamics that can also score its rollouts itself (:class:`ScoringDynamics`) saves the planner
building the trajectories as tensors: :class:`PendulumDynamics` rolls and scores the candidates in
one compiled loop.
"""

from __future__ import annotations

import math
from typing import NamedTuple, Protocol, runtime_checkable

import numba
import numpy as np
import torch
from torch import Tensor

from piga.world.effects import pendulum_gains, scaled_gravity
from piga.world.physics import Euler, Pendulum


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


class StageCost(NamedTuple):
    """Gymnasium's pendulum cost of a step, w_θ·wrap(θ − θ_goal)² + w_v·θ̇² + w_u·u², with
    wrap(x) = ((x + π) mod 2π) − π; a rollout's return is minus its sum over the horizon."""

    goal: float
    angle_weight: float
    velocity_weight: float
    action_weight: float

    def returns(self, angles: Tensor, speeds: Tensor, actions: Tensor) -> Tensor:
        """Returns (B,) of angles and speeds (B, H) under actions (B, H)."""
        # in place, on tiny tensors, where each operator call costs more than its arithmetic
        cost = torch.remainder(angles - (self.goal - math.pi), 2 * math.pi).sub_(math.pi).square_()
        if self.angle_weight != 1.0:
            cost.mul_(self.angle_weight)
        cost.addcmul_(speeds, speeds, value=self.velocity_weight).addcmul_(actions, actions, value=self.action_weight)
        return cost.sum(1).neg_()  # (B,)


@runtime_checkable
class ScoringDynamics(Dynamics, Protocol):
    """A :class:`Dynamics` that also scores its rollouts itself (faster than rolling out, then scoring)."""

    def returns(self, theta: float, theta_dot: float, actions: Tensor, cost: StageCost) -> Tensor:
        """``cost.returns`` (B,) of the rollouts from (θ, θ̇) under float32 actions (B, H, 1)."""
        ...


@numba.njit(cache=True, nogil=True)
def _pendulum_rollout(theta: np.float32, theta_dot: np.float32, actions: np.ndarray, h: np.float32, gravity_gain: np.float32,
                      torque_gain: np.float32, substeps: int, angles: np.ndarray, speeds: np.ndarray,
                      cost: np.ndarray, returns: np.ndarray) -> None:  # pragma: no cover (compiled)
    """Rolls the candidates of float32 ``actions`` (H, B) into ``angles`` and ``speeds`` (H, B);
    with a ``cost`` of 4 (goal, w_θ, w_v, w_u), also writes their returns (B,) into ``returns``."""
    steps, b = actions.shape
    scored = cost.shape[0] == 4
    two_pi = np.float32(2 * math.pi)
    inv_two_pi = np.float32(1 / (2 * math.pi))
    q = np.full(b, theta, np.float32)  # (B,) θ
    v = np.full(b, theta_dot, np.float32)  # (B,) θ̇
    if scored:
        returns[:] = 0
    for j in range(steps):  # steps outer, candidates inner: the rows stay in cache
        for i in range(b):
            u = actions[j, i]
            qi, vi = q[i], v[i]
            for _ in range(substeps):
                vi = vi + h * (gravity_gain * np.float32(math.sin(qi)) + torque_gain * u)  # semi-implicit Euler
                qi = qi + h * vi
            q[i], v[i] = qi, vi
            angles[j, i], speeds[j, i] = qi, vi
            if scored:
                d = qi - cost[0]
                d -= two_pi * np.floor((d + np.float32(math.pi)) * inv_two_pi)  # wrap(θ − θ_goal)
                returns[i] -= cost[1] * d * d + cost[2] * vi * vi + cost[3] * u * u


_NO_COST = np.zeros(0, np.float32)


class PendulumDynamics:
    """The pendulum engine of :class:`piga.world.physics.Pendulum` on plain arrays, for planning.

    θ̈ = k_g·sin θ + k_u·u with k_g = 3g / 2l and k_u = 3a / m l² (the gains of
    :func:`piga.world.effects.pendulum_gains`), integrated by semi-implicit Euler with ``substeps``
    substeps of dt / substeps per step, the action held over the step: what
    :class:`piga.world.physics.Euler` does with a :class:`~piga.world.physics.Pendulum`, up to float32
    rounding (``tests/test_planning_engine.py`` ties the two on random states and actions). Here θ is Gymnasium's angle: a model's angle
    offset φ is added to the state before planning, not inside the engine.

    Why not :func:`piga.world.physics.rollout` itself: a planning step rolls 200 candidates x 20 steps x
    5 CEM iterations, and on 200 numbers the fixed cost of each operator call dominates the
    arithmetic (an ``nn.Module`` call, parameter lookups and ``exp`` of the log-parameters every
    step). One numba-compiled loop over steps and candidates, which also scores the rollouts
    (:meth:`returns`), takes a fraction of the time of even in-place numpy operators per step
    (``benchmarks/plan_time.py`` times both).

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
        gravity_gain, torque_gain = pendulum_gains(length, mass)
        self.gravity_gain = gravity_gain * self.g
        """k_g = 3g / 2l."""
        self.torque_gain = torque_gain * self.a
        """k_u = 3a / m l²."""

    @classmethod
    def of(cls, system: Pendulum, integrator: Euler, gravity_mult: float = 1.0) -> PendulumDynamics:
        """The dynamics of a (learned) :class:`Pendulum` and its integrator, its g times ``gravity_mult``.

        Raises ValueError for a model this engine would plan wrongly: one that integrates with RK4
        or learned a damping b (``--preset continuous``; see ``agents.swingup`` for such systems).
        """
        if not isinstance(integrator, Euler) or getattr(system, "has_damping", False):
            raise ValueError("this model integrates within the frame or learned a damping (--preset continuous); the "
                             "pendulum planner's engine is semi-implicit Euler without damping (for dm_control's "
                             "pendulum use piga-control --env piga/DMCPendulum-v0)")
        p = system.parameters_dict()
        return cls(scaled_gravity(p["g"], gravity_mult), p["a"], system.dt, integrator.substeps, system.length, system.mass)

    def _roll(self, theta: float, theta_dot: float, actions: Tensor, cost: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Angles, speeds (H, B) and returns (B,) (zeros unless ``cost`` holds (goal, w_θ, w_v, w_u))."""
        u = np.ascontiguousarray(actions[..., 0].numpy().T, dtype=np.float32)  # (H, B)
        angles, speeds = np.empty_like(u), np.empty_like(u)
        returns = np.zeros(u.shape[1], np.float32)
        f = np.float32
        _pendulum_rollout(f(theta), f(theta_dot), u, f(self.dt / self.substeps), f(self.gravity_gain), f(self.torque_gain),
                          self.substeps, angles, speeds, cost, returns)
        return angles, speeds, returns

    def rollout(self, theta: float, theta_dot: float, actions: Tensor) -> tuple[Tensor, Tensor]:
        angles, speeds, _ = self._roll(theta, theta_dot, actions, _NO_COST)
        return torch.from_numpy(angles).T, torch.from_numpy(speeds).T  # (B, H) each

    def returns(self, theta: float, theta_dot: float, actions: Tensor, cost: StageCost) -> Tensor:
        """``cost.returns`` (B,) of the rollouts from (θ, θ̇) under float32 actions (B, H, 1), in one compiled loop."""
        _, _, returns = self._roll(theta, theta_dot, actions, np.array(cost, np.float32))
        return torch.from_numpy(returns)

    def reset(self) -> None:
        """Nothing to forget."""

    def executed(self, action: np.ndarray) -> None:
        """No history."""
