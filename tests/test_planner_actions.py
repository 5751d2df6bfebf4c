"""Every planner's choices for a seed are pinned: the oracle, the piga agent (with its learned and with a
diagnosis' corrected physics), the dm_control swing-up planner and the PlaNet-style agent, each on a few
seeded episodes, against the actions stored in ``tests/data/planner_actions.npz``.

The stored actions are what the scenarios (:func:`scenarios`) chose when they were recorded: a change to
the planners that is not meant to change plans must reproduce them exactly. Record them again (only
after a change that is meant to change plans) with ``python -m tests.test_planner_actions``.
"""

from __future__ import annotations

import math
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import torch

DATA = Path(__file__).parent / "data" / "planner_actions.npz"


def _episode_actions(agent: object, **overrides: object) -> np.ndarray:
    """Actions (E, T) of the agent's seeded pixel-pendulum episodes (episode 0 from hanging down)."""
    from piga.control.episodes import EpisodeConfig, run_episodes

    config = EpisodeConfig(**{"episodes": 2, "steps": 20, "hold_steps": 1, **overrides})  # type: ignore[arg-type]
    result = run_episodes(agent, config, record=config.episodes)  # type: ignore[arg-type]
    return np.stack([r.actions for r in result.recordings]).astype(np.float32)


def _pendulum_model() -> object:
    """An untrained pendulum model with seeded weights (its learned g and a are its start values)."""
    from piga.world.model import ModelConfig, PhysicsModel

    torch.manual_seed(0)
    model = PhysicsModel(ModelConfig())
    with torch.no_grad():
        model.encoder.background.fill_(1.0)
    return model


def _swing_up_actions(planner: object, steps: int = 20) -> np.ndarray:
    """Actions (T,) that ``planner`` plans along a fixed sequence of states."""
    planner.reset()  # type: ignore[attr-defined]
    return np.array([planner.plan(math.pi - 0.15 * t, 2.0 * math.sin(0.5 * t))[0]  # type: ignore[attr-defined]
                     for t in range(steps)], np.float32)


def _planet_actions(fast: bool) -> np.ndarray:
    """Actions of the PlaNet-style agent with a seeded random world model: two pixel episodes, then exploration."""
    from agents.config import CEMConfig
    from agents.planet.config import LatentPlannerConfig, RSSMConfig
    from agents.planet.planner import PlanetAgent
    from agents.planet.rssm import WorldModel

    torch.manual_seed(0)
    model = WorldModel(RSSMConfig(depth=4, deter_size=16, stoch_size=4, hidden_size=16, action_repeat=2))
    config = LatentPlannerConfig(cem=CEMConfig(horizon=5, iterations=3, candidates=50, elites=5), seed=2)
    agent = PlanetAgent(model, config, fast=fast)
    episodes = _episode_actions(agent, frame_stack=1).ravel()
    frames = np.random.default_rng(0).integers(0, 256, (6, 1, 64, 64), dtype=np.uint8)
    rng = np.random.default_rng(1)
    agent.reset()
    explored = np.concatenate([agent.explore(f, rng, 0.3) for f in frames])
    return np.concatenate([episodes, explored])


def scenarios() -> dict[str, np.ndarray]:
    """The actions each planner chooses in its seeded scenarios, by name."""
    from agents.config import CEMConfig
    from agents.mpc import MPCConfig, OracleAgent, PigaMPCAgent
    from agents.swingup import DampedPendulumDynamics, SwingUpConfig, SwingUpPlanner
    from piga.control.corrected import Correction
    from piga.control.episodes import EpisodeConfig
    from piga.diagnostics import fit

    torch.set_num_threads(1)
    env = EpisodeConfig().env_config()
    out: dict[str, np.ndarray] = {}
    # the oracle: swing-up to upright; a tilted goal (scored against upright while far from it); a goal
    # near hanging down (the holding std from the second plan on); the best sample with a middle fill
    out["oracle"] = _episode_actions(OracleAgent.for_env(env, MPCConfig()))
    out["oracle_tilted_goal"] = _episode_actions(OracleAgent.for_env(env, MPCConfig(goal_angle=0.5, seed=1)), goal_angle=0.5)
    out["oracle_goal_near_down"] = _episode_actions(OracleAgent(10.0, 1.0, MPCConfig(goal_angle=2.8)), goal_angle=2.8)
    best = MPCConfig(execute="best", warm_fill="middle", warm_init_std=None, seed=3,
                     cem=CEMConfig(horizon=10, iterations=3, candidates=64, elites=8, momentum=0.2, min_std=0.05))
    out["oracle_best_middle"] = _episode_actions(OracleAgent(12.0, 0.9, best))
    out["oracle_cold"] = _episode_actions(OracleAgent(10.0, 1.0, MPCConfig(warm_start=False, seed=4)))
    # the piga agent: frames through the encoder, the learned physics (told gravity changed), or a diagnosis'
    # corrected physics (delay and damping: a dynamics that does not score its own rollouts)
    model = _pendulum_model()
    out["piga"] = _episode_actions(PigaMPCAgent(model, MPCConfig(seed=1), gravity_mult=1.3), episodes=1)  # type: ignore[arg-type]
    corrected = Correction(fit.Model(("damping", "delay"), 1, {"g": 9.0, "a": 1.1, "b": 0.2}))
    agent = PigaMPCAgent(model, MPCConfig(seed=2), dynamics=corrected.dynamics(model, 1.0))  # type: ignore[arg-type]
    out["piga_corrected"] = _episode_actions(agent, episodes=1)
    # the dm_control swing-up planner: semi-implicit Euler with the default settings, RK4 with a flipped actuation
    euler = DampedPendulumDynamics(9.81, 1.0 / 3, 0.1 / 3, 0.04, 2)
    out["swingup_euler"] = _swing_up_actions(SwingUpPlanner(euler))
    rk4 = DampedPendulumDynamics(12.0, -0.5, 0.05, 0.04, 2, "rk4")
    small = SwingUpConfig(cem=CEMConfig(horizon=15, iterations=3, candidates=60, elites=6), seed=5, warm_start=False)
    out["swingup_rk4"] = _swing_up_actions(SwingUpPlanner(rk4, replace(small, energy_weight=2.0)))
    # the PlaNet-style agent: the fast scorer and the reference one
    out["planet_fast"] = _planet_actions(fast=True)
    out["planet_reference"] = _planet_actions(fast=False)
    return out


@pytest.fixture(scope="module")
def chosen() -> dict[str, np.ndarray]:
    return scenarios()


EXACT = ["oracle", "oracle_tilted_goal", "oracle_goal_near_down", "oracle_best_middle", "oracle_cold", "piga",
         "piga_corrected", "swingup_euler", "swingup_rk4", "planet_fast", "planet_reference"]


@pytest.mark.parametrize("name", EXACT)
@pytest.mark.slow
def test_the_planners_choose_the_recorded_actions(chosen: dict[str, np.ndarray], name: str) -> None:
    recorded = np.load(DATA)
    assert set(recorded.files) == set(EXACT) == set(chosen)
    np.testing.assert_array_equal(chosen[name], recorded[name])


if __name__ == "__main__":
    DATA.parent.mkdir(exist_ok=True)
    np.savez_compressed(DATA, **scenarios())
    print(f"wrote {DATA}", file=sys.stderr)
