"""Closing the loop on a diagnosis: MPC on a simulated real system with the nominal vs the corrected physics."""

from __future__ import annotations

from typing import Any

from agents.mpc import MPCConfig
from piga.control.corrected import Correction
from piga.diagnostics.diagnose import Diagnosis
from piga.control.episodes import EpisodeConfig
from piga.control.jobs import ControlJob, run_jobs


def compare_control(model_dir: str, diagnosis: Diagnosis, effects: tuple[tuple[str, float], ...], episodes: int = 5,
                    seed: int = 0, workers: int = 2, progress: bool = False) -> dict[str, Any]:
    """Swing-up episodes on the pixel pendulum with ``effects``, planned with the identified model's
    physics and with the physics the diagnosis chose (same frames and planner; the corrected agent
    reads angles through the fitted camera when the diagnosis found one).

    Returns ``{"effects": ..., "rows": [summary with "physics": "nominal" | "corrected", ...]}``.
    """
    config = EpisodeConfig(episodes=episodes, seed=seed, effects=tuple(effects))
    mpc = MPCConfig(seed=seed)
    correction = Correction(diagnosis.corrected_model(), diagnosis.corrected_camera())
    jobs = [ControlJob("piga", config, mpc, model_dir, tags=(("physics", "nominal"),)),
            ControlJob("piga", config, mpc, model_dir, tags=(("physics", "corrected"),), correction=correction)]
    rows = [r.summary.to_dict() for r in run_jobs(jobs, workers=workers, progress=progress)]
    return {"effects": dict(effects), "rows": rows}
