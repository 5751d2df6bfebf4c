"""Benchmark: plan time per control step at two git revisions of piga, as ratios measured in one run.

It checks out ``--baseline`` (a commit, tag or branch) into a temporary git worktree, and runs
:mod:`plan_time` (``--no-reference``: the oracle and the piga agent) alternately at that revision
and at the working tree's, ``--pairs`` times, on one torch thread and the same model, so that both
revisions see the same machine state. The page gives each agent's median plan time per run, the
median over the runs, and the ratio of the two medians (this revision over the baseline's): a
speed claim between two versions of the code, measured side by side rather than across records.

The model must load at both revisions: one trained at the baseline (a newer checkpoint may carry
fields an older loader does not know). For example, against the last commit before a refactor::

    git worktree add /tmp/base BASE && (cd /tmp/base && piga-collect --out data/p.h5 && \\
        piga-train-model data/p.h5 --out runs/base-model)
    python benchmarks/plan_time_revisions.py --baseline BASE --model /tmp/base/runs/base-model \\
        --out results/plan_time_revisions

Writes OUT.json and OUT.md (with the machine). Nothing else should run on the machine meanwhile.
"""

from __future__ import annotations

import json
import os
import shlex
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path
from typing import Any

from common import machine, machine_words, out_prefix
from piga.io.atomic import atomic_output, write_json, written_together
from piga.cli.common import ArgumentParser, PigaError, positive_int

ROOT = Path(__file__).resolve().parents[1]
AGENTS = ("oracle", "piga")


def git(*args: str) -> str:
    """A git command in the repository; its stdout (raises on failure)."""
    return subprocess.run(["git", "-C", str(ROOT), *args], check=True, capture_output=True, text=True).stdout.strip()


def plan_time(tree: Path, model: str, out: Path, episodes: int, steps: int | None) -> dict[str, float]:
    """One run of ``benchmarks/plan_time.py --no-reference`` with the code of ``tree``: each agent's median ms."""
    env = {**os.environ, "PYTHONPATH": str(tree), "OMP_NUM_THREADS": "1"}
    done = subprocess.run([sys.executable, "benchmarks/plan_time.py", "--model", model, "--out", str(out),
                           "--no-reference", "--episodes", str(episodes),
                           *(["--steps", str(steps)] if steps else [])], cwd=tree, env=env, capture_output=True,
                          text=True)
    if done.returncode != 0:
        raise PigaError(f"plan_time.py failed in {tree}: {(done.stderr.strip().splitlines() or ['no output'])[-1]}")
    rows = json.loads(out.with_suffix(".json").read_text())["rows"]
    return {row["agent"]: float(row["plan_ms_median"]) for row in rows if row["agent"] in AGENTS}


def summarize(runs: dict[str, list[dict[str, float]]]) -> dict[str, dict[str, Any]]:
    """Per agent: each revision's per-run medians, their median, and the ratio current / baseline."""
    out = {}
    for agent in AGENTS:
        base = [r[agent] for r in runs["baseline"]]
        cur = [r[agent] for r in runs["current"]]
        out[agent] = {"baseline_ms": base, "current_ms": cur, "baseline_median_ms": statistics.median(base),
                      "current_median_ms": statistics.median(cur),
                      "ratio": statistics.median(cur) / statistics.median(base)}
    return out


