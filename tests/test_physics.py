"""Tests of piga.world.physics: against Gymnasium's own step, closed forms, gradcheck, and validation."""

from __future__ import annotations

import math

import gymnasium as gym
import numpy as np
import pytest
import torch
from torch import Tensor, nn

from piga.world.physics import (
    SYSTEMS,
    Bouncing,
    Euler,
    Gravity,
    Pendulum,
    Spring,
    System,
    make_system,
    rollout,
)

F64 = torch.float64


def _gym_pendulum_trajectory(theta0: float, thetadot0: float, actions: np.ndarray) -> np.ndarray:
    """States (T, 2) after each of Gymnasium Pendulum-v1's steps from a set state."""
    env = gym.make("Pendulum-v1").unwrapped
    env.reset(seed=0)
    env.state = np.array([theta0, thetadot0], dtype=np.float64)
    states = []
    for u in actions:
        env.step(np.array([u]))
        states.append(np.array(env.state, dtype=np.float64))
    env.close()
    return np.stack(states)


def _pendulum_rollout(theta0: float, thetadot0: float, actions: np.ndarray, substeps: int) -> np.ndarray:
    system = Pendulum(learnable=False).to(F64)
    system.set_parameters(g=10.0, a=1.0)  # the logs computed in float64, not rounded to float32
    p0 = torch.tensor([[[theta0]]], dtype=F64)
    v0 = torch.tensor([[[thetadot0]]], dtype=F64)
    u = torch.as_tensor(actions, dtype=F64).view(1, -1, 1)  # (1, T, 1)
    p, v = rollout(system, Euler(substeps=substeps), p0, v0, u)  # (1, T, 1, 1) each
    return torch.stack([p[0, :, 0, 0], v[0, :, 0, 0]], dim=-1).numpy()  # (T, 2)


@pytest.fixture
def pendulum_case() -> tuple[float, float, np.ndarray, np.ndarray]:
    rng = np.random.default_rng(1)
    theta0, thetadot0 = 2.5, -0.5
    actions = rng.uniform(-2.0, 2.0, size=50)
    expected = _gym_pendulum_trajectory(theta0, thetadot0, actions)
    # Precondition: Gymnasium's ±8 speed clip (not modelled) must never bind on this trajectory.
    assert np.abs(expected[:, 1]).max() < 7.5
    return theta0, thetadot0, actions, expected


def test_pendulum_one_substep_matches_gymnasium_step(pendulum_case) -> None:
    theta0, thetadot0, actions, expected = pendulum_case
    ours = _pendulum_rollout(theta0, thetadot0, actions, substeps=1)
    np.testing.assert_allclose(ours, expected, rtol=0, atol=1e-10)


def test_pendulum_five_substeps_stays_close_to_gymnasium(pendulum_case) -> None:
    theta0, thetadot0, actions, expected = pendulum_case
    ours = _pendulum_rollout(theta0, thetadot0, actions, substeps=5)
    # Substepping changes only the discretisation: per frame, θ moves by dt·v_new (Gymnasium) or by
    # the substeps' average, a difference of about 0.4·dt²·max|θ̈| ≈ 0.4 · 0.0025 · 21 ≈ 0.02 rad.
    first = np.abs(ours[0] - expected[0])
    assert first[0] < 0.02 and first[1] < 0.01, first
    err = np.abs(ours[:5] - expected[:5]).max(axis=0)  # first 5 frames: (θ, θ̇)
    assert err[0] < 0.1 and err[1] < 0.05, err


# ---------------------------------------------------------------------------- gradcheck
class _Rollout(nn.Module):
    """Wraps rollout so that torch.func.functional_call can swap the log-parameters."""

    def __init__(self, system: System, substeps: int) -> None:
        super().__init__()
        self.system = system
        self.integrator = Euler(substeps)

    def forward(self, p0: Tensor, v0: Tensor, actions: Tensor | None, steps: int) -> tuple[Tensor, Tensor]:
        return rollout(self.system, self.integrator, p0, v0, actions, steps)


