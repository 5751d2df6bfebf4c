"""Videos of control episodes: the real frame beside the model's rendering of its belief and plan (piga),
or beside what a baseline sees (:func:`panels_video`)."""

from __future__ import annotations

import os
import shutil
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import torch

from piga.io.atomic import atomic_output
from piga.world.model import PhysicsModel
from piga.world.physics import rollout

#: Display scale of the 64x64 frames.
UPSCALE = 4


def _panel(img: np.ndarray, label: str) -> np.ndarray:
    """uint8 (H, W) -> labelled, upscaled RGB panel."""
    big = cv2.resize(img, (img.shape[1] * UPSCALE, img.shape[0] * UPSCALE), interpolation=cv2.INTER_NEAREST)
    rgb = np.repeat(big[..., None], 3, axis=-1).copy()
    cv2.putText(rgb, label, (4, 14), cv2.FONT_HERSHEY_SIMPLEX, 0.4, (200, 30, 30), 1, cv2.LINE_AA)
    return rgb


@torch.no_grad()
def control_video(model: PhysicsModel, frames: np.ndarray, trace: list[tuple[float, float, np.ndarray]],
                  path: str | os.PathLike[str], fps: int = 20, overwrite: bool = False) -> Path:
    """Writes an MP4 or GIF: real frame | model's belief | model's plan (a trail of the planned states).

    Args:
        frames: uint8 (T+1, H, W), the episode's frames.
        trace: per step, the believed (θ, θ̇) in the model's convention and the plan (H, 1).
        path: ``.mp4`` or ``.gif``.
    """
    target = Path(path)
    if target.suffix.lower() not in (".mp4", ".gif"):
        raise ValueError(f"video path must end in .mp4 or .gif, got {target.name}")
    model.eval()
    out = []
    for t, (theta, theta_dot, plan) in enumerate(trace):
        p0 = torch.tensor([[[theta]]])
        belief = model.decoder(p0)[0, 0].numpy()
        positions, _ = rollout(model.system, model.integrator, p0, torch.tensor([[[theta_dot]]]),
                               torch.from_numpy(plan)[None])
        trail = model.decoder(positions[0]).numpy()[:, 0].min(axis=0)  # darkest over the plan: a trail
        panels = [_panel(frames[t], "real"), _panel((belief * 255).astype(np.uint8), "belief"),
                  _panel((trail * 255).astype(np.uint8), "plan")]
        out.append(np.concatenate(panels, axis=1))
    return _write(np.stack(out), target, fps, overwrite)


def panels_video(panels: list[tuple[str, np.ndarray]], path: str | os.PathLike[str], fps: int = 20,
                 overwrite: bool = False) -> Path:
    """Writes an MP4 or GIF of labelled gray panels side by side, one video frame per row.

    Args:
        panels: (label, uint8 (T, H, W)) pairs, all of the same T.
        path: ``.mp4`` or ``.gif``.
    """
    target = Path(path)
    if target.suffix.lower() not in (".mp4", ".gif"):
        raise ValueError(f"video path must end in .mp4 or .gif, got {target.name}")
    lengths = {len(frames) for _, frames in panels}
    if len(lengths) != 1:
        raise ValueError(f"panels of different lengths: {sorted(lengths)}")
    out = [np.concatenate([_panel(frames[t], label) for label, frames in panels], axis=1) for t in range(lengths.pop())]
    return _write(np.stack(out), target, fps, overwrite)


#: A GIF of these panels over their raw RGB frames, measured on piga's control videos of the pendulum (7.3% to
#: 7.5% for 20 and 200 steps), rounded up: a GIF keeps every pixel of its 256-colour palette, so it is large.
GIF_COMPRESSION = 0.1
#: An MP4 of these panels over their raw RGB frames: well under 1% (a 200-step episode: ~0.5 MB of ~120 MB).
MP4_COMPRESSION = 0.01


def check_video_room(path: str | os.PathLike[str], steps: int, panels: int = 3, side: int = 256) -> None:
    """Refuses, before the episodes that it shows are played, a video of ``steps`` frames of ``panels`` panels
    (``side`` pixels, piga's 64-pixel frames 4x upscaled) whose disk has not the room :func:`_write` asks for, or
    whose frames the memory cannot hold: they are kept whole until they are encoded, twice over as they are stacked
    (a 15,000-step episode failed "out of memory" after it was played)."""
    from piga.io.resources import check_memory

    raw = steps * side * side * panels * 3
    check_memory(2 * raw, f"the video {Path(path).name} ({steps:,} frames, held whole until encoded)",
                 advice="give fewer --steps, or drop --video")
    _check_disk(Path(path), raw)


def _check_disk(target: Path, raw_bytes: float) -> None:
    """Refuses a video of ``raw_bytes`` of RGB frames whose disk has not the room for it, as a GIF or an MP4 of
    these panels takes (:data:`GIF_COMPRESSION`, :data:`MP4_COMPRESSION`)."""
    from piga.io.resources import check_disk

    ratio = GIF_COMPRESSION if target.suffix.lower() == ".gif" else MP4_COMPRESSION
    check_disk(target, raw_bytes * ratio + 64 * 1024, f"the video {target.name}",
               advice="free some space, or write it elsewhere")


def encoded_image(image: np.ndarray, extension: str, **options: Any) -> bytes:
    """``image`` (one picture, or a stack of frames for a GIF) encoded by imageio as ``extension`` (``.png``,
    ``.gif``), in memory. The caller writes the bytes itself: imageio's writer, failing on a full disk while it
    closes the file, is left half closed, and its finaliser fails again later with a traceback on stderr."""
    import imageio.v3 as iio

    return iio.imwrite("<bytes>", image, extension=extension, **options)


def _write(video: np.ndarray, target: Path, fps: int, overwrite: bool) -> Path:
    """Writes uint8 RGB frames (T, H, W, 3) to ``target`` (.mp4 or .gif) atomically."""
    import imageio.v3 as iio

    from piga.io.resources import format_bytes

    _check_disk(target, video.nbytes)
    with atomic_output(target, overwrite=overwrite) as tmp:
        try:
            if target.suffix.lower() == ".gif":
                tmp.write_bytes(encoded_image(video, ".gif", duration=1000 / fps, loop=0))
            else:
                # the temporary name has no .mp4 ending for ffmpeg to guess the container from: name it;
                # ffmpeg's own messages would go to our stderr, line by line: the error below says it once
                iio.imwrite(tmp, video, extension=".mp4", fps=fps, codec="libx264", macro_block_size=1,
                            output_params=["-f", "mp4"], ffmpeg_log_level="quiet")
        except OSError as exc:  # ffmpeg's broken pipe, a full disk
            tmp.unlink(missing_ok=True)  # the free space it reports is what the user has to work with
            free = shutil.disk_usage(tmp.parent).free
            cause = exc.strerror or "ffmpeg stopped"
            raise OSError(f"{target}: the video could not be written ({cause}); without it, its disk has "
                          f"{format_bytes(free)} free") from None
    return target
