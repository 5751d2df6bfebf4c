"""Control of dm_control's pendulum (:mod:`envs.dmc`) from pixels, scored in DMC's own units.

Two agents share one planner (:class:`agents.swingup.SwingUpPlanner`, energy-aware CEM):

- the oracle: the true state (``info["state"]``) and the true physics (the env's g, a, b in piga's
  form, MuJoCo's integrator and physics steps);
- the piga agent: frames only. The model's encoder reads the last L frames, its velocity estimator
  (through its integrator, with the action over the last frame, for a ``velocity_hold`` model)
  gives θ̇, and the planner rolls the model's *learned* g, a and b (0 without a learned damping)
  with the model's own integrator and substeps.

Episodes run in the one episode runner (:func:`piga.control.episodes.run_agent`). DMC's score of an
episode is its return (:attr:`piga.evaluation.episodes.EpisodeResult.return_`), the sum of its rewards
over 1000 physics steps of 0.02 s (at most 1000): the reward is 1 while the pole is within 8° of upright.
"""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass, field, replace
from typing import Any

import numpy as np

from agents.protocol import Agent
from agents.swingup import DampedPendulumDynamics, SwingUpConfig, SwingUpPlanner
from envs.dmc import DMCPendulumConfig, make_dmc_pendulum
from envs.fields import counted
from piga.control.episodes import EpisodeStart, Scoring, run_agent
from piga.evaluation.episodes import EpisodeBatch

__all__ = ["DMCControlConfig", "OracleSwingUp", "PigaSwingUp", "dmc_markdown", "dmc_record", "run_dmc_episodes"]


@dataclass(frozen=True)
class DMCControlConfig:
    """What ``piga-control --env piga/DMCPendulum-v0`` runs."""

    episodes: int = 10
    """Episodes of DMC's length (1000 physics steps)."""
    seed: int = 0
    """Episode e starts from ``reset(seed=seed + e)`` (DMC's reset: θ ~ U(-π, π) at rest)."""
    env: DMCPendulumConfig = field(default_factory=DMCPendulumConfig)
    """The environment (variants: mass, length, damping, flip)."""
    planner: SwingUpConfig = field(default_factory=SwingUpConfig)
    """The planner, the same for both agents; its RNG is seeded with ``seed`` (``piga-control --seed`` seeds the start
    states and the planner, on either env)."""

    def __post_init__(self) -> None:
        object.__setattr__(self, "planner", replace(self.planner, seed=self.seed))  # frozen: one seed, set once


class OracleSwingUp:
    """The planner with the true state and the env's true physics (MuJoCo's semi-implicit Euler)."""

    def __init__(self, env: DMCPendulumConfig, config: SwingUpConfig = SwingUpConfig()):
        p = env.piga_params()
        a = p["actuation_gain"] * (-1.0 if env.flip == "motor" else 1.0)  # in the hinge's own angle
        self.planner = SwingUpPlanner(DampedPendulumDynamics(p["g"], a, p["damping"], env.dt, env.action_repeat), config)

    def reset(self) -> None:
        self.planner.reset()

    def act(self, frames: np.ndarray, state: np.ndarray) -> np.ndarray:
        return self.planner.plan(float(state[0]), float(state[1]))


class PigaSwingUp:
    """Frames -> the model's (θ, θ̇) -> the planner over the model's learned physics. ``state`` is never read."""

    def __init__(self, model: Any, config: SwingUpConfig = SwingUpConfig()):
        from agents.mpc import EncoderReader

        if model.config.system != "pendulum":
            raise ValueError(f"a {model.config.system} model cannot control the pendulum")
        p = model.physical_parameters()
        self.offset = p.get("offset", 0.0)
        dynamics = DampedPendulumDynamics(p["g"], p["a"], p.get("b", 0.0), model.config.dt, model.config.substeps,
                                          model.config.integrator)
        self.planner = SwingUpPlanner(dynamics, config)
        self.reader = EncoderReader(model)
        self.input_frames = model.config.input_frames

    def reset(self) -> None:
        self.planner.reset()
        self.reader.executed(np.zeros(1, np.float32))

    def act(self, frames: np.ndarray, state: np.ndarray | None = None) -> np.ndarray:
        theta, theta_dot = self.reader(frames)
        action = self.planner.plan(theta + self.offset, theta_dot)
        self.reader.executed(action)
        return action


def run_dmc_episodes(agent: Agent, name: str, config: DMCControlConfig, frame_stack: int = 1,
                     progress: bool = False) -> EpisodeBatch:
    """Runs ``config.episodes`` DMC episodes of ``agent`` (episode e from ``reset(seed=seed + e)``, until DMC's
    time limit); the batch's summary is labelled ``agent=name``, and its returns are the DMC scores."""
    env = make_dmc_pendulum(replace(config.env, frame_stack=frame_stack, episode_length=0))
    starts = [EpisodeStart(config.seed + e) for e in range(config.episodes)]
    try:
        batch = run_agent(agent, env, starts, Scoring(), progress=progress, desc=name)
    finally:
        env.close()
    return batch.labelled(agent=name)


def dmc_record(batch: EpisodeBatch) -> dict[str, Any]:
    """The JSON record of a DMC batch: the agent, each episode's DMC score, their mean and std."""
    scores = batch.returns
    return {"agent": batch.summary.labels["agent"], "scores": scores, "mean": float(np.mean(scores)), "std": float(np.std(scores))}


def _seeds(first: int, episodes: int) -> str:
    """The episodes' seeds: "seed 3" for one, "seeds 3..7" for five."""
    return f"seed {first}" if episodes == 1 else f"seeds {first}..{first + episodes - 1}"


def dmc_markdown(results: list[EpisodeBatch], config: DMCControlConfig, command: str) -> str:
    """A Markdown table of the batches' DMC scores, with the command and the env."""
    lines = [f"Command: `{command}`", "",
             f"DMC pendulum-swingup through {'the face-on camera' if config.env.camera == 'face' else 'dm_control camera 0'}: "
             f"{json.dumps(config.env.to_dict())}; "
             f"{counted(config.episodes, 'episode')} of 1000 physics steps of 0.02 s (score: sum of DMC's reward, max "
             f"1000), {_seeds(config.seed, config.episodes)}.", "",
             "| agent | mean score | std | min | max |", "|---|---|---|---|---|"]
    for r in map(dmc_record, results):
        lines.append(f"| {r['agent']} | {r['mean']:.1f} | {r['std']:.1f} | {min(r['scores']):.0f} | {max(r['scores']):.0f} |")
    if any(r.summary.labels["agent"] in ("piga", "oracle") for r in results):  # an SB3 policy plans nothing
        lines += ["", f"Planner (piga and the oracle): {json.dumps(asdict(config.planner))}"]
    lines.append("")
    return "\n".join(lines)