def _gradcheck_system(system: System, p0: Tensor, v0: Tensor, actions: Tensor | None, steps: int) -> None:
    module = _Rollout(system.to(F64), substeps=3)
    names = [f"system.{name}" for name, _ in system.named_parameters()]
    params = [param.detach().clone().requires_grad_(True) for _, param in system.named_parameters()]
    inputs = [p0.requires_grad_(True), v0.requires_grad_(True)]
    if actions is not None:
        inputs.append(actions.requires_grad_(True))

    def fn(*args: Tensor) -> tuple[Tensor, Tensor]:
        state = args[: len(inputs)]
        u = state[2] if actions is not None else None
        overrides = dict(zip(names, args[len(inputs) :]))
        return torch.func.functional_call(module, overrides, (state[0], state[1], u, steps))

    assert torch.autograd.gradcheck(fn, (*inputs, *params))


def test_gradcheck_pendulum() -> None:
    gen = torch.Generator().manual_seed(0)
    p0 = torch.rand(2, 1, 1, generator=gen, dtype=F64) * 6 - 3
    v0 = torch.rand(2, 1, 1, generator=gen, dtype=F64) * 2 - 1
    u = torch.rand(2, 4, 1, generator=gen, dtype=F64) * 4 - 2
    _gradcheck_system(Pendulum(g=3.0, a=0.5), p0, v0, u, steps=4)


def test_gradcheck_spring() -> None:
    gen = torch.Generator().manual_seed(0)
    p0 = torch.rand(2, 2, 2, generator=gen, dtype=F64) * 20 + 6
    v0 = torch.rand(2, 2, 2, generator=gen, dtype=F64) - 0.5
    _gradcheck_system(Spring(k=2.0, l=3.0), p0, v0, None, steps=4)


def test_gradcheck_gravity() -> None:
    p0 = torch.tensor([[[10.0, 10.0], [20.0, 12.0], [14.0, 22.0]]], dtype=F64)
    v0 = torch.tensor([[[0.5, -0.5], [0.0, 1.0], [-0.5, 0.0]]], dtype=F64)
    _gradcheck_system(Gravity(g=30.0), p0, v0, None, steps=3)


def test_gradcheck_bouncing_through_a_bounce() -> None:
    # Ball 0 hits the right wall (x = 30) during the rollout; ball 1 hits the top (y = 2).
    p0 = torch.tensor([[[28.3, 10.0], [12.0, 3.1]]], dtype=F64)
    v0 = torch.tensor([[[5.0, 0.7], [1.0, -4.0]]], dtype=F64)
    system = Bouncing(size=32.0, radius=2.0)
    p, v = rollout(system.to(F64), Euler(3), p0, v0, steps=3)
    assert v[0, -1, 0, 0] < 0 and v[0, -1, 1, 1] > 0  # both bounced
    _gradcheck_system(system, p0, v0, None, steps=3)


# ----------------------------------------------------------------------- closed forms
def test_spring_two_balls_oscillate_with_the_analytic_period() -> None:
    k, l, amplitude = 4.0, 6.0, 3.0
    system = Spring(k=k, l=l, learnable=False).to(F64)
    p0 = torch.tensor([[[10.0, 16.0], [10.0 + 2 * l + amplitude, 16.0]]], dtype=F64)
    v0 = torch.zeros_like(p0)
    p, _ = rollout(system, Euler(substeps=200), p0, v0, steps=20)  # (1, 20, 2, 2)
    separation = (p[0, :, 1] - p[0, :, 0]).norm(dim=-1)  # (20,)
    # Relative coordinate: d'' = -2k (|d| - 2l), so |d| = 2l + A cos(sqrt(2k) t).
    t = system.dt * torch.arange(1, 21, dtype=F64)
    analytic = 2 * l + amplitude * torch.cos(math.sqrt(2 * k) * t)
    torch.testing.assert_close(separation, analytic, rtol=0, atol=0.02 * amplitude)
    # Momentum is conserved: the centre of mass stays put.
    centre = p[0].mean(dim=1)  # (20, 2)
    torch.testing.assert_close(centre, p0[0].mean(dim=0).expand_as(centre), rtol=0, atol=1e-9)


