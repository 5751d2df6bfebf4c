"""Reading an SB3 baseline's run (``piga-baseline ddpg``, DDPG, SAC or DrQ-v2) and running it as an agent, without the training code."""

from __future__ import annotations

import io
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from agents.sb3.autoencoder import FrameAutoencoder, load_autoencoder
from agents.sb3.config import Algorithm, SB3Config
from piga.io.checkpoint import CHECKPOINT, RunKind, read_checkpoint, read_run_record, unreadable

__all__ = ["AUTOENCODER", "MODEL", "REPLAY_BUFFERS", "SB3Agent", "load_sb3", "sb3_class", "trained_env"]

#: The latest policy in SB3's format, beside the run's checkpoint.
MODEL = "model.zip"
#: A latent run's autoencoder.
AUTOENCODER = "autoencoder.pt"
#: The folder of a run's replay buffer, one file per checkpoint step (``STEP.pkl``, SB3's pickle), beside the
#: checkpoint that names it; earlier ones are removed once a newer checkpoint names its own.
REPLAY_BUFFERS = "replay_buffers"


def sb3_class(algo: Algorithm) -> Any:
    """The SB3 class of ``algo`` (DrQ-v2's: :class:`agents.sb3.drqv2.DrQV2`)."""
    from stable_baselines3 import DDPG, SAC

    from agents.sb3.drqv2 import DrQV2

    return {"ddpg": DDPG, "sac": SAC, "drqv2": DrQV2}[algo]


def trained_env(run_dir: str | Path) -> str:
    """The env an SB3 run was trained on, from its ``config.json`` (cheap: the checkpoint holds the replay buffer);
    the pixel pendulum for a run from before ``--env``, or without the file."""
    from envs import PIXEL_PENDULUM

    record, _ = read_run_record(run_dir)  # a pipe refused, not read
    settings = record.get("ddpg")
    return str(settings.get("env", PIXEL_PENDULUM)) if isinstance(settings, dict) else PIXEL_PENDULUM


def load_sb3(run_dir: str | Path) -> tuple[Any, SB3Config, FrameAutoencoder | None]:
    """The policy (SB3 ``DDPG`` or ``SAC``), its config and, for "latent", its autoencoder (else None)."""
    run_dir = Path(run_dir)
    ckpt = read_checkpoint(run_dir, RunKind.DDPG)
    try:
        config = SB3Config(**ckpt["config"])
        model = sb3_class(config.algo).load(io.BytesIO(ckpt["model_zip"]), device="cpu")
    except Exception as exc:  # a foreign or damaged payload
        raise unreadable(run_dir / CHECKPOINT, RunKind.DDPG, exc) from None
    encoder = load_autoencoder(run_dir / AUTOENCODER) if config.obs == "latent" else None
    return model, config, encoder


@dataclass
class SB3Agent:
    """A trained SB3 policy (DDPG or SAC) as an episode agent (:mod:`agents.protocol`).

    It keeps its own stack of the last K frames or codes, zeros at reset, exactly as SB3's
    ``VecFrameStack`` did in training, so it needs only the newest frame (``input_frames`` = 1).
    "state" reads (cos θ, sin θ, θ̇) from the true state that episodes pass to every agent.
    """

    model: Any
    """SB3 ``DDPG`` or ``SAC``."""
    config: SB3Config
    """The run's settings."""
    encoder: Any = None
    """For "latent": the :class:`~agents.sb3.autoencoder.FrameAutoencoder`."""
    input_frames: int = 1
    """Frames the agent needs per decision."""
    _stack: np.ndarray | None = field(default=None, repr=False)

    @classmethod
    def from_run(cls, run_dir: str | Path) -> SB3Agent:
        """The agent of a ``piga-baseline ddpg`` run folder."""
        model, config, encoder = load_sb3(run_dir)
        return cls(model, config, encoder)

    def reset(self) -> None:
        """Starts an episode: an empty (zero) stack."""
        self._stack = np.zeros(self.model.observation_space.shape, self.model.observation_space.dtype)

    def act(self, frames: np.ndarray, state: np.ndarray) -> np.ndarray:
        """Action (1,) from the newest frame (uint8 (L·C, H, W), C channels a frame), or from ``state`` for obs="state"."""
        if self.config.obs == "state":
            obs = np.array([np.cos(state[0]), np.sin(state[0]), state[1]], np.float32)
        else:
            if self._stack is None:
                self.reset()
            assert self._stack is not None
            if self.config.obs == "pixels":  # the newest frame's channels (1 gray, 3 RGB)
                new = frames[-(self._stack.shape[0] // self.config.frame_stack):]
            else:
                new = self.encoder.encode_frame(frames[-1])
            size = len(new)
            self._stack = np.concatenate([self._stack[size:], np.asarray(new, self._stack.dtype)])
            obs = self._stack
        action, _ = self.model.predict(obs, deterministic=True)
        return np.asarray(action, np.float32).reshape(1)
