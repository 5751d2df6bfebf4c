"""``piga-import``: a user's own recording (video or frame folder, plus a CSV of actions) -> one HDF5 file."""

from __future__ import annotations

import sys
from collections.abc import Sequence

from envs.fields import counted
from envs.pendulum import MAX_IMAGE_SIZE
from piga.cli.common import (H5_SUFFIXES, ArgumentParser, command_line, format_default, h5_path, int_up_to,
                             positive_float, positive_int, run_cli, split_type)
from piga.data.collect import empty_split_warning
from piga.data.importer import MAX_DT, MIN_DT, ImportConfig, import_recording, recording_frame_seconds
from piga.data.schema import MIN_IMAGE_SIZE
from piga.io.lock import lock_run_folder

PROG = "piga-import"


def build_parser() -> ArgumentParser:
    defaults = ImportConfig(dt=1.0)
    p = ArgumentParser(
        prog=PROG,
        description="Import a recording of the pendulum and its actions into piga's HDF5 schema (README, "
        "'Data files'), cut into sequences of --steps frames. Frames are converted as the env converts its "
        "render: centre crop, INTER_AREA resize, Gymnasium's gray weights.",
    )
    p.add_argument("recording", help="a video file (.mp4, .gif, ... anything imageio reads), an image stack such "
                   "as a multi-page TIFF, or a folder of "
                   ".png/.jpg frames in natural name order")
    p.add_argument("actions", help="CSV with one action per frame: one column, or a header naming the column "
                   "'u' or 'action'")
    p.add_argument("--dt", type=positive_float, required=True, help=f"seconds between frames, {MIN_DT:g} to {MAX_DT:g} (required)")
    p.add_argument("--out", required=True, type=h5_path,
                   help=f"output {' or '.join(H5_SUFFIXES)} file (written atomically)")
    p.add_argument("--steps", type=positive_int, default=defaults.steps,
                   help="frames per sequence T, >= 2; leftover frames at the end are dropped (default %(default)s)")
    p.add_argument("--image-size", type=int_up_to(MAX_IMAGE_SIZE, "piga-collect's largest frames", least=MIN_IMAGE_SIZE),
                   default=defaults.image_size,
                   help=f"frame side in pixels, {MIN_IMAGE_SIZE} to {MAX_IMAGE_SIZE} (default %(default)s)")
    p.add_argument("--split", type=split_type, default=defaults.split,
                   help="train,valid,test as fractions or counts of sequences, in recording order "
                   f"(default {format_default(defaults.split)})")
    p.add_argument("--overwrite", action="store_true", help="replace --out if it exists")
    return p


def main(argv: Sequence[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    config = ImportConfig(dt=args.dt, steps=args.steps, image_size=args.image_size, split=args.split)
    lock_run_folder(args.out)  # a second command writing the same file is refused until this one ends
    result = import_recording(args.recording, args.actions, args.out, config, overwrite=args.overwrite,
                              command=command_line(PROG, argv))
    print(f"wrote {result.path}: {counted(result.sequences, 'sequence')} x {config.steps} frames of "
          f"({config.image_size}, {config.image_size}), split {result.split_counts}, dt={config.dt:g}")
    if result.source_side < config.image_size:
        print(f"note: the recording's frames are {result.source_side} px on their short side, so they were enlarged to "
              f"{config.image_size} px, which adds no detail"
              + (f" (--image-size {result.source_side} keeps them as recorded)" if result.source_side >= MIN_IMAGE_SIZE
                 else f" ({MIN_IMAGE_SIZE} px, the smallest --image-size, is as close as piga reads them)"))
    height, width = result.source_shape
    if height != width:  # the pixel pendulum's frames are square: the long side loses its ends, which the user may miss
        cut, side = abs(height - width), ("left and right" if width > height else "top and bottom")
        print(f"note: the recording's frames are {width}x{height} px (width x height); their centre square was kept, "
              f"cutting {cut} px in all from its {side}: check that the pendulum stays inside it")
    if result.dropped_frames:
        print(f"note: the last {result.dropped_frames} of {result.source_frames} frames (less than one sequence "
              f"of {config.steps}) were dropped")
    if (warning := empty_split_warning(config.split, result.split_counts, result.source_frames)) is not None:
        print(f"{PROG}: warning: {warning}", file=sys.stderr)
    said = recording_frame_seconds(args.recording)
    if said is not None and abs(said - config.dt) > 0.02 * config.dt:  # (a video slowed down says its own rate)
        print(f"{PROG}: warning: {args.recording} says its frames are {said:.4g} s apart; the file takes --dt "
              f"{config.dt:g}, as given, and the physics steps that long per frame", file=sys.stderr)
    return 0


def entry() -> None:
    run_cli(PROG, main)


if __name__ == "__main__":
    entry()
