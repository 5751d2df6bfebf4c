"""A baseline's run folder as an episode agent (:mod:`piga.control.episodes`), whatever its kind."""

from __future__ import annotations

import os
from typing import Any

import numpy as np

from piga.baselines.kinds import BASELINE_KINDS

__all__ = ["baseline_agent", "episode_panels"]


def baseline_agent(kind: str, run_dir: str | os.PathLike[str], seed: int = 0) -> Any:
    """The agent of a baseline run: :class:`agents.planet.planner.PlanetAgent` (PlaNet's planner
    settings, seeded with ``seed``) for "planet", :class:`piga.baselines.ddpg.DDPGAgent` for "ddpg".

    Each has ``input_frames`` (1: it keeps its own history), ``reset()`` and ``act(frames, state)``.
    Neither can be told a gravity change or a goal.
    """
    if kind == "planet":
        from agents.planet.config import LatentPlannerConfig
        from agents.planet.planner import PlanetAgent
        from piga.baselines.planet_run import load_planet

        model, _ = load_planet(run_dir)
        return PlanetAgent(model, LatentPlannerConfig(seed=seed))
    if kind == "ddpg":
        from piga.baselines.ddpg import DDPGAgent

        return DDPGAgent.from_run(run_dir)
    raise ValueError(f"not a baseline kind: {kind!r}; expected one of {', '.join(BASELINE_KINDS)}")


def episode_panels(agent: Any, recording: dict[str, np.ndarray]) -> list[tuple[str, np.ndarray]]:
    """The panels of a baseline's control video (:func:`piga.evaluation.video.panels_video`): the real frames,
    and for a PlaNet-style agent its world model's reconstruction of each frame it read.

    Args:
        agent: the episode's agent (:func:`baseline_agent`).
        recording: one of :func:`piga.control.episodes.run_episodes`' recordings: frames uint8 (T+1, H, W),
            actions (T, 1).

    Returns:
        ("real", uint8 (T, H, W)) and, for PlaNet-style, ("PlaNet belief", uint8 (T, H, W)): the
        decoded posterior at every R-th frame (R: the model's action repeat), shown for R steps.
    """
    frames = recording["frames"][:-1]  # the frames the agent acted on
    panels = [("real", frames)]
    model = getattr(agent, "model", None)
    if model is not None and hasattr(model, "open_loop"):  # a PlaNet-style world model
        import torch

        from agents.planet.rssm import model_steps

        repeat = model.config.action_repeat
        steps, actions, _ = model_steps(torch.from_numpy(frames)[None], torch.from_numpy(recording["actions"]).float()[None],
                                        torch.zeros(1, len(frames)), repeat)
        decoded, _ = model.open_loop(steps, actions, steps.shape[1], torch.Generator().manual_seed(0))  # (1, L, C, H, W)
        belief = ((decoded[0, :, 0] + 0.5).clamp(0, 1) * 255).round().to(torch.uint8).numpy()  # (L, H, W)
        belief = np.repeat(belief, repeat, axis=0)
        belief = np.concatenate([belief, belief[-1:].repeat(len(frames) - len(belief), axis=0)])  # a tail under R steps
        panels.append(("PlaNet belief", belief))
    return panels
