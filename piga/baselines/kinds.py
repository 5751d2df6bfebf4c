"""What a run folder holds: ``config.json``'s ``kind``.

| kind | written by | agent |
|---|---|---|
| ``piga`` | ``piga-train-model`` (its config.json has no ``kind``) | :class:`agents.mpc.PigaMPCAgent` |
| ``planet`` | ``piga-baseline planet`` | :class:`agents.planet.planner.PlanetAgent` |
| ``ddpg`` | ``piga-baseline ddpg`` | SB3 DDPG (:mod:`piga.baselines.ddpg`) |

This module imports neither torch nor SB3.
"""

from __future__ import annotations

import json
import os
from pathlib import Path

KINDS = ("piga", "planet", "ddpg")
"""Known run kinds."""

BASELINE_KINDS = ("planet", "ddpg")
"""Kinds that cannot be told a gravity change or given a goal."""


def run_kind(run_dir: str | os.PathLike[str]) -> str:
    """The kind of a run folder: ``config.json``'s ``kind``; "piga" when it has none (``piga-train-model``'s)
    or has no readable ``config.json`` (then loading the piga model says what is missing).

    Raises:
        ValueError: an unknown kind.
    """
    folder = Path(run_dir)
    try:
        record = json.loads((folder / "config.json").read_text())
    except (OSError, ValueError):
        record = {}
    kind = record.get("kind", "piga") if isinstance(record, dict) else "piga"
    if kind not in KINDS:
        raise ValueError(f"{folder}/config.json: unknown run kind {kind!r}; known: {', '.join(KINDS)}")
    return str(kind)


def require_piga_run(run_dir: str | os.PathLike[str], purpose: str) -> None:
    """Refuses a baseline's run folder where a ``piga-train-model`` run is needed, saying which it is.

    Args:
        purpose: what needs the piga run, e.g. "piga-diagnose diagnoses the identified physics".

    Raises:
        ValueError: ``run_dir`` is a planet or ddpg run (or of an unknown kind).
    """
    kind = run_kind(run_dir)
    if kind != "piga":
        raise ValueError(f"{run_dir} is a piga-baseline {kind} run; {purpose}, so it needs a run folder of "
                         "piga-train-model")


__all__ = ["BASELINE_KINDS", "KINDS", "require_piga_run", "run_kind"]
