"""DrQ-v2's learning curves, from its runs' records, beside the published DrQ-v2 curve on DMC pendulum-swingup.

Each ``--runs`` record is what ``benchmarks/learning_curve.py`` reads from a run's checkpoint (a run stopped part-way
included): the command, the commits, the settings and the evaluation curve. ``--published`` is the published
per-seed curve (``benchmarks/published_scores.py``: DrQ-v2's 9 seeds on pendulum-swingup); ``--reference``, what
policies that learned nothing score at the runs' evaluation starts (``benchmarks/reference_policies.py``). A DMC run's env steps
are counted in frames as DrQ-v2's paper counts them (action repeat 2: two per env step), the published curves' unit.

    python benchmarks/drqv2_curves.py --out results/drqv2 \
        --published results/published/dmc_vision-drqv2-pendulum_swingup.json \
        --runs results/drqv2_runs/records/pixels-s0.json results/drqv2_runs/records/pixels-cpu-s0.json \
               results/drqv2_runs/records/dmc-float32-s0.json results/drqv2_runs/records/dmc-bf16-s0.json \
        --reference results/reference_policies.json

Writes OUT.md, OUT.json (each run's curve, and the published curve at its points) and OUT.png (the curves).
"""

from __future__ import annotations

import json
import shlex
import sys
from pathlib import Path
from typing import Any

import numpy as np

from common import check_record, is_learning_curve, is_number, out_prefix, signed, write_page

from agents.sb3.config import LEARNED_RETURN
from envs import DMC_PENDULUM, PIXEL_PENDULUM
from envs.dmc import DMCPendulumConfig
from piga.cli.common import ArgumentParser

#: Frames per DMC env step: its action repeat (DrQ-v2's paper and the published curves count frames).
DMC_FRAMES_PER_STEP = DMCPendulumConfig().action_repeat


#: Each DMC view (``piga-baseline ddpg --view``) in words; a record from before the option was seen face-on.
VIEW_WORDS = {"face": "face-on camera, 64x64 gray", "fixed": "camera 0, 64x64 gray", "drqv2": "camera 0, 84x84 RGB"}


def run_summary(name: str, record: dict[str, Any]) -> dict[str, Any]:
    """One run: its env, device and precision, steps trained of those planned, its curve in frames."""
    config = record["config"]
    env = config.get("env", PIXEL_PENDULUM)
    per_step = DMC_FRAMES_PER_STEP if env == DMC_PENDULUM else 1
    curve = [{"step": r["step"], "frames": r["step"] * per_step, "score": r["eval_mean_return"]} for r in record["learning_curve"]]
    mark = LEARNED_RETURN[env]
    reached = next((r["step"] for r in curve if r["score"] > mark), None)
    return {"name": name, "env": env, "device": config.get("device", "auto"),
            "precision": config.get("encoder_precision", "float32"), "planned": config["steps"],
            "buffer_size": config.get("buffer_size"),  # None in a record that omits it
            "view": VIEW_WORDS[config.get("view", "face")] if env == DMC_PENDULUM else "Gymnasium's render, 64x64 gray",
            "warmup_frames": config.get("learning_starts", 0) * per_step,
            "trained": curve[-1]["step"] if curve else 0, "curve": curve, "mark": mark, "first_step_above_mark": reached,
            "best": max((r["score"] for r in curve), default=None), "train_minutes": record.get("train_seconds", 0) / 60,
            "command": record.get("command"), "commit": record.get("commit"), "resumed_commits": record.get("resumed_commits", [])}


def check_run(path: Path, record: Any) -> dict[str, Any]:
    """A learning_curve.py record read from ``path``, refused in one line unless it is of the shape read here."""
    check_record(path, isinstance(record, dict), "must be a learning_curve.py record (a JSON object)")
    config, curve = record.get("config"), record.get("learning_curve")
    check_record(path, isinstance(config, dict) and isinstance(config.get("steps"), int) and not isinstance(config["steps"], bool),
                 "must give the run's settings, 'config', with its planned 'steps' (an integer)")
    check_record(path, is_learning_curve(curve), "must give 'learning_curve' as a list of points, each a 'step' (an "
                 "integer) and an 'eval_mean_return' (a number)")
    check_record(path, is_number(record.get("train_seconds", 0)), "must give 'train_seconds' as a number")
    return record


