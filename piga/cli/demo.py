"""``piga-demo``: the main job on small defaults, for a fresh machine.

Today it collects a small data set and saves a strip of its frames. Later stages (training,
control) are added to this one command as they land.
"""

from __future__ import annotations

import shlex
from collections.abc import Sequence
from dataclasses import replace
from pathlib import Path

from piga.cli import show
from piga.cli.common import ArgumentParser, nonnegative_int, positive_int, run_cli
from piga.collect import CollectConfig, collect
from piga.data import inspect_dataset

PROG = "piga-demo"


def build_parser() -> ArgumentParser:
    p = ArgumentParser(prog=PROG, description="Run piga's main job on small defaults: collect pixel-pendulum data "
                       "and save a strip of frames.")
    p.add_argument("--out", default="demo", help="output folder (default %(default)s)")
    p.add_argument("--sequences", type=positive_int, default=CollectConfig.sequences, help="sequences to collect (default %(default)s)")
    p.add_argument("--seed", type=nonnegative_int, default=0, help="root seed (default %(default)s)")
    p.add_argument("--overwrite", action="store_true", help="replace files of an earlier demo in --out")
    return p


def main(argv: Sequence[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    data = out / "pendulum.h5"
    print(f"[1/2] collecting {args.sequences} sequences into {data}")
    config = replace(CollectConfig(), sequences=args.sequences, seed=args.seed)
    collect(config, data, overwrite=args.overwrite, command=shlex.join([PROG, *(argv or [])]))
    info = inspect_dataset(data)
    strip = out / "frames.png"
    print(f"[2/2] saving a strip of frames to {strip}")
    show.main([str(data), "--out", str(strip), *(["--overwrite"] if args.overwrite else [])])
    print(f"summary: {info.n_sequences} sequences x {info.steps} frames {info.image_shape}, "
          f"true g={info.params['g']:g}, actuation gain={info.params['actuation_gain']:g}; see {strip}")
    return 0


def entry() -> None:
    run_cli(PROG, main)
