"""What a planner needs from a model: a batched rollout of its state under action sequences.

The planner (:class:`agents.planner.Planner`) knows no model. Whatever predicts states plugs in
through the :class:`Dynamics` protocol: the learned physics of a piga model and the oracle's true
physics (both :class:`PendulumDynamics`), the physics corrected by a diagnosis
(:mod:`piga.control.corrected`), the damped pendulum of dm_control (:mod:`agents.swingup`) and a
latent model (:mod:`agents.planet.planner`). A pendulum's state is (θ, θ̇) in Gymnasium's
convention (θ = 0 upright), the one its costs (:mod:`agents.cost`) score in.

A dynamics that can roll out and score in one pass for some costs (:class:`FusedDynamics`) saves
the planner building the trajectories as tensors: :class:`PendulumDynamics` rolls and scores the
candidates for a :class:`~agents.cost.PendulumCost` in one compiled loop.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Protocol, runtime_checkable

import numba
import numpy as np
import torch
from torch import Tensor

from agents.cost import Cost, PendulumCost
from piga.world.effects import pendulum_gains, scaled_gravity
from piga.world.physics import Euler, Pendulum

__all__ = ["Dynamics", "FusedDynamics", "PendulumDynamics", "PendulumModel", "Scorer", "pendulum_state", "start_of"]

Scorer = Callable[[Tensor], Tensor]
"""actions (B, H, A) -> returns (B,) of the rollouts from one start state, rolled out and scored in one pass."""


class Dynamics(Protocol):
    """A batched model of a system's state under action sequences."""

    def rollout(self, state: Tensor, actions: Tensor, generator: torch.Generator | None = None) -> Tensor:
        """States (B, H, S) of the H steps after ``state`` under float32 actions (B, H, A).

        ``state`` is (1, S), one start shared by the B candidates (what a planner passes), or (B, S)
        where the dynamics says it takes one start per candidate. A stochastic model draws its
        samples from ``generator``.
        """
        ...

    def reset(self) -> None:
        """Starts an episode (forgets any history)."""
        ...

    def executed(self, action: np.ndarray) -> None:
        """Told the action (A,) that was sent to the system (a model with an actuator delay keeps a history)."""
        ...


@runtime_checkable
class FusedDynamics(Dynamics, Protocol):
    """A :class:`Dynamics` that rolls out and scores in one pass for the costs it knows (faster than
    rolling out, then scoring)."""

    def fused(self, state: Tensor, cost: Cost, generator: torch.Generator | None = None) -> Scorer | None:
        """A :data:`Scorer` of ``cost``'s returns (:func:`agents.cost.returns`) of this dynamics' rollouts
        from ``state`` (1, S), drawing any samples from ``generator``; None for a cost it cannot score itself."""
        ...


@runtime_checkable
class PendulumModel(Dynamics, Protocol):
    """A pendulum's :class:`Dynamics` over (θ, θ̇), θ̈ = k_g·sin θ + ..., that says its gravity gain k_g
    (what an energy-aware cost needs: the upright's energy at rest is k_g)."""

    @property
    def gravity_gain(self) -> float:
        """k_g = 3g / 2l."""
        ...


def pendulum_state(theta: float, theta_dot: float) -> Tensor:
    """A pendulum's start state (1, 2) = [[θ, θ̇]] for a planner, in float64 (each engine rounds it as it computes)."""
    return torch.from_numpy(np.array([[theta, theta_dot]], np.float64))


def start_of(state: Tensor) -> tuple[float, float]:
    """(θ, θ̇) of a pendulum state (1, 2) shared by all candidates; ValueError for anything else."""
    if state.shape != (1, 2):
        raise ValueError(f"this pendulum engine rolls every candidate from one start state (1, 2) = [[θ, θ̇]], "
                         f"got shape {tuple(state.shape)}")
    (theta, theta_dot), = state.tolist()
    return theta, theta_dot


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
    (:meth:`fused`), takes a fraction of the time of even in-place numpy operators per step
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
                             "pendulum planner's engine is semi-implicit Euler without damping")
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

    def rollout(self, state: Tensor, actions: Tensor, generator: torch.Generator | None = None) -> Tensor:
        """States (B, H, 2) = (θ, θ̇) of the H steps after ``state`` (1, 2) under float32 actions (B, H, 1)."""
        angles, speeds, _ = self._roll(*start_of(state), actions, _NO_COST)
        return torch.from_numpy(np.stack([angles, speeds], -1)).transpose(0, 1)  # (B, H, 2)

    def fused(self, state: Tensor, cost: Cost, generator: torch.Generator | None = None) -> Scorer | None:
        """For a :class:`~agents.cost.PendulumCost`: its returns (B,) of the rollouts from ``state`` (1, 2)
        under float32 actions (B, H, 1), rolled and scored in one compiled loop; None for other costs."""
        if not isinstance(cost, PendulumCost):
            return None
        theta, theta_dot = start_of(state)
        weights = np.array(cost, np.float32)  # (goal, w_θ, w_v, w_u)
        return lambda actions: torch.from_numpy(self._roll(theta, theta_dot, actions, weights)[2])

    def reset(self) -> None:
        """Nothing to forget."""

    def executed(self, action: np.ndarray) -> None:
        """No history."""
