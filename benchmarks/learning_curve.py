"""An SB3 baseline run's learning curve, read from its checkpoint: for a run stopped part-way, whose
``metrics.json`` is written only at the end.

    python benchmarks/learning_curve.py RUN_DIR --out results/drqv2_runs/records/pixels-s0.json

Writes OUT: the run's command (its ``config.json``; the run folder written RUN) and the commits of the code that
started and continued it, its settings, the EvalCallback curve so far (step, mean return, seconds) and the training
seconds.
"""

from __future__ import annotations

import shlex
import sys
from pathlib import Path

from common import is_learning_curve, out_prefix

from piga.io.atomic import write_json
from piga.io.checkpoint import RunKind, read_checkpoint, read_run_record
from piga.cli.common import ArgumentParser


def main(argv: list[str] | None = None) -> int:
    p = ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("run", type=Path, help="a piga-baseline ddpg run folder (DDPG, SAC or DrQ-v2)")
    p.add_argument("--out", required=True, type=out_prefix, help="the record to write (JSON)")
    p.add_argument("--overwrite", action="store_true", help="replace an existing record")
    args = p.parse_args(argv)
    try:
        ckpt = read_checkpoint(args.run, RunKind.DDPG)
        written = args.run / "config.json"  # piga-baseline's record of the command (a run trained in Python has none)
        started, why = read_run_record(args.run)
        if why is not None and why != "is missing":
            raise ValueError(f"{written} {why}")
        if not isinstance(started.get("command", ""), (str, type(None))):
            raise ValueError(f"{written}: 'command' must be the command line as text, got {started['command']!r}")
        if not is_learning_curve(ckpt["history"]):
            raise ValueError(f"{args.run / 'checkpoint.pt'}: its 'history' is not a learning curve (edited?)")
        words = shlex.split(started.get("command") or "")
        command = shlex.join("RUN" if i and words[i - 1] == "--out" else w for i, w in enumerate(words)) or None
        # the code's commits, as the run's record has them (runs started before it recorded them have none)
        commits = {key: started[key] for key in ("commit", "resumed_commits") if key in started}
        record = {"command": command, **commits, "config": ckpt["config"], "learning_curve": ckpt["history"],
                  "train_seconds": ckpt["elapsed"]}
        write_json(args.out, record, overwrite=args.overwrite)
    except (OSError, ValueError, KeyError) as exc:
        print(f"learning_curve.py: error: {' '.join(str(exc).split())}", file=sys.stderr)
        return 1
    print(", ".join(f"{r['step']}: {r['eval_mean_return']:.1f}" for r in record["learning_curve"]))
    return 0


if __name__ == "__main__":
    from piga.cli.common import run_script

    run_script(main, __file__)