def check_published(path: Path, published: Any) -> dict[str, Any]:
    """A published_scores.py record read from ``path``, refused in one line unless it is of the shape read here."""
    check_record(path, isinstance(published, dict) and isinstance(published.get("source"), str),
                 "must be a published_scores.py record (a JSON object naming its 'source')")
    seeds = published.get("seeds")
    check_record(path, isinstance(seeds, list) and len(seeds) > 0 and all(
        isinstance(s, dict) and isinstance(s.get("xs"), list) and isinstance(s.get("ys"), list)
        and len(s["xs"]) == len(s["ys"]) > 0 and all(is_number(v) for v in s["xs"] + s["ys"]) for s in seeds),
                 "must give 'seeds', a list of curves, each 'xs' and 'ys' (lists of as many numbers)")
    return published


def check_reference(path: Path, reference: Any) -> dict[str, Any]:
    """A reference_policies.py record read from ``path``, refused in one line unless it is of the shape read here."""
    check_record(path, isinstance(reference, dict) and isinstance(reference.get("command"), str)
                 and isinstance(reference.get("eval_episodes"), int) and reference["eval_episodes"] > 0,
                 "must be a reference_policies.py record (a JSON object with its 'command' and 'eval_episodes')")
    scores = reference.get("scores")
    check_record(path, isinstance(scores, dict) and all(
        isinstance(policies, dict) and all(isinstance(r, list) and r and all(is_number(v) for v in r)
                                           for r in policies.values()) for policies in scores.values()),
                 "must give 'scores' as each env's policies' returns (lists of numbers)")
    return {**reference, "file": str(path)}


def published_at(published: dict[str, Any], frames: float) -> dict[str, float]:
    """The published seeds' scores at ``frames`` (each seed's curve interpolated linearly), summarised."""
    ys = np.array([np.interp(frames, s["xs"], s["ys"]) for s in published["seeds"]])
    return {"mean": float(ys.mean()), "std": float(ys.std()), "min": float(ys.min()), "max": float(ys.max()),
            "above_200": int((ys > 200).sum()), "seeds": len(ys)}


def reference_lines(reference: dict[str, Any] | None, env: str) -> list[str]:
    """The scores on ``env`` of policies that learned nothing at the curve's own evaluation starts
    (``benchmarks/reference_policies.py``), as a paragraph; none without ``--reference``."""
    if not reference or env not in reference["scores"]:
        return []
    first = reference["eval_episodes"]
    cells = ", ".join(f"{name} {signed(float(np.mean(returns[:first])))}" for name, returns in reference["scores"][env].items())
    return [f"Policies that learned nothing, scored at the same {first} evaluation starts as each point above "
            f"({reference['file']}, from `{reference['command']}`): {cells}. A run's score equal to a constant "
            "torque's is its actor saturated at that bound.", ""]


