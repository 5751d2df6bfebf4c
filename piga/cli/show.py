"""``piga-show``: a strip of frames from a data file, as a PNG."""

from __future__ import annotations

import sys
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from envs.fields import counted
from piga.cli.common import ArgumentParser, file_path, given_options, positive_int, run_cli, typed_text
from piga.data.schema import (SPLITS, BlankFramesError, DatasetInfo, check_actions_file, check_frames_have_signal,
                              inspect_dataset, open_data_file, read_rows, split_indices)
from piga.io.resources import check_figure_disk
from piga.io.atomic import check_not_an_input

PROG = "piga-show"


def build_parser() -> ArgumentParser:
    p = ArgumentParser(prog=PROG, description="Save a grid of frames (rows: sequences, columns: time) from a piga data file.")
    p.add_argument("data", help="HDF5 file of piga's schema")
    p.add_argument("--out", required=True, type=file_path,
                   help="output image: .png, or another suffix matplotlib writes (.pdf, .svg, .jpg, ...)")
    p.add_argument("--split", choices=list(SPLITS), default="train", help="split to show (default %(default)s)")
    p.add_argument("--sequences", type=positive_int, default=4, help="rows (default %(default)s, or all the split holds "
                   "where it holds fewer; more than it holds is refused where given)")
    p.add_argument("--frames", type=positive_int, default=10, help="columns (default %(default)s, or all a sequence holds "
                   "where it holds fewer; more is refused where given)")
    p.add_argument("--overwrite", action="store_true", help="replace --out if it exists")
    return p


#: Characters of the strip's title (the file's name, system and parameters) beyond which it is cut.
MAX_TITLE = 200


def main(argv: Sequence[str] | None = None) -> int:
    from piga.evaluation.plots import (check_figure_target, frame_strip, save_figure,  # matplotlib after run_cli's set-up
                                       strip_cell_side)

    parser = build_parser()
    args = parser.parse_args(argv)
    written = given_options(parser, argv)
    check_figure_target(args.out, args.overwrite)
    check_figure_disk(args.out, "the strip")
    check_not_an_input(args.out, {"data file": args.data})
    info = inspect_dataset(args.data)
    available = split_indices(args.data, args.split)
    if len(available) == 0:  # first: the --split to change, before what the other splits' frames hold
        held = [name for name, n in info.split_counts.items() if n]
        raise ValueError(f"split '{args.split}' of {args.data} is empty; give --split "
                         + " or ".join(f"{name} ({counted(info.split_counts[name], 'sequence')})" for name in held))
    warnings = []  # said once the strip is sure to be drawn: a refusal after them made two lines
    try:  # a blank or still file is drawn, with a warning for the blank one: a viewer is how one finds out
        check_frames_have_signal(args.data, motion=False)
    except BlankFramesError as blank:
        warnings.append(f"{PROG}: warning: {blank}; drawn all the same")
    if (odd := _refused_elsewhere(info)) is not None:
        warnings.append(f"{PROG}: warning: {odd}; drawn all the same")
    check_actions_file(args.data)  # a non-finite action is named rather than drawn
    # a count written beyond the file is refused (the defaults shrink to a small file: the strip shows what it holds)
    for dest, have, noun, where in (("sequences", len(available), "sequence", f"in its {args.split} split"),
                                    ("frames", info.steps, "frame", "per sequence")):
        if dest in written and getattr(args, dest) > have:
            raise ValueError(f"--{dest} {getattr(args, dest)}: {args.data} has {counted(have, noun)} {where}; give at "
                             f"most {have}")
    idx = available[: args.sequences]
    t = min(args.frames, info.steps)
    _check_strip_fits(args.out, t, len(idx))
    with open_data_file(args.data) as f:
        with read_rows(f["frames"], "the strip's sequences"):
            frames = np.stack([f["frames"][int(i), :t] for i in idx])
        with read_rows(f["actions"], "the strip's sequences"):
            actions = np.stack([f["actions"][int(i), :t] for i in idx])
    for line in warnings:
        print(line, file=sys.stderr)
    labels = [f"seq {i}" for i in idx]
    cols = [f"t={k}" for k in range(t)]
    title = f"{typed_text(info.path.name)}: {info.named}, dt={info.dt:g}, params {info.params}"
    if len(title) > MAX_TITLE:  # a file's attributes can be any text; matplotlib lays out every character
        title = title[: MAX_TITLE - 3] + "..."
    fig = frame_strip(frames, labels, cols, title)
    for r in range(len(idx)):  # the action after each frame, under it
        for c in range(t):
            if actions.shape[-1]:
                fig.axes[r * t + c].set_xlabel(f"u={actions[r, c, 0]:+.2f}", fontsize=6)
    note = _faded_note(frames, strip_cell_side(fig))
    path = save_figure(fig, args.out, overwrite=args.overwrite)
    print(f"wrote {path}")
    if note is not None:
        print(f"note: {note}")
    return 0


