"""Reading a PlaNet-style run (``piga-baseline planet``): its world model, without the training code."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import torch

from agents.planet.config import RSSMConfig
from agents.planet.rssm import WorldModel

#: The checkpoint's file name in a run folder.
CHECKPOINT = "checkpoint.pt"

__all__ = ["CHECKPOINT", "load_planet"]


def load_planet(run_dir: str | Path) -> tuple[WorldModel, dict[str, Any]]:
    """The world model (eval mode) of a ``piga-baseline planet`` run, and its checkpoint."""
    path = Path(run_dir) / CHECKPOINT
    if not path.exists():
        raise FileNotFoundError(f"{path}: no checkpoint (is {run_dir} a piga-baseline planet run folder?)")
    try:
        ckpt = torch.load(path, map_location="cpu", weights_only=False)
        model = WorldModel(RSSMConfig(**ckpt["rssm_config"]))
        model.load_state_dict(ckpt["model"])
    except Exception as exc:  # a truncated or foreign file
        raise ValueError(f"{path}: not a readable PlaNet-style checkpoint ({exc.__class__.__name__}: {exc})") from None
    return model.eval(), ckpt
