"""The differentiable physics engine: systems as force functions over generalised coordinates, and integrators.

A :class:`System` knows the equations of motion of one family of scenes and holds their unknown
physical parameters (:mod:`.systems`); an integrator (:mod:`.integrators`) advances positions and
velocities by one frame with a small step function over the system's acceleration;
:func:`rollout` unrolls it over a sequence. Everything is plain PyTorch, so gradients flow to the
initial state (from the encoder and velocity estimator) and to the physical parameters.

| system | N | D | A | acceleration of object i (d = p_i - p_j) | dt | learned (init -> truth) |
|---|---|---|---|---|---|---|
| :class:`Pendulum` | 1 | 1 (angle) | 1 | (3 / 2l)·g·sin θ + (3 / m l²)·(a·u − b·θ̇), b optional | 0.05 | g 1 -> 10, a 0.3 -> 1 |
| :class:`Spring` | 2 | 2 | 0 | Σ_j -k·(abs(d) - 2l)·d / abs(d) | 0.3 | k 1 -> 4, l 1 -> 6 (balls) |
| :class:`Gravity` | 3 | 2 | 0 | Σ_j -g·m_j·d / abs(d)³ | 0.5 | g 1 -> 60 (m = 1); or m 1/g -> 1 (g fixed) |
| :class:`Bouncing` | 2 | 2 | 0 | 0, elastic walls | 0.3 | (none) |

Conventions:

- Shapes: generalised coordinates and their velocities are (B, N, D), actions (B, A), sequences
  (B, T, N, D). D is whatever coordinates an object has: an angle, a position (x, y), or a cart's
  position and its pole's angle; a system with a configuration-dependent mass matrix solves
  M(q)·q̈ = f(q, q̇, u) inside its :meth:`System.acceleration`.
- Positive parameters live in log space: ``log_g`` is the ``nn.Parameter``, ``g`` the property
  ``exp(log_g)``. Defaults start far from the truth on purpose: learning must find the values.
  :attr:`System.units` gives each parameter's unit.
- The pendulum follows Gymnasium's ``Pendulum-v1``: θ = 0 upright, positive counter-clockwise as
  displayed; its ±8 rad/s speed clip is deliberately *not* modelled. Its equation is
  :func:`piga.world.effects.pendulum_acceleration`, the one the diagnosis and the planners use.
- Cartesian systems work in pixel units (x right, y down), as the decoder does.

Integrators (the action held over the frame, a zero-order hold): :class:`Euler` (semi-implicit,
``substeps`` per frame; one substep is Gymnasium's pendulum exactly) and :class:`RK4` (classical
Runge-Kutta, ``substeps`` per frame), which follows a *continuous* system under a held action, as
a real motor or MuJoCo's fine physics steps act within a frame. Each is a loop over a step
function (:func:`euler_step`, :func:`rk4_step`) of an acceleration ``f(q, q̇)``, which the
diagnosis and the planners call on their own accelerations. :func:`hold_velocity` reads the
velocity at a frame from the last two positions *through* the integrator, which a backward
difference gets wrong as soon as the system moves within the frame.

Example::

    system = Pendulum()                      # learnable g = 1, a = 0.3
    p, v = rollout(system, Euler(substeps=5), p0, v0, actions)   # (B, T, 1, 1) each
"""

from piga.world.physics.integrators import (
    INTEGRATORS,
    RK4,
    Euler,
    euler_step,
    hold_velocity,
    make_integrator,
    rk4_step,
    rollout,
    shoot_velocity,
)
from piga.world.physics.systems import (SYSTEMS, Bouncing, BouncingOptions, Gravity, GravityOptions, Pendulum, PendulumOptions,
                                       Spring, SpringOptions, System, SystemOptions, make_system)

__all__ = [
    "System",
    "Pendulum",
    "Spring",
    "Gravity",
    "Bouncing",
    "Euler",
    "RK4",
    "INTEGRATORS",
    "euler_step",
    "rk4_step",
    "make_integrator",
    "hold_velocity",
    "shoot_velocity",
    "rollout",
    "make_system",
    "SYSTEMS",
    "SystemOptions",
    "PendulumOptions",
    "SpringOptions",
    "GravityOptions",
    "BouncingOptions",
]