#: The share of a frame's contrast (its brightest value less its darkest) that its thumbnail in the strip must keep:
#: below it, objects smaller than a pixel of the strip are averaged away.
KEPT_CONTRAST = 0.5


def _faded_note(frames: np.ndarray, side: int) -> str | None:
    """A note where frames larger than the strip's cells (``side`` px) lose objects to the area average that draws them
    (:func:`piga.evaluation.plots.thumbnail`): the least share of a frame's contrast that a thumbnail keeps, below
    :data:`KEPT_CONTRAST`; None where every thumbnail keeps more, or the frames fit (``frames`` [R, C, H, W(, C)])."""
    from piga.evaluation.plots import thumbnail

    height, width = frames.shape[2:4]
    if max(height, width) <= side:
        return None
    kept = [float(np.ptp(thumbnail(frame, side))) / contrast
            for frame in frames.reshape(-1, *frames.shape[2:]) if (contrast := float(np.ptp(frame))) > 0]
    if not kept or min(kept) >= KEPT_CONTRAST:
        return None
    step = max(height, width) / side
    return (f"the frames are {width}x{height} px (width x height), drawn {side} px a side: each pixel of the strip "
            f"averages {step:.3g}x{step:.3g} of theirs, and objects smaller than that show faint or not at all (a "
            f"thumbnail keeps {min(kept):.0%} of its frame's contrast)")


def _refused_elsewhere(info: DatasetInfo) -> str | None:
    """What the other commands refuse in a file that the strip draws all the same, in one line: a system that no model
    knows, action columns other than the system's (a pendulum's one torque, none for a scene), sequences of one frame,
    and frames that are not square (None: none)."""
    odd = []
    actions: int | None = 1  # the pendulum's one torque; None: a system that no model knows
    if info.system != "pendulum":  # (the models' list imports torch: not for the pendulum's files, the common case)
        from piga.world.model import SYSTEM_SHAPES

        actions = SYSTEM_SHAPES[info.system][2] if info.system in SYSTEM_SHAPES else None
        if actions is None:
            odd.append(f"the system {info.system!r}, which no model knows (known: {', '.join(sorted(SYSTEM_SHAPES))})")
    if info.image_shape[0] != info.image_shape[1]:
        odd.append(f"frames of {info.image_shape[0]}x{info.image_shape[1]} px (a model takes square ones)")
    if actions is not None and info.action_dim != actions:  # a pendulum file labelled 'spring', say
        odd.append(f"{counted(info.action_dim, 'action column')} (a {info.system} takes {actions})")
    if info.steps < 2:
        odd.append(f"{counted(info.steps, 'frame')} per sequence (a video needs two)")
    if not odd:
        return None
    return (f"{typed_text(str(info.path))} has {' and '.join(odd)}: piga-train-model, piga-baseline and piga-diagnose "
            "refuse it")


#: The largest side, in pixels, of an image that Pillow writes in each format with a limit (libjpeg's, libwebp's):
#: beyond it the strip failed after the drawing with the library's words ("Maximum supported image dimension").
IMAGE_SIDE_LIMITS = {"jpg": 65500, "jpeg": 65500, "webp": 16383}
#: Pixels a frame of the strip takes, a little above (measured: 182 frames were 12,729 px wide, 70 a frame, once
#: bbox_inches="tight" trimmed frame_strip's 0.9 x 0.95 inches at save_figure's 100 dpi).
STRIP_CELL_PX = (72, 95)


def _check_strip_fits(out: str, frames: int, sequences: int) -> None:
    """Refuses, before the strip is drawn, a strip wider or taller than its format can hold (.jpg, .webp)."""
    suffix = Path(out).suffix.lstrip(".").lower()
    if (limit := IMAGE_SIDE_LIMITS.get(suffix)) is None:
        return
    width, height = frames * STRIP_CELL_PX[0], sequences * STRIP_CELL_PX[1]
    if max(width, height) > limit:
        most = (f"--frames {limit // STRIP_CELL_PX[0]}" if width > limit else "") + \
            (" and " if width > limit and height > limit else "") + \
            (f"--sequences {limit // STRIP_CELL_PX[1]}" if height > limit else "")
        raise ValueError(f"--out {out}: a strip of {sequences} x {frames} frames is about {width} x {height} px, beyond "
                         f".{suffix}'s limit of {limit} px a side; give at most {most}, or write .png")


def entry() -> None:
    run_cli(PROG, main)


if __name__ == "__main__":
    entry()
