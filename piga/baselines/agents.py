"""A baseline's run folder as an episode agent (:mod:`piga.episodes`), whatever its kind."""

from __future__ import annotations

import os
from typing import Any

from piga.baselines.kinds import BASELINE_KINDS

__all__ = ["baseline_agent"]


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
