"""Reading a PlaNet-style run (``piga-baseline planet``): its world model, without the training code."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from agents.planet.config import RSSMConfig
from agents.planet.rssm import WorldModel
from piga.io.checkpoint import CHECKPOINT, RunKind, read_checkpoint, unreadable

__all__ = ["load_planet"]


def load_planet(run_dir: str | Path) -> tuple[WorldModel, dict[str, Any]]:
    """The world model (eval mode) of a ``piga-baseline planet`` run, and its checkpoint."""
    ckpt = read_checkpoint(run_dir, RunKind.PLANET)
    try:
        model = WorldModel(RSSMConfig(**ckpt["rssm_config"]))
        model.load_state_dict(ckpt["model"])
    except Exception as exc:  # a foreign or damaged payload
        raise unreadable(Path(run_dir) / CHECKPOINT, RunKind.PLANET, exc) from None
    return model.eval(), ckpt
