"""Reading a PlaNet-style run (``piga-baseline planet``): its world model, without the training code."""

from __future__ import annotations

import shutil
from pathlib import Path
from typing import Any

from agents.planet.config import RSSMConfig
from agents.planet.rssm import WorldModel
from piga.io.checkpoint import CHECKPOINT, RunKind, read_checkpoint, unreadable, write_checkpoint

__all__ = ["load_planet", "trained_frames", "write_selected"]


def load_planet(run_dir: str | Path) -> tuple[WorldModel, dict[str, Any]]:
    """The world model (eval mode) of a ``piga-baseline planet`` run, and its checkpoint."""
    ckpt = read_checkpoint(run_dir, RunKind.PLANET)
    try:
        model = WorldModel(RSSMConfig(**ckpt["rssm_config"]))
        model.load_state_dict(ckpt["model"])
    except Exception as exc:  # a foreign or damaged payload
        raise unreadable(Path(run_dir) / CHECKPOINT, RunKind.PLANET, exc) from None
    return model.eval(), ckpt


def trained_frames(run_dir: str | Path) -> dict[str, Any]:
    """What the checkpoint of a ``piga-baseline planet`` run says of the frames it was trained on: the data file's
    ``path``, ``image_shape``, ``dt`` (seconds between frames) and ``env_id`` (None for a file that names no env;
    absent in runs from before it was recorded); {} for a checkpoint that says nothing of them."""
    data = read_checkpoint(run_dir, RunKind.PLANET).get("data")
    return data if isinstance(data, dict) else {}


def write_selected(run_dir: str | Path, out_dir: str | Path) -> dict[str, Any]:
    """Writes ``out_dir``, a run folder whose model is ``run_dir``'s weights of the lowest valid loss (the
    checkpoint's ``best_model``, :func:`agents.planet.train.train_planet`), for every tool that reads a run; its
    checkpoint keeps no optimiser (it is for planning, not for more training). Returns ``{"step", "loss"}`` of the
    selected weights.

    Raises:
        ValueError: the run measured no valid loss (a file without a valid split, or a run trained before
            the valid loss was measured at each checkpoint).
    """
    ckpt = read_checkpoint(run_dir, RunKind.PLANET)
    state = ckpt["state"]
    if ckpt.get("best_model") is None or not state.get("best_step"):
        raise ValueError(f"{Path(run_dir) / CHECKPOINT}: no valid loss was measured during training, so no model "
                         "can be selected on it (does the data file have a valid split?)")
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    selected = {**ckpt, "model": ckpt["best_model"], "best_model": None, "optimizer": None,
                "state": {**state, "step": state["best_step"]}, "selected_from": str(run_dir)}
    write_checkpoint(out_dir, selected)
    if (Path(run_dir) / "config.json").exists():
        shutil.copy(Path(run_dir) / "config.json", out_dir / "config.json")
    return {"step": state["best_step"], "loss": state["best_valid_loss"]}
