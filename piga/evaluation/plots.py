"""Figures a person looks at: frame strips, rollouts, templates, learning curves, control sweeps.

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

from piga.io.atomic import atomic_output  # noqa: E402


def save_figure(fig: Figure, path: str | os.PathLike[str], overwrite: bool = True, dpi: int = 100) -> Path:
    """Saves ``fig`` as PNG (or the format of the suffix) atomically, then closes it."""
    import errno
    import shutil

    import warnings

    target = Path(path)
    try:
        with atomic_output(target, overwrite=overwrite) as tmp, warnings.catch_warnings():
            # a title that holds a file's name in a script the font lacks (CJK): a box per glyph, and matplotlib's
            # two-line warning per glyph on stderr, which says nothing the picture does not
            warnings.filterwarnings("ignore", message=r"Glyph \d+ .*missing from", category=UserWarning)
            fig.savefig(tmp, format=target.suffix.lstrip(".") or "png", dpi=dpi, bbox_inches="tight")
    except Exception as exc:
        # matplotlib's PDF writer breaks on a full disk with an AttributeError of its own ('Stream' has no 'pos'):
        # a failure where the disk has no room left is the disk's, whatever the writer said
        if isinstance(exc, OSError) or shutil.disk_usage(target.parent).free >= 64 * 1024:
            raise
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC), str(target)) from exc
    finally:
        plt.close(fig)
    return target


def check_figure_target(path: str | os.PathLike[str], overwrite: bool, flag: str = "--out") -> Path:
    """Fails early, before any work, if :func:`save_figure` could not write ``path`` as the user named it: no
    suffix (the format would be a guess, and the file's name would not say it), a suffix matplotlib has no writer
    for, or a target :func:`~piga.io.atomic.check_writable_target` refuses."""
    import shutil

    from piga.io.atomic import check_file_name, check_writable_target

    target = Path(path)
    check_file_name(target, flag, "figure.png")
    formats = dict(plt.figure().canvas.get_supported_filetypes())
    plt.close("all")
    tex = plt.rcParams["pgf.texsystem"]
    if shutil.which(tex) is None:  # matplotlib's .pgf writer runs the TeX system, and offers it whether or not it is there
        formats.pop("pgf", None)
    suffix = target.suffix.lstrip(".").lower()
    if suffix not in formats:
        what = (f"matplotlib writes .pgf through {tex}, which is not installed" if suffix == "pgf" else
                f"matplotlib writes no .{suffix} files" if suffix else "an image needs the suffix of its format")
        raise ValueError(f"{flag} {target}: {what}; use .png (or "
                         f"{', '.join('.' + f for f in sorted(formats) if f != 'png')})")
    return check_writable_target(target, overwrite)


def _in_range(img: np.ndarray) -> np.ndarray:
    """A float image clipped to [0, 1], where a model's renders can overshoot a little: matplotlib clips RGB itself,
    but warns on every image (10 lines for a video-lstm run's strip)."""
    return img if img.dtype == np.uint8 else np.clip(img, 0, 1)


def thumbnail(img: np.ndarray, side: int) -> np.ndarray:
    """``img`` (H, W) or (H, W, C), area-averaged (cv2's ``INTER_AREA``) to at most ``side`` pixels on its longer side;
    as it is where it fits. What is drawn is then each frame's light averaged over a pixel of the strip, whatever
    matplotlib's own resampling of a larger image does, and ``piga-show`` can measure what the average keeps (a 1024 px
    scene's 6 px balls: a few gray levels, which looked like black frames)."""
    import cv2

    h, w = img.shape[:2]
    scale = side / max(h, w)
    if scale >= 1:
        return img
    size = (max(1, round(w * scale)), max(1, round(h * scale)))  # cv2's (width, height)
    small = cv2.resize(np.ascontiguousarray(img), size, interpolation=cv2.INTER_AREA)
    return small.reshape(*small.shape[:2], *img.shape[2:])  # cv2 drops a single channel's axis


def strip_cell_side(fig: Figure) -> int:
    """The pixels a frame of :func:`frame_strip`'s ``fig`` is drawn in, a side (its first cell at the figure's dpi,
    :func:`save_figure`'s 100)."""
    box = fig.axes[0].get_position()
    width, height = fig.get_size_inches() * fig.dpi
    return max(1, int(min(box.width * width, box.height * height)))


def frame_strip(
    frames: np.ndarray, row_labels: list[str] | None = None, col_labels: list[str] | None = None, title: str | None = None
) -> Figure:
    """A grid of frames: ``frames`` uint8 or float [R, C, H, W] (gray) or [R, C, H, W, 3]; frames larger than a cell
    are area-averaged to it (:func:`thumbnail`)."""
    rows, cols = frames.shape[:2]
    fig, axes = plt.subplots(rows, cols, figsize=(cols * 0.9, rows * 0.95 + (0.3 if title else 0)), squeeze=False)
    fig.subplots_adjust(wspace=0.05, hspace=0.1)  # first: the cells' size is what the frames are averaged to
    side = strip_cell_side(fig)
    for r in range(rows):
        for c in range(cols):
            ax = axes[r, c]
            img = thumbnail(frames[r, c], side)
            ax.imshow(_in_range(img), cmap="gray" if img.ndim == 2 else None, vmin=0, vmax=255 if img.dtype == np.uint8 else 1)
            ax.set_xticks([])
            ax.set_yticks([])
            if r == 0 and col_labels:
                ax.set_title(col_labels[c], fontsize=7, parse_math=False)
            if c == 0 and row_labels:
                ax.set_ylabel(row_labels[r], fontsize=7, parse_math=False)
    if title:
        fig.suptitle(title, fontsize=9, parse_math=False)  # a file's name or attribute may hold '$': text, not TeX
    return fig


def rollout_figure(truth: np.ndarray, pred: np.ndarray, input_frames: int, pred_frames: int, every: int = 2) -> Figure:
    """Truth vs prediction for a few sequences.

    Args:
        truth, pred: float [B, S, H, W] (gray) or [B, S, H, W, 3] in [0, 1]: the S frames after the inputs.
        input_frames: L (for the labels).
        pred_frames: T_pred; later columns are extrapolation.
        every: show every ``every``-th frame.
    """
    steps = list(range(0, truth.shape[1], every))
    rows = []
    labels = []
    for b in range(truth.shape[0]):
        rows += [truth[b, steps], pred[b, steps]]
        labels += [f"true #{b}", f"pred #{b}"]
    cols = [f"t={input_frames + s + 1}" + ("" if s < pred_frames else "*") for s in steps]
    return frame_strip(np.stack(rows), labels, cols, title="rollout from 4 input frames (* = extrapolation beyond T_pred)")


def openloop_figure(real: np.ndarray, imagined: np.ndarray, rewards: np.ndarray, predicted: np.ndarray, context: int,
                    shown: int = 2, every: int = 3) -> Figure:
    """A world model's open-loop prediction: real frames above imagined ones, and real against predicted rewards.

    Args:
        real, imagined: float [B, T, H, W] (gray) or [B, T, H, W, 3] in [0, 1]; the first ``context`` imagined frames are filtered (reconstructions).
        rewards, predicted: [B, T].
        shown: sequences drawn; every: show every ``every``-th frame.
    """
    steps = list(range(0, real.shape[1], every))
    shown = min(shown, len(real))
    fig = plt.figure(figsize=(len(steps) * 0.8, shown * 1.7 + 1.8))
    grid = fig.add_gridspec(2 * shown + 1, len(steps), height_ratios=[1] * (2 * shown) + [2.2], hspace=0.15, wspace=0.05)
    for b in range(shown):
        for row, (images, label) in enumerate(((real, f"real #{b}"), (imagined, f"model #{b}"))):
            for col, t in enumerate(steps):
                ax = fig.add_subplot(grid[2 * b + row, col])
                ax.imshow(_in_range(images[b, t]), cmap="gray", vmin=0, vmax=1)
                ax.set_xticks([])
                ax.set_yticks([])
                if b == 0 and row == 0:
                    ax.set_title(f"t={t}" + ("" if t < context else "*"), fontsize=7)
                if col == 0:
                    ax.set_ylabel(label, fontsize=7)
    ax = fig.add_subplot(grid[-1, :])
    for b in range(shown):
        line, = ax.plot(rewards[b], label=f"real #{b}")
        ax.plot(predicted[b], "--", color=line.get_color(), label=f"model #{b}")
    ax.axvline(context - 0.5, color="gray", lw=0.8)
    ax.set_xlabel("frame t")
    ax.set_ylabel("reward")
    ax.legend(fontsize=6, ncol=2 * shown)
    fig.suptitle(f"open loop: {context} frames filtered, then imagined under the real actions (* = imagined)", fontsize=9)
    return fig


def templates_figure(contents: np.ndarray, masks: np.ndarray, background: np.ndarray, background_mask: np.ndarray) -> Figure:
    """Learned templates at the reference pose: per object content, mask and mask⊙content; then the background.

    Args:
        contents: [N, H, W] or [N, H, W, 3] in [0, 1]; masks: [N, H, W], the decoder's softmaxed masks.
        background: [H, W] or [H, W, 3]; background_mask: [H, W], its softmaxed mask.
    """
    n = contents.shape[0]
    fig, axes = plt.subplots(n + 1, 3, figsize=(6, 2 * (n + 1)), squeeze=False)
    for i in range(n + 1):
        c = contents[i] if i < n else background
        m = masks[i] if i < n else background_mask
        obj = c * (m[..., None] if c.ndim == 3 else m)
        for j, (img, title) in enumerate([(c, "content c"), (m, "mask m (softmax)"), (obj, "m⊙c")]):
            ax = axes[i, j]
            ax.imshow(_in_range(img), cmap="gray" if img.ndim == 2 else None, vmin=0, vmax=1)
            ax.set_xticks([])
            ax.set_yticks([])
            ax.set_title(("background: " if i == n else f"object {i}: ") + title, fontsize=8)
    fig.tight_layout()
    return fig


def curves_figure(history: list[dict[str, float]], true_params: dict[str, float]) -> Figure:
    """Learning curves per epoch: losses (log scale) and each physical parameter with its true value."""
    epochs = [h["epoch"] for h in history]
    names = [k for k in history[0] if k in ("g", "a", "k", "l", "m", "offset")] if history else []
    names = [k for k in names if len({h[k] for h in history}) > 1]  # a frozen parameter has no curve
    fig, axes = plt.subplots(1, 1 + len(names), figsize=(3.2 * (1 + len(names)), 2.8), squeeze=False)
    ax = axes[0, 0]
    for key in ("loss", "loss_pred", "loss_rec"):
        ax.plot(epochs, [h[key] for h in history], label=key)
    ax.set_yscale("log")
    ax.set_xlabel("epoch")
    ax.legend(fontsize=7)
    ax.set_title("losses", fontsize=9)
    for ax, name in zip(axes[0, 1:], names):
        ax.plot(epochs, [h[name] for h in history], marker=".", label=f"learned {name}")
        if name in true_params:
            ax.axhline(true_params[name], color="k", ls="--", lw=1, label=f"true {name} = {true_params[name]:g}")
        ax.set_xlabel("epoch")
        ax.legend(fontsize=7)
        ax.set_title(name, fontsize=9)
    fig.tight_layout()
    return fig


def sweep_figure(summaries: list[dict], x_key: str = "gravity_mult", x_label: str = "gravity multiplier") -> Figure:
    """Success rate and mean return against ``x_key``, one line per ``agent`` (control sweeps)."""
    fig, axes = plt.subplots(1, 2, figsize=(8, 3))
    for agent in sorted({s["agent"] for s in summaries}):
        rows = sorted((s for s in summaries if s["agent"] == agent), key=lambda s: s[x_key])
        xs = [s[x_key] for s in rows]
        axes[0].plot(xs, [100 * s["success_rate"] for s in rows], marker="o", label=agent)
        axes[1].plot(xs, [s["mean_return"] for s in rows], marker="o", label=agent)
    for ax, title in zip(axes, ("success (%)", "mean return")):
        ax.set_xlabel(x_label)
        ax.set_title(title, fontsize=9)
        ax.axvline(1.0, color="k", lw=0.5, ls=":")
        ax.legend(fontsize=7)
    axes[0].set_ylim(-5, 105)
    fig.tight_layout()
    return fig