def markdown(record: dict[str, Any]) -> str:
    runs, published = record["runs"], record["published"]
    lines = [
        "# DrQ-v2 from pixels: learning curves",
        "",
        f"From `{record['command']}`. Each run's record was read from its checkpoint by `benchmarks/learning_curve.py` "
        "(a run stopped part-way included); its command and commits are in the record. DrQ-v2's settings and what "
        "it is given: the command reference, `docs/commands/baseline.md`. Evaluation: 5 episodes from the "
        "same seeded starts at each point (on DMC the score is DMC's, 0-1000; on the pixel pendulum, Pendulum-v1's "
        "return). The encoder's precision is the run's `--encoder-precision` (bfloat16: "
        "[results/drqv2_precision.md](drqv2_precision.md)). Training minutes are wall-clock time under whatever "
        "else the machine ran, not a speed measure (the benchmark above is); a run whose steps trained are below "
        "those planned continues (`piga-baseline ddpg --resume`). DrQ-v2's random warm-up is 4,000 frames "
        f"(its num_seed_frames, physics steps); a DMC run started before piga counted it in frames warmed up for "
        f"4,000 env steps, {4000 * DMC_FRAMES_PER_STEP:,} frames: the column says which.",
        "",
        "| run | env | view | device, encoder | random warm-up (frames) | env steps trained (planned) | best evaluation | "
        "first step above the mark | training min |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for r in runs:
        first = f"{r['first_step_above_mark']:,}" if r["first_step_above_mark"] is not None else "not yet"
        best = signed(r["best"]) if r["best"] is not None else "—"
        lines.append(f"| {r['name']} | {r['env']} | {r['view']} | {r['device']}, {r['precision']} | {r['warmup_frames']:,} | "
                     f"{r['trained']:,} ({r['planned']:,}) | "
                     f"{best} | {first} (mark {r['mark']:g}) | {r['train_minutes']:.0f} |")
    dmc = [r for r in runs if r["env"] == DMC_PENDULUM]
    if dmc:
        frames = sorted({p["frames"] for r in dmc for p in r["curve"]})
        sizes = sorted({r["buffer_size"] for r in dmc if r["buffer_size"] is not None})
        buffers = " or ".join(f"{n:,}" for n in sizes) or "unrecorded"  # each run's, from its record
        holds = all(r["buffer_size"] is not None and r["buffer_size"] >= r["planned"] for r in dmc)  # none dropped
        lines += [
            "",
            f"## {DMC_PENDULUM} against the published DrQ-v2",
            "",
            f"Published: {published['source']}, {len(published['seeds'])} seeds, each curve interpolated at the run's "
            "frames (env steps x 2). A score outside the seeds' range is marked (above) or (below) it. DrQ-v2's "
            "curve on this task is late and wide: at 100,000 frames 4 of its 9 seeds score above 200, at 200,000 "
            "6 of 9.",
            "",
            "What differs from the published runs (DrQ-v2's own code and its easy-task settings, which piga's "
            "preset takes): the view as the first table gives it (DrQ-v2's: 84x84 RGB through the suite's camera "
            "0, in front of the pendulum and above it, looking down at 45°; piga's face-on camera sits on the hinge "
            f"axis); a replay buffer of {buffers} transitions (its 1e6{'; each holds every transition of its run' if holds else ''}); 5 "
            "evaluation episodes at each point (its 10); the warm-up as the first table gives it. Two runs that "
            "differ in their view alone show what the view changes.",
            "",
            *reference_lines(record.get("reference"), DMC_PENDULUM),
            "| frames | " + " | ".join(r["name"] for r in dmc) + " | published mean ± std | published range | seeds above 200 |",
            "|---|" + "---|" * len(dmc) + "---|---|---|",
        ]
        at_frames = {x: published_at(published, x) for x in frames}
        for x in frames:
            at = at_frames[x]
            cells = []
            for r in dmc:
                score = next((p["score"] for p in r["curve"] if p["frames"] == x), None)
                side = "" if score is None or at["min"] <= score <= at["max"] else (" (above)" if score > at["max"] else " (below)")
                cells.append("" if score is None else f"{score:.1f}{side}")
            lines.append(f"| {x:,} | " + " | ".join(cells) + f" | {at['mean']:.0f} ± {at['std']:.0f} | "
                         f"{at['min']:.0f}–{at['max']:.0f} | {at['above_200']} of {at['seeds']} |")
        for r in dmc:  # the verdict the table shows: from which point on the run stays above every published seed
            since = len(r["curve"])  # the first of the points that, to the end, are all above the seeds' range
            while since and r["curve"][since - 1]["score"] > at_frames[r["curve"][since - 1]["frames"]]["max"]:
                since -= 1
            if since < len(r["curve"]):
                lines += ["", f"{r['name']} is above every published seed from {r['curve'][since]['frames']:,} frames "
                          "on: outside the published spread, above it (one seed; what differs is listed above)."]
        for r in dmc:  # a point below every published seed, next to how low the seeds go at the next points
            below = [p for p in r["curve"] if p["score"] < at_frames[p["frames"]]["min"]]
            if below:
                points = []
                for p in below:
                    later = min((x for x in frames if x > p["frames"]), key=lambda x: at_frames[x]["min"], default=None)
                    points.append(f"{p['score']:.1f} at {p['frames']:,} frames (the lowest seed {at_frames[p['frames']]['min']:.1f}"
                                  + (f"; {at_frames[later]['min']:.1f} at {later:,}" if later else "") + ")")
                lines += ["", f"{r['name']} is below every published seed at {len(below)} point(s): {', '.join(points)}."]
    pixel = [r for r in runs if r["env"] == PIXEL_PENDULUM]
    if pixel:
        steps = sorted({p["step"] for r in pixel for p in r["curve"]})
        lines += [
            "",
            f"## {PIXEL_PENDULUM}",
            "",
            "Evaluation return (Pendulum-v1's, 200 steps; the SB3 zoo's mark of a learned swing-up is −200).",
            "",
            *reference_lines(record.get("reference"), PIXEL_PENDULUM),
            "| env steps | " + " | ".join(f"{r['name']} ({r['device']}, {r['precision']})" for r in pixel) + " |",
            "|---|" + "---|" * len(pixel),
        ]
        for s in steps:
            cells = [next((signed(p["score"]) for p in r["curve"] if p["step"] == s), "") for r in pixel]
            lines.append(f"| {s:,} | " + " | ".join(cells) + " |")
    lines += ["", f"![DrQ-v2's curves]({Path(record['figure']).name})", ""]
    return "\n".join(lines)


def figure(record: dict[str, Any], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from piga.evaluation.plots import save_figure

    runs, published = record["runs"], record["published"]
    fig, (left, right) = plt.subplots(1, 2, figsize=(11, 4))
    for s in published["seeds"]:
        left.plot(np.array(s["xs"]) / 1000, s["ys"], color="0.75", lw=0.8)
    xs = np.linspace(0, max(max(s["xs"]) for s in published["seeds"]), 51)
    left.plot(xs / 1000, [published_at(published, x)["mean"] for x in xs], color="0.35", lw=1.5,
              label=f"published DrQ-v2 ({len(published['seeds'])} seeds, mean in dark)")
    for r in runs:
        ax = left if r["env"] == DMC_PENDULUM else right
        key = "frames" if ax is left else "step"
        ax.plot([p[key] / 1000 for p in r["curve"]], [p["score"] for p in r["curve"]], marker="o", lw=2,
                label=f"{r['name']} ({r['device']}, {r['precision']})")
    left.set(xlim=(0, 220), xlabel="frames (thousands; env steps x 2)", ylabel="DMC score", title=DMC_PENDULUM)
    left.axhline(200, color="k", ls=":", lw=0.8)
    right.set(xlabel="env steps (thousands)", ylabel="evaluation return", title=PIXEL_PENDULUM)
    right.axhline(-200, color="k", ls=":", lw=0.8)
    for ax in (left, right):
        if ax.get_legend_handles_labels()[0]:  # (no pixel pendulum run: its axis stays empty, with no legend to draw)
            ax.legend(fontsize=7)
    fig.tight_layout()
    save_figure(fig, path, dpi=110)


def main(argv: list[str] | None = None) -> int:
    p = ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--out", type=out_prefix, required=True, help="output prefix: OUT.md, OUT.json, OUT.png")
    p.add_argument("--runs", type=Path, nargs="+", required=True, help="learning_curve.py records")
    p.add_argument("--published", type=Path, required=True, help="published_scores.py's record of DrQ-v2's curve")
    p.add_argument("--reference", type=Path, help="reference_policies.py's record: what policies that learned nothing "
                   "score at the runs' evaluation starts")
    args = p.parse_args(argv)
    inputs = [*args.runs, args.published, *([args.reference] if args.reference else [])]
    outputs = [args.out.with_suffix(suffix) for suffix in (".md", ".json", ".png")]
    clash = next((o for o in outputs for i in inputs if o.resolve() == i.resolve()), None)
    if clash is not None:
        p.error(f"--out {args.out} would write {clash}, one of its inputs: give another --out")
    try:
        runs = [run_summary(path.stem, check_run(path, json.loads(path.read_text()))) for path in args.runs]
        published = check_published(args.published, json.loads(args.published.read_text()))
        reference = check_reference(args.reference, json.loads(args.reference.read_text())) if args.reference else None
    except (OSError, ValueError, KeyError) as exc:
        print(f"drqv2_curves.py: error: {' '.join(str(exc).split())}", file=sys.stderr)
        return 1
    command = shlex.join(["python", "benchmarks/drqv2_curves.py", *(sys.argv[1:] if argv is None else argv)])
    record = {"command": command, "runs": runs, "published": published, "figure": str(args.out.with_suffix(".png")),
              "reference": reference}
    figure(record, args.out.with_suffix(".png"))
    write_page(args.out, {**record, "published": {"source": published["source"], "file": str(args.published)}},
               markdown(record))
    return 0


if __name__ == "__main__":
    from piga.cli.common import run_script

    run_script(main, __file__)