def test_gravity_two_bodies_in_circular_orbit_keep_their_distance() -> None:
    g, radius = 60.0, 10.0
    system = Gravity(n_objects=2, g=g, learnable=False).to(F64)
    speed = math.sqrt(g / (2 * radius))  # each body orbits the centre at radius / 2
    p0 = torch.tensor([[[16.0 - radius / 2, 16.0], [16.0 + radius / 2, 16.0]]], dtype=F64)
    v0 = torch.tensor([[[0.0, speed], [0.0, -speed]]], dtype=F64)
    period = 2 * math.pi * (radius / 2) / speed
    steps = math.ceil(period / system.dt)
    p, _ = rollout(system, Euler(substeps=100), p0, v0, steps=steps)  # (1, T, 2, 2)
    distance = (p[0, :, 1] - p[0, :, 0]).norm(dim=-1)
    assert (distance - radius).abs().max() < 0.01 * radius
    # And it really went around: the bodies passed through the opposite side.
    assert p[0, :, 0, 0].max() > 16.0 + 0.9 * radius / 2


def test_bouncing_reflects_off_a_wall_and_stays_inside() -> None:
    system = Bouncing(n_objects=1, size=32.0, radius=2.0, dt=1.0).to(F64)
    p0 = torch.tensor([[[29.0, 16.0]]], dtype=F64)
    v0 = torch.tensor([[[3.0, 0.0]]], dtype=F64)
    p, v = rollout(system, Euler(substeps=1), p0, v0, steps=1)
    # 29 + 3 = 32 overshoots the wall at 30 by 2, so it comes back to 28 with velocity -3.
    torch.testing.assert_close(p[0, 0, 0], torch.tensor([28.0, 16.0], dtype=F64))
    torch.testing.assert_close(v[0, 0, 0], torch.tensor([-3.0, 0.0], dtype=F64))

    gen = torch.Generator().manual_seed(0)
    many = Bouncing(n_objects=3, size=32.0, radius=2.0)
    p0 = torch.rand(16, 3, 2, generator=gen) * 28 + 2
    v0 = (torch.rand(16, 3, 2, generator=gen) - 0.5) * 20
    p, v = rollout(many, Euler(), p0, v0, steps=100)
    assert p.min() >= 2.0 and p.max() <= 30.0
    torch.testing.assert_close(v.abs(), v0.abs().unsqueeze(1).expand_as(v))  # speeds unchanged


# --------------------------------------------------------------------- parameters
@pytest.mark.parametrize("cls", [Pendulum, Spring, Gravity])
def test_parameters_start_away_from_truth_in_log_space(cls: type[System]) -> None:
    system = cls()
    values = system.parameters_dict()
    assert set(values) == set(cls.reference_values)
    for name, value in values.items():
        log_param = getattr(system, f"log_{name}")
        assert isinstance(log_param, nn.Parameter) and log_param.requires_grad
        assert getattr(system, name).item() == pytest.approx(math.exp(log_param.item()))
        assert value > 0
        assert abs(math.log(value / cls.reference_values[name])) > math.log(3), (name, value)
    names = {name for name, _ in system.named_parameters()}
    logs = {f"log_{n}" for n in values}
    assert logs <= names and names - logs <= {"offset"}  # only the pendulum's signed angle offset is not a log


def test_pendulum_offset_shifts_upright() -> None:
    system = Pendulum(g=10.0, a=1.0, offset=0.5)
    p = torch.tensor([[[-0.5]]])
    assert system.acceleration(p, torch.zeros_like(p)).abs().item() < 1e-6  # model angle -φ is upright
    assert system.offset.requires_grad
    assert not Pendulum(learnable=("g", "a")).offset.requires_grad


