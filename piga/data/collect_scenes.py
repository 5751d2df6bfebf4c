"""Collecting the paper's unactuated scenes (:mod:`envs.scenes`) into piga's HDF5 schema.

Determinism is the pendulum's (:mod:`piga.data.collect`): sequence n draws everything from
``SeedSequence(seed)``'s n-th child, so the arrays depend only on ``seed`` and the settings, not on
``workers``. Each batch of sequences is a farm of piga's job runner (:func:`piga.io.pool.run_pool`: one
job per sequence, in ``workers`` processes; no environment to step: a scene has no actions, so a
Gymnasium vector env would add nothing).

The file: ``/frames`` uint8 [N, T, H, W, 3], ``/actions`` float32 [N, T, 0], ``/states`` float32
[N, T, 4·n_objects] (x0, y0, x1, y1, ..., vx0, vy0, ...: pixels and pixels per second; evaluation
only), and the attrs ``system`` (the physics: "bouncing", "spring" or "gravity"), ``scene`` (the
picture, e.g. "digits-spring"), ``n_objects``, ``dt``, ``params`` (the true values), ``state_names``
and ``scene_config``.
"""

from __future__ import annotations

import functools
import shlex
import sys
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from piga.io.progress import progress_bar

from envs.scenes import SceneConfig, SceneError, check_forces_visible, generate_sequence, scene_config, state_names
from piga.io.atomic import check_writable_target
from piga.data.collect import COLLECT_DISK_ADVICE, check_collect_sizes, sequence_rng, split_counts
from piga.data.schema import SPLITS, DatasetWriter, check_data_disk
from piga.io.pool import JobFailed, run_pool
from piga.io.choices import check_types

#: Frames per sequence by scene: L + T_pred + T_ext of the chosen windows (docs/systems.md).
SCENE_STEPS: dict[str, int] = {"bouncing": 30, "spring": 30, "gravity": 40, "digits-spring": 30}



@dataclass(frozen=True)
class SceneCollectConfig:
    """What ``piga-collect --system SCENE`` gathers."""

    scene: SceneConfig = field(default_factory=lambda: scene_config("spring"))
    """The scene: physics, picture and starts (:class:`envs.scenes.SceneConfig`)."""
    sequences: int = 1000
    """N."""
    steps: int = 30
    """T, frames per sequence."""
    seed: int = 0
    """Root seed of every random draw."""
    workers: int = 2
    """Processes (1 runs in this process)."""
    split: tuple[float, float, float] = (0.8, 0.1, 0.1)
    """Train/valid/test, as fractions summing to 1 or as counts summing to ``sequences``."""
    batch: int = 64
    """Sequences gathered between writes to disk (bounds memory)."""

    def __post_init__(self) -> None:
        check_types(self)  # a value of the wrong kind named here, not met deep inside
        if not isinstance(self.scene, SceneConfig):
            raise TypeError(f"SceneCollectConfig.scene must be an envs.scenes.SceneConfig (envs.scenes.scene_config"
                            f"(NAME)); got {self.scene!r} ({type(self.scene).__name__})")
        check_collect_sizes(self.sequences, self.steps, self.workers, self.seed, self.batch, self.split,
                            type(self).__name__)
        if self.scene.half and self.steps <= self.scene.half_frames:
            raise ValueError(f"half data need more than {self.scene.half_frames} frames per sequence (the test "
                             f"sequences go down after them), got {self.steps}")


def _one(n: int, scene: SceneConfig, seed: int, steps: int, first_test: int) -> tuple[np.ndarray, np.ndarray]:
    """Sequence n of a collection: frames (T, H, W, 3) and states (T, 4N); sequences from ``first_test`` on are the
    test split's (which matters to :attr:`envs.scenes.SceneConfig.half`)."""
    _, rng = sequence_rng(seed, n)
    return generate_sequence(scene, rng, steps, test=n >= first_test)


def scene_attrs(config: SceneCollectConfig, command: str | None = None) -> dict[str, Any]:
    """The file attributes of a scene collection."""
    scene = config.scene
    return {
        "system": scene.physics,
        "scene": scene.scene,
        "n_objects": scene.n_objects,
        "dt": scene.dt,
        "params": dict(scene.params),
        "state_names": state_names(scene.n_objects),
        "scene_config": scene.to_dict(),
        "seed": config.seed,
        "command": command if command is not None else shlex.join(sys.argv),
        "split_counts": dict(zip(SPLITS, split_counts(config.sequences, config.split))),
    }


