"""The shared planner: CEM over any Dynamics and Cost, its bounds, warm start and seeded generator, and
the fused scorers (the pendulum's compiled loop, the latent model's imagination) against rolling out, then scoring."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
import torch
from torch import Tensor

from agents.config import CEMConfig, MPCConfig
from agents.cost import PendulumCost, returns
from agents.dynamics import FusedDynamics, PendulumDynamics, pendulum_state
from agents.planner import Planner

SMALL = CEMConfig(horizon=6, iterations=6, candidates=300, elites=30)


class Linear:
    """x' = x + dt·(A x + u): a two-dimensional system with two actions, states (B, H, 2), with no scorer of its own."""

    def __init__(self, noise: float = 0.0):
        self.noise = noise
        self.executed_actions: list[np.ndarray] = []

    def rollout(self, state: Tensor, actions: Tensor, generator: torch.Generator | None = None) -> Tensor:
        x = state.float().expand(actions.shape[0], -1)  # (B, 2)
        out = []
        for t in range(actions.shape[1]):
            x = x + 0.5 * (torch.stack([x[:, 1], -x[:, 0]], 1) * 0.1 + actions[:, t])
            if self.noise:
                x = x + self.noise * torch.randn(x.shape, generator=generator)
            out.append(x)
        return torch.stack(out, 1)  # (B, H, 2)

    def reset(self) -> None:
        self.executed_actions = []

    def executed(self, action: np.ndarray) -> None:
        self.executed_actions.append(action)


class ToTarget:
    """Squared distance to a target at each step and, weighted, at the end."""

    def __init__(self, target: tuple[float, float], terminal_weight: float = 0.0):
        self.target = torch.tensor(target)
        self.terminal_weight = terminal_weight

    def stage(self, states: Tensor, actions: Tensor) -> Tensor:
        return (states - self.target).square().sum(-1) + 0.01 * actions.square().sum(-1)  # (B, H)

    def terminal(self, final: Tensor) -> Tensor | None:
        return self.terminal_weight * (final - self.target).square().sum(-1) if self.terminal_weight else None


def test_the_planner_steers_a_system_with_two_states_and_two_actions() -> None:
    planner = Planner(Linear(), ToTarget((1.0, -1.0)), [-1.0, -1.0], [1.0, 1.0], SMALL)
    state = torch.zeros(2)
    for _ in range(12):
        action = planner.act(state)
        assert action.shape == (2,) and action.dtype == np.float32 and np.all(np.abs(action) <= 1.0)
        state = Linear().rollout(state[None], torch.from_numpy(action).view(1, 1, 2))[0, 0]
    assert torch.allclose(state, torch.tensor([1.0, -1.0]), atol=0.15)
    assert len(planner.dynamics.executed_actions) == 12  # type: ignore[attr-defined]


def test_returns_add_the_terminal_cost() -> None:
    states, actions = torch.rand(4, 3, 2), torch.rand(4, 3, 2)
    plain, terminal = ToTarget((0.5, 0.5)), ToTarget((0.5, 0.5), terminal_weight=2.0)
    expected = plain.stage(states, actions).sum(1) + 2.0 * (states[:, -1] - 0.5).square().sum(-1)
    torch.testing.assert_close(returns(terminal, states, actions), -expected)
    torch.testing.assert_close(returns(plain, states, actions), -plain.stage(states, actions).sum(1))


def test_warm_start_shifts_and_reset_reseeds_and_forgets() -> None:
    def planner(warm: str, noise: float = 0.1) -> Planner:
        return Planner(Linear(noise), ToTarget((1.0, -1.0)), [-1.0, -1.0], [1.0, 1.0], SMALL, warm_start=warm, seed=3)  # type: ignore[arg-type]

    warm = planner("repeat")
    first = [warm.plan(torch.zeros(2)) for _ in range(3)]
    assert warm.warm
    warm.reset()
    assert not warm.warm and not warm.dynamics.executed_actions  # type: ignore[attr-defined]
    again = [warm.plan(torch.zeros(2)) for _ in range(3)]
    for a, b in zip(first, again):  # the episode repeats: the generator reseeded, the warm start forgotten
        np.testing.assert_array_equal(a, b)
    cold = planner("off")
    np.testing.assert_array_equal(cold.plan(torch.zeros(2)), first[0])  # the first plan of an episode is cold
    assert not cold.warm and not np.array_equal(cold.plan(torch.zeros(2)), first[1])
    other = Planner(Linear(0.1), ToTarget((1.0, -1.0)), [-1.0, -1.0], [1.0, 1.0], SMALL, seed=4)
    assert not np.array_equal(other.plan(torch.zeros(2)), first[0])


def test_settings_are_checked() -> None:
    with pytest.raises(ValueError, match="warm_start"):
        Planner(Linear(), ToTarget((0, 0)), [-1.0], [1.0], SMALL, warm_start="on")  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="execute"):
        Planner(Linear(), ToTarget((0, 0)), [-1.0], [1.0], SMALL, execute="first")  # type: ignore[arg-type]
    with pytest.raises(ValueError, match=r"one start state \(1, 2\)"):
        PendulumDynamics(10.0, 1.0, 0.05).rollout(torch.zeros(3, 2), torch.zeros(3, 4, 1))