def test_oracle_values_and_parameters_dict() -> None:
    system = Pendulum(**Pendulum.reference_values, learnable=False)
    assert system.parameters_dict() == pytest.approx({"g": 10.0, "a": 1.0})
    assert not any(param.requires_grad for param in system.parameters())
    system.set_parameters(g=14.0)  # a counterfactual gravity
    assert system.parameters_dict() == pytest.approx({"g": 14.0, "a": 1.0})
    assert not system.log_g.requires_grad
    with pytest.raises(ValueError, match="Pendulum has no parameter 'k'; known: \\['g', 'a'\\]"):
        system.set_parameters(k=1.0)


def test_learnable_parameters_get_gradients_and_frozen_ones_do_not() -> None:
    system = Pendulum(learnable={"g"})
    assert system.log_g.requires_grad and not system.log_a.requires_grad
    p0 = torch.full((3, 1, 1), 0.5)
    v0 = torch.zeros(3, 1, 1)
    u = torch.ones(3, 5, 1)
    p, _ = rollout(system, Euler(), p0, v0, u)
    p.square().sum().backward()
    assert system.log_g.grad is not None and system.log_g.grad.abs() > 0
    assert system.log_a.grad is None

    spring = Spring(learnable=False)
    assert not any(param.requires_grad for param in spring.parameters())


def test_bouncing_has_no_parameters() -> None:
    system = Bouncing()
    assert list(system.parameters()) == [] and system.parameters_dict() == {}


# --------------------------------------------------------------------- validation
def test_bad_constructor_values_raise() -> None:
    with pytest.raises(ValueError, match="g must be finite and > 0, got -1"):
        Pendulum(g=-1.0)
    with pytest.raises(ValueError, match=r"unknown parameter name\(s\) \['m'\]"):
        Gravity(learnable={"m"})
    with pytest.raises(ValueError, match="substeps"):
        Euler(substeps=0)
    with pytest.raises(ValueError, match="size must be > 2 \\* radius"):
        Bouncing(size=4.0, radius=2.0)


def test_rollout_validates_shapes() -> None:
    system = Spring()
    p0 = torch.zeros(4, 2, 2)
    euler = Euler()
    with pytest.raises(ValueError, match=r"p0 must have shape \(B, N=2, D=2\).*\(4, 3, 2\)"):
        rollout(system, euler, torch.zeros(4, 3, 2), torch.zeros(4, 3, 2), steps=2)
    with pytest.raises(ValueError, match="v0 must have the shape of p0"):
        rollout(system, euler, p0, torch.zeros(4, 2, 1), steps=2)
    with pytest.raises(ValueError, match="needs `steps`"):
        rollout(system, euler, p0, p0)
    pendulum = Pendulum()
    q0 = torch.zeros(4, 1, 1)
    with pytest.raises(ValueError, match=r"actions must have shape \(B=4, T, A=1\)"):
        rollout(pendulum, euler, q0, q0, torch.zeros(4, 5, 2))
    with pytest.raises(ValueError, match=r"actions must have shape \(B=4, T, A=1\)"):
        rollout(pendulum, euler, q0, q0, torch.zeros(3, 5, 1))
    with pytest.raises(ValueError, match="steps=3 disagrees"):
        rollout(pendulum, euler, q0, q0, torch.zeros(4, 5, 1), steps=3)


def test_rollout_shapes_and_first_frame_uses_first_action() -> None:
    system = Pendulum(g=10.0, a=1.0)
    p0, v0 = torch.zeros(2, 1, 1), torch.zeros(2, 1, 1)
    actions = torch.zeros(2, 6, 1)
    actions[:, 0] = 1.0
    p, v = rollout(system, Euler(substeps=1), p0, v0, actions)
    assert p.shape == v.shape == (2, 6, 1, 1)
    # From rest at the top, only the first action moves it at all: v_1 = 3 a u dt.
    torch.testing.assert_close(v[:, 0, 0, 0], torch.full((2,), 3.0 * 0.05))


def test_make_system_registry() -> None:
    for name, cls in SYSTEMS.items():
        assert type(make_system(name)) is cls
    assert make_system("gravity", n_objects=2).n_objects == 2
    with pytest.raises(ValueError, match="unknown system 'pong'; known: bouncing, gravity, pendulum, spring"):
        make_system("pong")
