"""Integrators: small step functions over an acceleration, and the frame integrators built from them.

A step function advances generalised coordinates q and velocities q̇ by h under an acceleration
``f(q, q̇)`` (the action held, closed over by ``f``), as torchdiffeq's steps do. They are plain
arithmetic, so the same function steps a torch :class:`~piga.world.physics.systems.System`, the
diagnosis' candidate physics and the swing-up planner's numpy arrays. ``limit`` (a speed clip)
acts on each new velocity as soon as it is computed, so semi-implicit Euler moves with the limited
velocity.

:class:`Euler` and :class:`RK4` are the model's integrators: ``substeps`` steps per frame over a
system, with its constraints after each.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import torch
from torch import Tensor, nn

from piga.world.physics.systems import System

__all__ = ["Euler", "RK4", "INTEGRATORS", "euler_step", "rk4_step", "make_integrator", "hold_velocity",
           "shoot_velocity", "rollout"]

Array = Any
"""A torch tensor or a numpy array (or a float)."""
Acceleration = Callable[[Array, Array], Array]
"""f(q, q̇) -> q̈, the action held."""
Limit = Callable[[Array], Array]
"""q̇ -> the velocity the system keeps (a speed clip)."""


def euler_step(f: Acceleration, q: Array, v: Array, h: float, limit: Limit | None = None,
               implicit_damping: float | None = None) -> tuple[Array, Array]:
    """One semi-implicit Euler step: q̇ <- q̇ + h·f(q, q̇), then q <- q + h·q̇ with the *new* q̇.

    ``implicit_damping`` r (1/s) adds a damping −r·q̇ taken implicitly, as MuJoCo's Euler does:
    q̇ <- (q̇ + h·f(q, q̇)) / (1 + h·r), f then without that damping.
    """
    v = v + h * f(q, v)
    if implicit_damping is not None:
        v = v / (1.0 + h * implicit_damping)
    if limit is not None:
        v = limit(v)
    return q + h * v, v


def rk4_step(f: Acceleration, q: Array, v: Array, h: float, limit: Limit | None = None) -> tuple[Array, Array]:
    """One classical Runge-Kutta step of order 4 of (q, q̇) under f(q, q̇)."""
    a1 = f(q, v)
    v2 = v + 0.5 * h * a1
    a2 = f(q + 0.5 * h * v, v2)
    v3 = v + 0.5 * h * a2
    a3 = f(q + 0.5 * h * v2, v3)
    v4 = v + h * a3
    a4 = f(q + h * v3, v4)
    q = q + h / 6.0 * (v + 2.0 * v2 + 2.0 * v3 + v4)
    v = v + h / 6.0 * (a1 + 2.0 * a2 + 2.0 * a3 + a4)
    if limit is not None:
        v = limit(v)
    return q, v


class _Integrator(nn.Module):
    """An integrator with ``substeps`` substeps per frame (an int >= 1, else ValueError) of its :attr:`step`
    function over a system, the action held, and the system's constraints after each."""

    def __init__(self, substeps: int) -> None:
        super().__init__()
        if isinstance(substeps, bool) or not isinstance(substeps, int) or substeps < 1:
            raise ValueError(f"substeps must be an int >= 1, got {substeps!r}")
        self.substeps = substeps

    step: Callable[..., tuple[Tensor, Tensor]]
    """The step function: ``step(f, q, v, h)``."""

    def forward(
        self, system: System, p: Tensor, v: Tensor, u: Tensor | None = None
    ) -> tuple[Tensor, Tensor]:
        """Advance (p, v), each (B, N, D), by one frame under action u (B, A) or None."""
        h = system.dt / self.substeps
        f = lambda q, w: system.acceleration(q, w, u)  # noqa: E731 - the action held
        for _ in range(self.substeps):
            p, v = self.step(f, p, v, h)  # (B, N, D) each
            p, v = system.constrain(p, v)
        return p, v

    def extra_repr(self) -> str:
        return f"substeps={self.substeps}"


class Euler(_Integrator):
    """Semi-implicit Euler with ``substeps`` substeps per frame, as in the paper.

    Each substep of h = dt / substeps does ``v <- v + h·F(p, v, u)``, then ``p <- p + h·v`` with
    the *new* v, then ``system.constrain(p, v)``. The action is held over the frame. With
    ``substeps = 1`` this is exactly Gymnasium ``Pendulum-v1``'s step (without its speed clip).
    """

    def __init__(self, substeps: int = 5) -> None:
        super().__init__(substeps)

    step = staticmethod(euler_step)


class RK4(_Integrator):
    """Classical Runge-Kutta of order 4, ``substeps`` substeps per frame, the action held over the frame.

    A zero-order hold of a continuous system: the state follows θ̈ = F(θ, θ̇, u) with u constant
    over the frame, to O(h⁴) per frame. Use it for a real system (or a simulator with fine
    physics steps), where the motion within a frame matters: there the second difference of the
    frames sees part of the previous frame's action too, which one Euler step attributes to the
    current one. ``system.constrain`` is applied after each substep.
    """

    def __init__(self, substeps: int = 4) -> None:
        super().__init__(substeps)

    step = staticmethod(rk4_step)


