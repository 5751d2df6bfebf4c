"""Repeated frames: a camera that drops a frame shows the previous one again, a late camera repeats its first.

A frame identical to the one before it (byte for byte, or within a video codec's
:data:`REPEAT_TOLERANCE` gray levels) while the pendulum moves carries no new information: a
dropped frame. When the first k frames of (nearly) every sequence repeat the first one, the camera
started k frames late: a camera delay of k steps, which from then on looks exactly like an
actuator delay of k (o_{t+1} = f(o_t, u_{t-k})).

Used by :mod:`~piga.diagnostics.observe` (which frames repeat), :mod:`~piga.diagnostics.fit`
(a free run predicts the repeat; fits leave repeats out), :mod:`~piga.diagnostics.vision` (the
``frame_drop`` effect) and :mod:`~piga.diagnostics.twin` (the twin repeats the same frames).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, NamedTuple

import numpy as np

from piga.io.choices import check_ranges, check_types

#: Largest pixel change (gray levels) between a frame and the one before it that still counts as a
#: repeat. A camera repeats a frame byte for byte, but a video codec re-encodes the copy: in an
#: H.264 recording, repeated frames came back with changes of at most 1 gray level, while a
#: pendulum that moves by more than 0.1° changes some pixel by 10 levels or more.
REPEAT_TOLERANCE = 2


@dataclass(frozen=True)
class RepeatConfig:
    """When repeated frames are named dropped frames."""

    min_drop_rate: float = 0.005
    """Share of repeated frames while the pendulum moves, above which frames are named dropped."""
    min_drops: int = 5
    """... and at least this many of them."""
    moving: float = 0.02
    """rad per step (1.1°) across a repeated frame at or below which it is not counted as a drop."""
    visible: float = 10.0
    """Gray levels by which a step must change the picture (the largest pixel change between the decoder's renders
    through the recording's camera) for a repeat across it to count as a drop (:func:`visible_step`): through a blur
    a moving pendulum repeats its frame (measured: a 3.9 px blur moved 0.02-0.028 rad per step across 17 frames that
    changed by at most 2 levels, and read "frame_drop 0.0118"); without one, 0.02 rad changes 45."""

    def __post_init__(self) -> None:
        check_types(self)
        check_ranges(self, {"min_drop_rate": (0, 1), "min_drops": (1, 10_000_000), "moving": (0, math.pi),
                            "visible": (0, 255)})


class RepeatFindings(NamedTuple):
    """What the repeated frames of a recording say about its camera."""

    leading: int
    """Frames 1..k repeat frame 0 in nearly every sequence (a camera that starts late)."""
    drops: int
    """Repeats after the leading run while the pendulum moves (dropped frames)."""
    rate: float
    """Their share among the frames where a drop would show."""
    effects: list[dict[str, Any]]
    """The "frame_drop" effect with its Wilson interval when significant, else empty."""


def stale_frames(frames: np.ndarray, tolerance: int = REPEAT_TOLERANCE) -> np.ndarray:
    """(N, T) bool: frame t repeats frame t - 1, no pixel changing by more than ``tolerance`` gray
    levels (never true at t = 0). ``frames`` (N, T, ...) uint8."""
    change = np.abs(frames[:, 1:].astype(np.int16) - frames[:, :-1].astype(np.int16))
    same = change.reshape(frames.shape[0], frames.shape[1] - 1, -1).max(-1) <= tolerance
    return np.concatenate([np.zeros((frames.shape[0], 1), bool), same], axis=1)


def leading_repeats(stale: np.ndarray, share: float = 0.9) -> int:
    """k such that frames 1..k repeat frame 0 in at least ``share`` of the (N, T) sequences (0: none)."""
    run = np.argmin(np.concatenate([stale[:, 1:], np.zeros((len(stale), 1), bool)], axis=1), axis=1)  # (N,) leading run
    k = 0
    while np.mean(run >= k + 1) >= share:
        k += 1
    return k


def repeat_sources(stale: np.ndarray) -> np.ndarray:
    """(N, T) int: for each frame, the index of the last fresh frame at or before it."""
    t = np.arange(stale.shape[1])
    return np.maximum.accumulate(np.where(stale, 0, t[None]), axis=1)


def wilson(k: int, n: int, z: float = 1.96) -> list[float]:
    """Wilson score interval of a proportion k / n."""
    p = k / n
    centre = (p + z * z / (2 * n)) / (1 + z * z / n)
    half = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / (1 + z * z / n)
    return [centre - half, centre + half]


def repeated_frames(stale: np.ndarray | None, theta: np.ndarray, config: RepeatConfig = RepeatConfig()) -> RepeatFindings:
    """Dropped and delayed frames from the repeated ones.

    A dropped frame is a repeat while the pendulum moves by more than ``config.moving`` per step
    across it. Slower repeats are left alone: a still pendulum rightly looks the same, and a video
    codec freezes slow motion (an H.264 recording of a clean camera repeats ~2% of its frames,
    all below 0.7° per step). The rate is counted among the frames where a drop would show: those
    where the pendulum moves that fast.

    Args:
        stale: (N, T) bool, frame t repeats frame t - 1 (:func:`stale_frames`), or None.
        theta: (N, T) angles, to tell a moving pendulum from a slow one.
    """
    if stale is None or not stale.any():
        return RepeatFindings(0, 0, 0.0, [])
    leading = leading_repeats(stale)
    n, t = stale.shape
    src = repeat_sources(stale)
    # the next fresh frame at or after each frame (t: none)
    nxt = np.where(stale, t, np.arange(t)[None])
    nxt = np.minimum.accumulate(nxt[:, ::-1], axis=1)[:, ::-1]
    rows = np.arange(n)[:, None]
    cols = np.arange(leading + 1, t)[None]
    p, q = src[rows, cols - 1], nxt[rows, cols]  # the fresh frames around each frame
    valid = q < t
    qq = np.minimum(q, t - 1)
    motion = np.abs(theta[rows, qq] - theta[rows, p]) / np.maximum(qq - p, 1)
    shows = valid & (motion > config.moving)  # a drop would show here
    drops = int((shows & stale[:, leading + 1 :]).sum())
    frames = int(shows.sum())
    rate = drops / max(1, frames)
    effects = []
    if drops >= config.min_drops and rate > config.min_drop_rate:
        effects.append({"effect": "frame_drop", "value": rate, "unit": "probability per frame", "interval": wilson(drops, frames)})
    return RepeatFindings(leading, drops, rate, effects)


__all__ = ["REPEAT_TOLERANCE", "RepeatConfig", "RepeatFindings", "leading_repeats", "repeat_sources", "repeated_frames",
           "stale_frames", "wilson"]