def markdown(record: dict[str, Any]) -> str:
    """The results page."""
    lines = ["# Plan time per control step at two revisions", "",
             f"Command: `{record['command']}`", "",
             f"Baseline: `{record['baseline']}` (commit {record['baseline_commit'][:10]}); current: commit "
             f"{record['current_commit'][:10]}{' with uncommitted changes' if record['dirty'] else ''}. Model: "
             f"`{record['model']}`. {record['pairs']} runs of each, alternating, each run {record['episodes']} "
             f"episodes of `benchmarks/plan_time.py --no-reference`. Machine: {machine_words(record['machine'])}.", "",
             "| agent | baseline ms (median of runs) | current ms | current / baseline | runs (baseline; current) |",
             "|---|---|---|---|---|"]
    for agent, s in record["summary"].items():
        runs = ", ".join(f"{x:.2f}" for x in s["baseline_ms"]) + "; " + ", ".join(f"{x:.2f}" for x in s["current_ms"])
        lines.append(f"| {agent} | {s['baseline_median_ms']:.3f} | {s['current_median_ms']:.3f} | {s['ratio']:.2f} "
                     f"| {runs} |")
    lines += ["", "Each run's number is the median plan time of its steps (reading the state from the frames and "
              "planning, for the piga agent; planning alone for the oracle). A ratio below 1 is faster than the "
              "baseline.", ""]
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    p = ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--baseline", required=True, help="the git revision to compare with (commit, tag or branch)")
    p.add_argument("--model", required=True, help="a pendulum run folder that both revisions load")
    p.add_argument("--out", type=out_prefix, default="results/plan_time_revisions", help="output prefix (default %(default)s)")
    p.add_argument("--pairs", type=int, default=5, help="runs at each revision, alternating (default %(default)s)")
    p.add_argument("--episodes", type=positive_int, default=5, help="episodes per agent and run (default %(default)s)")
    p.add_argument("--steps", type=positive_int, default=None, help="steps per episode (default: plan_time.py's)")
    args = p.parse_args(argv)
    import torch

    torch.set_num_threads(1)  # what each run uses (OMP_NUM_THREADS=1), and so what the machine record says
    if args.pairs < 1 or args.episodes < 1:
        raise PigaError("--pairs and --episodes must be at least 1")
    model = str(Path(args.model).resolve())
    if not (Path(model) / "checkpoint.pt").exists():
        raise PigaError(f"--model {args.model}: no checkpoint.pt there")
    try:
        base_commit = git("rev-parse", "--verify", f"{args.baseline}^{{commit}}")
    except subprocess.CalledProcessError:
        raise PigaError(f"--baseline {args.baseline}: not a revision of this repository") from None
    command = shlex.join(["python", *(sys.argv if argv is None else ["benchmarks/plan_time_revisions.py", *argv])])
    runs: dict[str, list[dict[str, float]]] = {"baseline": [], "current": []}
    with tempfile.TemporaryDirectory(prefix="piga-revisions-") as tmp:
        base_tree, scratch = Path(tmp) / "baseline", Path(tmp) / "out"
        scratch.mkdir()
        git("worktree", "add", "--detach", str(base_tree), base_commit)
        try:
            for i in range(args.pairs):  # alternating, so that both revisions see the same machine state
                runs["baseline"].append(plan_time(base_tree, model, scratch / f"baseline{i}", args.episodes, args.steps))
                runs["current"].append(plan_time(ROOT, model, scratch / f"current{i}", args.episodes, args.steps))
                print(f"pair {i + 1}/{args.pairs}: baseline {runs['baseline'][-1]}, current {runs['current'][-1]}",
                      flush=True)
        finally:
            git("worktree", "remove", "--force", str(base_tree))
    record = {"command": command, "baseline": args.baseline, "baseline_commit": base_commit,
              "current_commit": git("rev-parse", "HEAD"), "dirty": bool(git("status", "--porcelain", "--untracked-files=no")),
              "model": args.model, "pairs": args.pairs, "episodes": args.episodes, "machine": machine(),
              "runs": runs, "summary": summarize(runs)}
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    with written_together([out.with_suffix(".json"), out.with_suffix(".md")]):
        with atomic_output(out.with_suffix(".md"), overwrite=True) as path:
            Path(path).write_text(markdown(record))
        write_json(out.with_suffix(".json"), record, overwrite=True)
    print(json.dumps(record["summary"], indent=2))
    return 0


if __name__ == "__main__":
    from piga.cli.common import run_script

    run_script(main, __file__)
