"""The planners' engines follow the one pendulum definition (piga.world.physics / piga.world.effects)."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from agents.dynamics import PendulumDynamics, pendulum_state
from agents.swingup import DampedPendulumDynamics
from piga.world.physics import RK4, Euler, Pendulum, rollout


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_the_compiled_planning_engine_is_the_torch_definition(seed: int) -> None:
    """The numba kernel against Pendulum + Euler in float64, on random parameters, states and actions."""
    rng = np.random.default_rng(seed)
    g, a, length, mass = rng.uniform(5, 15), rng.uniform(0.3, 2), rng.uniform(0.5, 1.5), rng.uniform(0.5, 1.5)
    substeps = int(rng.integers(1, 6))
    system = Pendulum(g=g, a=a, length=length, mass=mass, learnable=False).double()
    dynamics = PendulumDynamics.of(system, Euler(substeps))
    actions = torch.from_numpy(rng.uniform(-2, 2, (32, 15, 1)).astype(np.float32))
    for theta, speed in rng.uniform([-np.pi, -8], [np.pi, 8], (4, 2)):
        states = dynamics.rollout(pendulum_state(theta, speed), actions)  # (B, H, 2) float32
        angles, speeds = states[..., 0], states[..., 1]
        start = torch.full((32, 1, 1), float(np.float32(theta)), dtype=torch.float64)
        p, v = rollout(system, Euler(substeps), start, torch.full_like(start, float(np.float32(speed))), actions.double())
        torch.testing.assert_close(angles.double(), p[..., 0, 0], atol=2e-4, rtol=1e-5)
        torch.testing.assert_close(speeds.double(), v[..., 0, 0], atol=2e-4, rtol=1e-5)


@pytest.mark.parametrize("seed", [0, 1])
def test_the_swing_up_engine_is_the_torch_definition(seed: int) -> None:
    """DampedPendulumDynamics with RK4 against Pendulum(damping=b) + RK4 in float64, a flipped actuation included."""
    rng = np.random.default_rng(seed)
    g, a, b, substeps = rng.uniform(5, 15), -rng.uniform(0.3, 2), rng.uniform(0.01, 0.5), int(rng.integers(1, 5))
    dynamics = DampedPendulumDynamics(g, a, b, 0.04, substeps, "rk4")
    system = Pendulum(g=g, a=a, damping=b, dt=0.04, signed_actuation=True, learnable=False).double()
    actions = torch.from_numpy(rng.uniform(-1, 1, (16, 20, 1)).astype(np.float32))
    theta, speed = rng.uniform(-np.pi, np.pi), rng.uniform(-6, 6)
    states = dynamics.rollout(pendulum_state(theta, speed), actions)  # (B, H, 2)
    angles, speeds = states[..., 0], states[..., 1]
    start = torch.full((16, 1, 1), theta, dtype=torch.float64)
    p, v = rollout(system, RK4(substeps), start, torch.full_like(start, speed), actions.double())
    torch.testing.assert_close(angles.double(), p[..., 0, 0], atol=1e-5, rtol=1e-6)
    torch.testing.assert_close(speeds.double(), v[..., 0, 0], atol=1e-5, rtol=1e-6)