INTEGRATORS: dict[str, type[nn.Module]] = {"euler": Euler, "rk4": RK4}
"""Name -> integrator class (both take ``substeps``)."""


def make_integrator(name: str, substeps: int) -> Euler | RK4:
    """The integrator registered as ``name`` with ``substeps`` substeps per frame."""
    try:
        cls = INTEGRATORS[name]
    except KeyError:
        raise ValueError(f"unknown integrator {name!r}; known: {', '.join(sorted(INTEGRATORS))}") from None
    return cls(substeps)  # type: ignore[return-value]


def hold_velocity(
    system: System,
    integrator: Callable[..., tuple[Tensor, Tensor]],
    p_prev: Tensor,
    v_chord: Tensor,
    u_prev: Tensor | None,
    iterations: int = 3,
) -> Tensor:
    """The velocity at a frame, read through the integrator from the frame before it (shooting).

    Finds the velocity v₀ at the previous frame whose one-frame step under ``u_prev`` moves the
    position by ``dt · v_chord`` (the observed displacement), by Newton steps with the slope
    approximated by dt, and returns the velocity that step ends with. For one Euler substep this
    is the backward difference itself; with substeps, or RK4, it adds what the held action and the
    forces did within the frame (for a continuous system: dt·F/2 more than the chord).

    Args:
        system: the system (its forces and dt).
        integrator: as in :func:`rollout`.
        p_prev: positions at the previous frame, (B, N, D).
        v_chord: the observed displacement per second over the last frame, (B, N, D) (angle
            differences already wrapped).
        u_prev: the action applied over the last frame, (B, A), or None.
        iterations: Newton steps; each shrinks the error by a factor ~ dt·∂F/∂v·dt.

    Returns:
        Velocities at the frame, (B, N, D).
    """
    return shoot_velocity(lambda q, v: integrator(system, q, v, u_prev), p_prev, v_chord, system.dt, iterations)


def shoot_velocity(frame: Callable[[Array, Array], tuple[Array, Array]], q_prev: Array, v_chord: Array, dt: float,
                   iterations: int) -> Array:
    """The velocity that one ``frame(q, q̇) -> (q', q̇')`` step ends with when it starts at ``q_prev`` and moves by
    ``dt · v_chord``: Newton steps on the start velocity, with the slope approximated by dt (:func:`hold_velocity`)."""
    target = v_chord * dt  # (B, N, D)
    v0 = v_chord
    for _ in range(iterations):
        q1, _ = frame(q_prev, v0)
        v0 = v0 + (target - (q1 - q_prev)) / dt
    _, v1 = frame(q_prev, v0)
    return v1


def rollout(
    system: System,
    integrator: Callable[..., tuple[Tensor, Tensor]],
    p0: Tensor,
    v0: Tensor,
    actions: Tensor | None = None,
    steps: int | None = None,
) -> tuple[Tensor, Tensor]:
    """Unroll the dynamics from (p0, v0) for T frames.

    Args:
        system: The system (forces, parameters, constraints).
        integrator: Called as ``integrator(system, p, v, u)`` for one frame, e.g. :class:`Euler`.
        p0: Initial positions, (B, N, D).
        v0: Initial velocities, (B, N, D).
        actions: (B, T, A); frame t + 1 is reached under ``actions[:, t]``. None for no actions
            (an actuated system then gets no torque).
        steps: T; required when ``actions`` is None, and must equal ``actions.shape[1]`` otherwise.

    Returns:
        Positions and velocities of the T frames after the initial one, each (B, T, N, D).
    """
    n, d = system.n_objects, system.coord_dim
    if p0.dim() != 3 or p0.shape[1:] != (n, d):
        raise ValueError(
            f"p0 must have shape (B, N={n}, D={d}) for {type(system).__name__}, got {tuple(p0.shape)}"
        )
    if v0.shape != p0.shape:
        raise ValueError(f"v0 must have the shape of p0 {tuple(p0.shape)}, got {tuple(v0.shape)}")
    if actions is not None:
        a = system.action_dim
        if actions.dim() != 3 or actions.shape[0] != p0.shape[0] or actions.shape[2] != a:
            raise ValueError(
                f"actions must have shape (B={p0.shape[0]}, T, A={a}) for "
                f"{type(system).__name__}, got {tuple(actions.shape)}"
            )
        if steps is not None and steps != actions.shape[1]:
            raise ValueError(f"steps={steps} disagrees with actions.shape[1]={actions.shape[1]}")
        steps = actions.shape[1]
    elif steps is None:
        raise ValueError("rollout needs `steps` when `actions` is None")
    if isinstance(steps, bool) or not isinstance(steps, int) or steps < 0:
        raise ValueError(f"steps must be an int >= 0, got {steps!r}")

    p, v = p0, v0
    positions: list[Tensor] = []
    velocities: list[Tensor] = []
    for t in range(steps):
        u = None if actions is None else actions[:, t]  # (B, A)
        p, v = integrator(system, p, v, u)  # (B, N, D) each
        positions.append(p)
        velocities.append(v)
    if not positions:
        empty = p0.new_empty((p0.shape[0], 0, n, d))
        return empty, empty.clone()
    return torch.stack(positions, dim=1), torch.stack(velocities, dim=1)  # (B, T, N, D) each


