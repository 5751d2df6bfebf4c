"""agents.reward_head: the learned objective plugs into the one planner in place of Gymnasium's cost, reads piga's
own encoded state (the agent's, at control time) and is trained from frames, actions and rewards only."""

from __future__ import annotations

from pathlib import Path

import h5py
import pytest
import torch

from agents.config import MPCConfig
from agents.cost import returns
from agents.dynamics import PendulumDynamics, pendulum_state
from agents.mpc import EncoderReader, PendulumPlanner, PigaMPCAgent
from agents.reward_head import (LearnedCost, RewardHead, RewardHeadConfig, encoded_transitions, load_reward_head,
                                save_reward_head, train_reward_head)
from piga.data.schema import read_sequences
from piga.world.model import ModelConfig, PhysicsModel
from tests.helpers import copy_without

FAST = RewardHeadConfig(hidden=16, steps=60, batch_size=64)


@pytest.fixture(scope="module")
def model() -> PhysicsModel:
    torch.manual_seed(0)
    return PhysicsModel(ModelConfig(rec_frames="input", pred_frames=4)).eval()


def test_the_planner_scores_plans_with_the_learned_cost_instead_of_gymnasiums() -> None:
    head = RewardHead(RewardHeadConfig(hidden=8))
    dynamics = PendulumDynamics(10.0, 1.0, 0.05)
    planner = PendulumPlanner(dynamics, MPCConfig(), LearnedCost(head))
    assert isinstance(planner.cost(0.0), LearnedCost) and isinstance(planner.cost(0.5), LearnedCost)
    state = pendulum_state(0.3, -0.2)
    actions = torch.rand(5, 20, 1, generator=torch.Generator().manual_seed(0)) * 4 - 2  # (B, H, 1)
    objective = planner.optimizer.objective(state, planner.cost(0.0))  # not the engine's fused Gymnasium scorer
    states = dynamics.rollout(state, actions)  # (B, H, 2)
    with torch.no_grad():
        assert torch.allclose(objective(actions), head(states, actions).sum(1), atol=1e-5)
        gym = planner.optimizer.objective(state, PendulumPlanner(dynamics).cost(0.0))(actions)
        assert not torch.allclose(objective(actions), gym)
    assert planner.plan(0.3, -0.2).shape == (1,)
    with pytest.raises(ValueError, match="upright"):
        PendulumPlanner(dynamics, MPCConfig(goal_angle=0.2), LearnedCost(head))


def test_the_agent_plans_against_the_cost_it_is_given(model: PhysicsModel) -> None:
    cost = LearnedCost(RewardHead())
    agent = PigaMPCAgent(model, cost=cost)
    assert agent.planner.cost(0.0) is cost and returns(cost, torch.zeros(2, 3, 2), torch.zeros(2, 3, 1)).shape == (2,)


def test_encoded_states_are_those_the_agent_reads_at_control_time(model: PhysicsModel, tiny_data: Path) -> None:
    frames, actions = read_sequences(tiny_data, "train", limit=2)
    states, acts = encoded_transitions(model, frames, actions)
    length = model.config.input_frames
    assert states.shape == (2, frames.shape[1] - length + 1, 2) and torch.equal(acts, torch.from_numpy(actions[:, length - 1:]))
    for k in (0, 5):
        theta, speed = EncoderReader(model)(frames[1, k:k + length])
        assert states[1, k].tolist() == pytest.approx([theta, speed], abs=1e-5)


def test_the_head_learns_from_frames_actions_and_rewards_never_states(model: PhysicsModel, tiny_data: Path,
                                                                      tmp_path: Path) -> None:
    no_states = copy_without(tiny_data, tmp_path / "no_states.h5", "states")
    head, metrics = train_reward_head(model, no_states, FAST)
    again, _ = train_reward_head(model, tiny_data, FAST)  # /states there or not: the same head
    for a, b in zip(head.state_dict().values(), again.state_dict().values()):
        assert torch.equal(a, b)
    assert metrics["valid_abs_error"] is not None and metrics["train_transitions"] == 8 * (16 - model.config.input_frames + 1)
    scaled = tmp_path / "scaled.h5"
    scaled.write_bytes(no_states.read_bytes())
    with h5py.File(scaled, "a") as f:
        f["rewards"][...] = 10 * f["rewards"][()]
    other, _ = train_reward_head(model, scaled, FAST)  # the rewards are what it regresses
    x, u = torch.zeros(1, 2), torch.zeros(1, 1)
    assert not torch.allclose(other(x, u), head(x, u))
    save_reward_head(tmp_path / "head.pt", head, metrics)
    with torch.no_grad():
        assert torch.equal(load_reward_head(tmp_path / "head.pt")(x, u), head(x, u))


def test_the_config_refuses_nonsense() -> None:
    with pytest.raises(ValueError, match="lr must be a finite number > 0"):
        RewardHeadConfig(lr=0.0)