@pytest.mark.parametrize("substeps", [1, 3])
def test_the_compiled_loop_scores_like_rolling_out_then_scoring(substeps: int) -> None:
    """The fused pendulum scorer gives Gymnasium's cost of its own rollouts, wrap included (goals near ±π,
    angles far past a turn), and the planner takes that path for it; any other cost rolls out, then scores."""
    dynamics = PendulumDynamics(11.0, 1.3, 0.05, substeps)
    actions = torch.rand(64, 20, 1, generator=torch.Generator().manual_seed(1)) * 4 - 2
    for theta, speed, goal in [(3.0, 6.0, -3.1), (-2.0, -8.0, 3.1), (0.1, 0.0, 0.0), (7.0, 1.0, 1.0)]:
        cost = PendulumCost(goal, 0.7, 0.1, 0.001)
        state = pendulum_state(theta, speed)
        scorer = dynamics.fused(state, cost)
        assert scorer is not None
        torch.testing.assert_close(scorer(actions), returns(cost, dynamics.rollout(state, actions), actions),
                                   rtol=1e-5, atol=1e-3)
    assert isinstance(dynamics, FusedDynamics) and dynamics.fused(state, ToTarget((0.0, 0.0))) is None

    class RollOnly:  # the same physics without its own scoring: the planner's generic path
        def rollout(self, state: Tensor, actions: Tensor, generator: torch.Generator | None = None) -> Tensor:
            return dynamics.rollout(state, actions)

        def reset(self) -> None: ...

        def executed(self, action: np.ndarray) -> None: ...

    cost = PendulumCost(0.5, 1.0, 0.1, 0.001)
    fused = Planner(dynamics, cost, [-2.0], [2.0], SMALL)
    generic = Planner(RollOnly(), cost, [-2.0], [2.0], SMALL)
    state = pendulum_state(2.5, -1.0)
    torch.testing.assert_close(fused.objective(state)(actions), generic.objective(state)(actions), rtol=1e-5, atol=1e-3)


def test_the_swing_up_planner_takes_the_gravity_gain_from_the_interface() -> None:
    from agents.swingup import SwingUpConfig, SwingUpPlanner

    small = SwingUpConfig(cem=CEMConfig(horizon=5, iterations=2, candidates=20, elites=4))
    planner = SwingUpPlanner(PendulumDynamics(9.0, 0.5, 0.04), small)  # any pendulum that says its k_g
    assert planner.optimizer.cost.gravity_gain == pytest.approx(13.5)  # type: ignore[attr-defined]
    assert abs(float(planner.plan(3.0, 0.0)[0])) <= 1.0
    with pytest.raises(TypeError, match="gravity_gain"):
        SwingUpPlanner(Linear(), small)  # type: ignore[arg-type]


def test_the_latent_model_scores_in_one_pass_like_rolling_out_then_scoring() -> None:
    from agents.planet.config import RSSMConfig
    from agents.planet.planner import LatentDynamics, RewardCost
    from agents.planet.rssm import WorldModel

    torch.manual_seed(0)
    model = WorldModel(RSSMConfig(depth=4, deter_size=16, stoch_size=4, hidden_size=16, action_repeat=2)).eval()
    dynamics, cost = LatentDynamics(model), RewardCost(model)
    state = torch.randn(1, 20)  # [h, s]
    actions = torch.rand(9, 5, 1) * 4 - 2
    with torch.inference_mode():
        states = dynamics.rollout(state, actions, torch.Generator().manual_seed(5))
        assert states.shape == (9, 5, 20)
        scorer = dynamics.fused(state, cost, torch.Generator().manual_seed(5))
        assert scorer is not None and LatentDynamics(model, fast=False).fused(state, cost) is None
        assert dynamics.fused(state, RewardCost(WorldModel(model.config))) is None  # another model's reward head
        torch.testing.assert_close(scorer(actions), returns(cost, states, actions),
                                   rtol=1e-4, atol=1e-5)


def test_the_piga_agent_tells_any_state_reader_its_actions() -> None:
    """A reader is told each action through the StateReader protocol, zeros at the start of an episode."""
    from agents.mpc import PigaMPCAgent
    from piga.world.model import ModelConfig, PhysicsModel

    class Told:
        def __init__(self) -> None:
            self.actions: list[np.ndarray] = []

        def __call__(self, frames: np.ndarray) -> tuple[float, float]:
            return 3.0, 0.0

        def executed(self, action: np.ndarray) -> None:
            self.actions.append(np.array(action))

    reader = Told()
    config = replace(MPCConfig(), cem=CEMConfig(horizon=4, iterations=2, candidates=20, elites=4))
    agent = PigaMPCAgent(PhysicsModel(ModelConfig()), config, reader=reader)
    agent.reset()
    sent = [agent.act(np.zeros((4, 64, 64), np.uint8)) for _ in range(2)]
    assert len(reader.actions) == 3 and not reader.actions[0].any()
    np.testing.assert_array_equal(reader.actions[1:], sent)
