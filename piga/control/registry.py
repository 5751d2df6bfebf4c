"""A run folder as an episode agent, whatever its kind: the registry from :class:`piga.io.checkpoint.RunKind`
to the agent it runs as, and the panels of a baseline's control video."""

from __future__ import annotations

import os
from collections.abc import Callable

import numpy as np

from agents.protocol import Agent
from piga.evaluation.episodes import Recording
from piga.io.checkpoint import RunKind

__all__ = ["BASELINE_AGENTS", "baseline_agent", "episode_panels"]


def _planet_agent(run_dir: str | os.PathLike[str], seed: int) -> Agent:
    """:class:`agents.planet.planner.PlanetAgent` with PlaNet's planner settings, seeded with ``seed``."""
    from agents.planet.config import LatentPlannerConfig
    from agents.planet.planner import PlanetAgent
    from agents.planet.run import load_planet

    model, _ = load_planet(run_dir)
    return PlanetAgent(model, LatentPlannerConfig(seed=seed))


def _sb3_agent(run_dir: str | os.PathLike[str], seed: int) -> Agent:
    """:class:`agents.sb3.run.SB3Agent` (a deterministic policy: ``seed`` is not used)."""
    from agents.sb3.run import SB3Agent

    return SB3Agent.from_run(run_dir)


#: The agent of each baseline kind's run folder, given the folder and the planner's seed. (A piga run's
#: agent also needs the planner's settings and what it is told: :func:`piga.control.jobs.build_agent`.)
BASELINE_AGENTS: dict[RunKind, Callable[[str | os.PathLike[str], int], Agent]] = {
    RunKind.PLANET: _planet_agent,
    RunKind.DDPG: _sb3_agent,
}


def baseline_agent(kind: RunKind, run_dir: str | os.PathLike[str], seed: int = 0) -> Agent:
    """The agent of a baseline run (:data:`BASELINE_AGENTS`). Each has ``input_frames`` (1: it keeps its own
    history). Neither can be told a gravity change or a goal.

    Raises:
        ValueError: ``kind`` is not a baseline's.
    """
    if kind not in BASELINE_AGENTS:
        raise ValueError(f"not a baseline kind: {kind.value!r}; expected one of {', '.join(k.value for k in BASELINE_AGENTS)}")
    return BASELINE_AGENTS[kind](run_dir, seed)


def episode_panels(agent: Agent, recording: Recording) -> list[tuple[str, np.ndarray]]:
    """The panels of a baseline's control video (:func:`piga.evaluation.video.panels_video`): the real frames,
    and for a PlaNet-style agent its world model's reconstruction of each frame it read.

    Args:
        agent: the episode's agent (:func:`baseline_agent`).
        recording: one of :func:`piga.control.episodes.run_episodes`' recordings.

    Returns:
        ("real", uint8 (T, H, W)) and, for PlaNet-style, ("PlaNet belief", uint8 (T, H, W)): the
        decoded posterior at every R-th frame (R: the model's action repeat), shown for R steps.
    """
    frames = recording.frames[:-1]  # the frames the agent acted on
    panels = [("real", frames)]
    model = getattr(agent, "model", None)
    if model is not None and hasattr(model, "open_loop"):  # a PlaNet-style world model
        import torch

        from agents.planet.rssm import model_steps

        repeat = model.config.action_repeat
        steps, actions, _ = model_steps(torch.from_numpy(frames)[None], torch.from_numpy(recording.actions).float()[None],
                                        torch.zeros(1, len(frames)), repeat)
        decoded, _ = model.open_loop(steps, actions, steps.shape[1], torch.Generator().manual_seed(0))  # (1, L, C, H, W)
        belief = ((decoded[0, :, 0] + 0.5).clamp(0, 1) * 255).round().to(torch.uint8).numpy()  # (L, H, W)
        belief = np.repeat(belief, repeat, axis=0)
        belief = np.concatenate([belief, belief[-1:].repeat(len(frames) - len(belief), axis=0)])  # a tail under R steps
        panels.append(("PlaNet belief", belief))
    return panels
