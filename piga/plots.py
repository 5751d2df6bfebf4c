"""Figures a person looks at: frame strips (and, later, rollouts, templates, learning curves).

Every figure is written atomically through :func:`save_figure`.
"""

from __future__ import annotations

import os
from pathlib import Path

import matplotlib

matplotlib.use("Agg")  # files only; no display needed
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib.figure import Figure  # noqa: E402

from piga.atomic import atomic_output  # noqa: E402


def save_figure(fig: Figure, path: str | os.PathLike[str], overwrite: bool = True, dpi: int = 100) -> Path:
    """Saves ``fig`` as PNG (or the format of the suffix) atomically, then closes it."""
    target = Path(path)
    with atomic_output(target, overwrite=overwrite) as tmp:
        fig.savefig(tmp, format=target.suffix.lstrip(".") or "png", dpi=dpi, bbox_inches="tight")
    plt.close(fig)
    return target


def frame_strip(
    frames: np.ndarray, row_labels: list[str] | None = None, col_labels: list[str] | None = None, title: str | None = None
) -> Figure:
    """A grid of frames: ``frames`` uint8 or float [R, C, H, W] (gray) or [R, C, H, W, 3]."""
    rows, cols = frames.shape[:2]
    fig, axes = plt.subplots(rows, cols, figsize=(cols * 0.9, rows * 0.95 + (0.3 if title else 0)), squeeze=False)
    for r in range(rows):
        for c in range(cols):
            ax = axes[r, c]
            img = frames[r, c]
            ax.imshow(img, cmap="gray" if img.ndim == 2 else None, vmin=0, vmax=255 if img.dtype == np.uint8 else 1)
            ax.set_xticks([])
            ax.set_yticks([])
            if r == 0 and col_labels:
                ax.set_title(col_labels[c], fontsize=7)
            if c == 0 and row_labels:
                ax.set_ylabel(row_labels[r], fontsize=7)
    if title:
        fig.suptitle(title, fontsize=9)
    fig.subplots_adjust(wspace=0.05, hspace=0.1)
    return fig