def scene_disk_need(config: SceneCollectConfig) -> tuple[float, float, int]:
    """The disk the data file of ``config`` takes, for :func:`piga.data.schema.check_data_disk`: the file once
    compressed (frames shrunk by :data:`piga.io.resources.SCENE_FRAME_COMPRESSION`, states raw, and HDF5's own
    bytes), a batch as it takes the disk (the room the writer keeps free), and the sequences."""
    from piga.io.resources import SCENE_FRAME_COMPRESSION, hdf5_file_overhead

    scene, n, t = config.scene, config.sequences, config.steps
    shrink = SCENE_FRAME_COMPRESSION["digits" if scene.scene == "digits-spring" else "balls"]
    step_bytes = 3 * scene.image_size**2 / shrink + 16 * scene.n_objects  # a frame compressed, its states raw
    return n * t * step_bytes + hdf5_file_overhead(n), min(config.batch, n) * t * step_bytes, n


def collect_scene(config: SceneCollectConfig, out: str | Path, overwrite: bool = False, command: str | None = None,
                  progress: bool = True) -> Path:
    """Simulates and renders ``config.sequences`` sequences and writes them to ``out`` atomically."""
    from piga.io.resources import check_memory

    check_writable_target(out, overwrite)
    scene, n, t = config.scene, config.sequences, config.steps
    size = scene.image_size
    what = f"{n} sequences x {t} frames of {size}x{size} RGB"  # before any simulation: a size that could never finish
    check_memory(min(config.batch, n) * t * (3 * size * size + 16 * scene.n_objects), what)
    check_data_disk(out, *scene_disk_need(config), what, advice=COLLECT_DISK_ADVICE)
    counts = split_counts(n, config.split)
    one = functools.partial(_one, scene=scene, seed=config.seed, steps=t, first_test=counts[0] + counts[1])
    # the bar outside the writer: one that refuses the file as it closes (blank frames) clears it
    with progress_bar(total=n, desc=f"collect {scene.scene}", unit="seq", disable=not progress) as bar:
        with DatasetWriter(out, n, t, (size, size, 3), 0, 4 * scene.n_objects, scene_attrs(config, command),
                           overwrite=overwrite) as writer:
            for start in range(0, n, config.batch):
                stop = min(start + config.batch, n)
                frames = np.zeros((stop - start, t, size, size, 3), np.uint8)
                states = np.zeros((stop - start, t, 4 * scene.n_objects), np.float32)

                def keep(row: int, sequence: tuple[np.ndarray, np.ndarray]) -> None:
                    frames[row], states[row] = sequence
                    bar.update(1)

                # one batch per farm, so that memory holds one batch (the runner keeps a farm's results)
                try:
                    run_pool(one, range(start, stop), config.workers, progress=False, on_result=keep,
                             names=[f"sequence {i}" for i in range(start, stop)])
                except JobFailed as failed:  # a scene's own refusal (no start fits) is the scene's, not a job's
                    if isinstance(failed.cause, SceneError):
                        raise failed.cause from None
                    raise
                if start == 0:  # forces too weak to show: refused before more is simulated (the file is not kept)
                    check_forces_visible(scene, states)
                writer.write(start, frames, np.zeros((stop - start, t, 0), np.float32), states)
            writer.set_split(np.repeat(np.arange(3, dtype=np.int8), counts))
    return Path(out)


#: Sizes: 'default' (:class:`SceneCollectConfig`'s defaults, 1000 sequences) is small enough for a CPU;
#: 'paper' is the paper's 5000 / 500 / 500. A preset sets the sizes only: the scene and its frames per
#: sequence (:data:`SCENE_STEPS`) are the ``--system``'s.
SCENE_PRESETS: dict[str, SceneCollectConfig] = {
    "default": SceneCollectConfig(),
    "paper": SceneCollectConfig(sequences=6000, split=(5000, 500, 500)),
}


__all__ = ["SCENE_PRESETS", "SCENE_STEPS", "SceneCollectConfig", "collect_scene", "scene_attrs"]
