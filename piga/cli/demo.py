"""``piga-demo``: the main job on small defaults, for a fresh machine.

It collects a small data set and saves a strip of its frames. It then trains the world model with
the fast preset and prints the learned g and a with their errors. Later stages (control) join this
one command as they land.
"""

from __future__ import annotations

import shlex
from collections.abc import Sequence
from dataclasses import replace
from pathlib import Path

from piga.cli import show, train
from piga.cli.common import ArgumentParser, PigaError, nonnegative_int, positive_int, run_cli
from piga.collect import CollectConfig, collect
from piga.data import inspect_dataset

PROG = "piga-demo"


def build_parser() -> ArgumentParser:
    p = ArgumentParser(prog=PROG, description="Run piga's main job on small defaults: collect pixel-pendulum data, "
                       "train the world model (fast preset) and print the learned g and a with their errors.")
    p.add_argument("--out", default="demo", help="output folder (default %(default)s)")
    p.add_argument("--sequences", type=positive_int, default=CollectConfig.sequences, help="sequences to collect (default %(default)s)")
    p.add_argument("--epochs", type=positive_int, help="training epochs (default: the fast preset's)")
    p.add_argument("--seed", type=nonnegative_int, default=0, help="seed of data and training (default %(default)s)")
    p.add_argument("--overwrite", action="store_true", help="replace files of an earlier demo in --out")
    return p


def main(argv: Sequence[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    out = Path(args.out)
    if out.exists() and not out.is_dir():
        raise PigaError(f"--out {out} is a file, not a folder")
    data, strip, run_dir = out / "pendulum.h5", out / "frames.png", out / "model"
    if not args.overwrite:
        for path in (data, strip, run_dir / "checkpoint.pt"):
            if path.exists():
                raise PigaError(f"{path} exists from an earlier demo; pass --overwrite to replace it")
    out.mkdir(parents=True, exist_ok=True)
    over = ["--overwrite"] if args.overwrite else []
    print(f"[1/3] collecting {args.sequences} sequences into {data}", flush=True)
    config = replace(CollectConfig(), sequences=args.sequences, seed=args.seed)
    collect(config, data, overwrite=args.overwrite, command=shlex.join([PROG, *(argv or [])]))
    print(f"[2/3] saving a strip of frames to {strip}", flush=True)
    show.main([str(data), "--out", str(strip), *over])
    print(f"[3/3] training the world model into {run_dir} (fast preset)", flush=True)
    train.main([str(data), "--out", str(run_dir), "--seed", str(args.seed), *over,
                *(["--epochs", str(args.epochs)] if args.epochs else [])])
    import json

    metrics = json.loads((run_dir / "metrics.json").read_text())
    info = inspect_dataset(data)
    errs = metrics["parameter_errors"]
    print("summary: " + ", ".join(f"{n}: learned {e['learned']:.4f}, true {e['true']:g}, error {100 * e['relative_error']:.2f}%"
                                  for n, e in errs.items())
          + f"; {info.n_sequences} sequences, {metrics['training']['seconds'] / 60:.1f} min of training; see {out}/")
    return 0


def entry() -> None:
    run_cli(PROG, main)
