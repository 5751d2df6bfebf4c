"""Benchmark: piga against the PlaNet-style world model and SB3 DDPG, side by side (the paper's Figure 5).

Every agent is scored by the same episodes (:mod:`piga.episodes`: starts, seeds, success), on the
same machine, one process at a time:

1. **Sample efficiency**: success rate and mean return against the number of training sequences,
   for piga (``piga-train-model``'s recipe) and the PlaNet-style model trained on the same files
   (nested subsets of one random-action collection), over seeds; the oracle as a line.
2. **DDPG learning curves**: EvalCallback's mean return against env steps, from pixels, from an
   autoencoder's latent and from the true state, with the first step at which each reached -200.
3. **Zero-shot gravity sweep**: piga told the multiplier, the oracle, PlaNet-style and DDPG not told.
4. **Goal images**: piga reaches them; the baselines refuse (no goal input), as recorded.
5. **Plan time per step**: piga's CEM against PlaNet-style latent CEM, measured in this run.
6. **Compute**: training wall time of each agent, and the machine.

    python benchmarks/baselines.py --out results/baselines                  # the full comparison (hours)
    python benchmarks/baselines.py --out runs/check --preset tiny          # the pipeline end to end, in minutes

Finished runs are kept in ``OUT_runs/`` and skipped when the benchmark is run again, so an
interrupted benchmark continues where it stopped. ``OUT.json`` and ``OUT.md`` are rewritten
(atomically) at the end. Numbers of the ``tiny`` preset check the pipeline only; they are no result.
"""

from __future__ import annotations

import argparse
import json
import math
import shlex
import sys
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import Any

from common import machine
from piga.atomic import atomic_output, write_json


@dataclass(frozen=True)
class BenchConfig:
    """What the comparison runs."""

    sizes: tuple[int, ...] = (25, 50, 100, 250, 500, 1000, 2000)
    """Training sequences per point of the sample-efficiency sweep."""
    seeds: tuple[int, ...] = (0, 1, 2)
    """Training seeds per point."""
    steps: int = 40
    """Frames per collected sequence (piga-collect's default)."""
    data_seed: int = 100
    """Seed of the one random-action collection that every subset is cut from."""
    piga_epochs: int = 16
    """piga-train-model's epochs (its default)."""
    planet_steps: int = 3000
    """PlaNet-style optimiser steps (piga-baseline planet's default)."""
    ddpg_steps: tuple[tuple[str, int], ...] = (("state", 30000), ("latent", 80000), ("pixels", 80000))
    """DDPG budgets per observation (the paper's: proprioception 30k, latent 80k)."""
    ddpg_seeds: tuple[int, ...] = (0, 1, 2)
    """DDPG seeds."""
    episodes: int = 20
    """Control episodes per evaluation."""
    sweep: str = "0.5:1.8:0.1"
    """Gravity multipliers of the zero-shot sweep."""
    sweep_episodes: int = 10
    """Episodes per multiplier."""
    goal_angles: tuple[float, ...] = (-30.0, 15.0, 45.0)
    """Goal images (degrees) for piga."""
    episode_steps: int = 200
    """Steps per control episode."""
    overrides: dict[str, dict[str, Any]] = field(default_factory=dict)
    """Extra settings per stage (the tiny preset shrinks the models)."""


PRESETS: dict[str, BenchConfig] = {
    "full": BenchConfig(),
    "tiny": BenchConfig(sizes=(8, 16), seeds=(0,), steps=16, piga_epochs=1, planet_steps=4,
                        ddpg_steps=(("state", 400), ("latent", 400), ("pixels", 400)), ddpg_seeds=(0,), episodes=1,
                        sweep="1.0:1.4:0.4", sweep_episodes=1, goal_angles=(15.0,), episode_steps=20,
                        overrides={"planet": {"batch_size": 2, "chunk_length": 8}, "rssm": {"deter_size": 8, "stoch_size": 4},
                                   "piga": {"batch_size": 16, "warmup_steps": 2, "curriculum_steps": 2},
                                   "ddpg": {"learning_starts": 100, "eval_every": 200, "eval_episodes": 1, "batch_size": 16,
                                            "buffer_size": 1000},
                                   "autoencoder": {"steps": 20}, "cem": {"horizon": 3, "iterations": 2, "candidates": 20, "elites": 4}}),
}


def collect_subsets(cfg: BenchConfig, folder: Path) -> dict[int, Path]:
    """One data file per size: the first n sequences of one collection are its train split (nested
    subsets: sequence k depends only on (data_seed, k)), plus 10% more for valid and test."""
    from piga.collect import CollectConfig, collect

    files = {}
    for n in cfg.sizes:
        path = folder / f"data-n{n}.h5"
        extra = max(1, n // 10)
        if not path.exists():
            collect(CollectConfig(sequences=n + 2 * extra, steps=cfg.steps, seed=cfg.data_seed, workers=1, split=(n, extra, extra)),
                    path, progress=False, command=f"benchmarks/baselines.py (n={n})")
        files[n] = path
    return files


def evaluate(kind: str, run: Path | None, cfg: BenchConfig, gravity_mult: float = 1.0, episodes: int | None = None) -> dict[str, Any]:
    """piga.episodes' summary for one agent (kind "piga", "planet", "ddpg" or "oracle")."""
    from agents.config import CEMConfig
    from piga.episodes import EpisodeConfig
    from piga.jobs import ControlJob, run_job

    episode_config = EpisodeConfig(episodes=episodes or cfg.episodes, steps=cfg.episode_steps,
                                   hold_steps=min(20, cfg.episode_steps), gravity_mult=gravity_mult)
    job = ControlJob(kind, episode_config, model_dir=str(run) if run else None)
    if kind == "planet" and "cem" in cfg.overrides:  # tiny preset only: PlaNet's planner, shrunk
        from agents.planet.config import LatentPlannerConfig
        from agents.planet.planner import PlanetAgent
        from piga.baselines.planet_run import load_planet
        from piga.episodes import run_episodes

        agent = PlanetAgent(load_planet(run)[0], LatentPlannerConfig(cem=CEMConfig(**cfg.overrides["cem"])))
        return run_episodes(agent, replace(episode_config, frame_stack=1))["summary"]
    return run_job(job)["summary"]


def train_piga(data: Path, run: Path, seed: int, cfg: BenchConfig) -> float:
    """Trains (unless done) and returns the run's training seconds."""
    from piga.runs import load_model
    from piga.train import TrainConfig, train

    if not (run / "checkpoint.pt").exists():
        overrides = {"rec_frames": "input", "pred_frames": 4} if "piga" in cfg.overrides else {}
        train(data, run, TrainConfig(epochs=cfg.piga_epochs, seed=seed, threads=1, **cfg.overrides.get("piga", {})),
              overrides, progress=False)
    return float(load_model(run)[1]["state"]["elapsed"])


def train_planet_run(data: Path, run: Path, seed: int, cfg: BenchConfig) -> float:
    """Trains (unless done) and returns the run's training seconds."""
    from agents.planet.config import PlanetTrainConfig
    from piga.baselines.planet import rssm_config_for, train_planet
    from piga.data import inspect_dataset

    if not (run / "metrics.json").exists():
        config = PlanetTrainConfig(steps=cfg.planet_steps, seed=seed, threads=1, **cfg.overrides.get("planet", {}))
        train_planet(data, run, config, rssm_config_for(inspect_dataset(data), cfg.overrides.get("rssm")), progress=False)
        write_json(run / "config.json", {"kind": "planet", "data": str(data), "train": config.to_dict()})
    return float(json.loads((run / "metrics.json").read_text())["train_seconds"])


def train_ddpg_run(obs: str, steps: int, seed: int, data: Path, run: Path, cfg: BenchConfig) -> dict[str, Any]:
    """Trains (unless done) and returns the run's metrics (learning curve, seconds)."""
    from piga.baselines.autoencoder import AutoencoderConfig, train_autoencoder
    from piga.baselines.ddpg import AUTOENCODER, config_for, train_ddpg

    if not (run / "metrics.json").exists():
        config = config_for(obs, steps=steps, seed=seed, **cfg.overrides.get("ddpg", {}))
        run.mkdir(parents=True, exist_ok=True)
        autoencoder = None
        if obs == "latent":
            autoencoder = run / AUTOENCODER
            train_autoencoder(data, AutoencoderConfig(seed=seed, **cfg.overrides.get("autoencoder", {})), autoencoder, progress=False)
        train_ddpg(config, run, autoencoder, progress=False)
        write_json(run / "config.json", {"kind": "ddpg", "data": str(data), "ddpg": config.to_dict()})
    return json.loads((run / "metrics.json").read_text())


def goal_images(piga_run: Path, cfg: BenchConfig, folder: Path) -> list[dict[str, Any]]:
    """piga reaching goal images; the baselines have no goal input (refused by piga-control)."""
    import imageio.v3 as iio

    from agents.mpc import MPCConfig, PigaMPCAgent
    from piga.episodes import EpisodeConfig, run_episodes
    from piga.goal import goal_from_image, render_goal_image
    from piga.runs import load_model

    model, ckpt = load_model(piga_run)
    rows = []
    for angle in cfg.goal_angles:
        path = folder / f"goal{angle:g}.png"
        iio.imwrite(path, render_goal_image(angle))
        estimate = goal_from_image(model, ckpt, path)
        agent = PigaMPCAgent(model, replace(MPCConfig(), goal_angle=estimate.angle))
        summary = run_episodes(agent, EpisodeConfig(episodes=max(1, cfg.episodes // 5), steps=cfg.episode_steps,
                                                    hold_steps=min(20, cfg.episode_steps), goal_angle=math.radians(angle),
                                                    frame_stack=agent.input_frames))["summary"]
        rows.append({"goal_deg": angle, "read_deg": math.degrees(estimate.angle), "piga": summary,
                     "planet": "refused: no goal input", "ddpg": "refused: no goal input"})
    return rows


def markdown(record: dict[str, Any]) -> str:
    """The results page."""
    lines = [f"# Baselines: piga, PlaNet-style and DDPG\n\nCommand: `{record['command']}` (preset `{record['preset']}`)\n",
             f"Machine: {record['machine']}\n", "## Sample efficiency (gravity x1.0)\n",
             "| sequences | agent | seeds | success (mean) | mean return | train s (mean) |", "|---|---|---|---|---|---|"]
    for row in record["sample_efficiency"]:
        lines.append(f"| {row['sequences']} | {row['agent']} | {len(row['runs'])} | {100 * row['success_mean']:.0f}% | "
                     f"{row['return_mean']:.1f} | {row['train_seconds_mean']:.0f} |")
    o = record["oracle"]
    lines += [f"\nOracle: {100 * o['success_rate']:.0f}% success, mean return {o['mean_return']:.1f}.\n",
              "## DDPG\n", "| observation | seed | steps | first step at >= -200 | final eval return | success | train s |",
              "|---|---|---|---|---|---|---|"]
    for r in record["ddpg"]:
        lines.append(f"| {r['obs']} | {r['seed']} | {r['metrics']['steps']} | {r['metrics']['first_step_reaching_minus_200'] or 'never'} | "
                     f"{r['metrics']['final_eval_mean_return']:.1f} | {100 * r['control']['success_rate']:.0f}% | "
                     f"{r['metrics']['train_seconds']:.0f} |")
    lines += ["\n## Zero-shot gravity sweep (piga and the oracle told the multiplier; baselines not told)\n",
              "| gravity x | " + " | ".join(record["sweep"]["agents"]) + " |", "|---|" + "---|" * len(record["sweep"]["agents"])]
    for m, cells in zip(record["sweep"]["multipliers"], record["sweep"]["success"]):
        lines.append(f"| {m:g} | " + " | ".join(f"{100 * c:.0f}%" for c in cells) + " |")
    lines += ["\n## Goal images\n", "| goal (deg) | read (deg) | piga success | PlaNet-style | DDPG |", "|---|---|---|---|---|"]
    for g in record["goals"]:
        lines.append(f"| {g['goal_deg']:g} | {g['read_deg']:.2f} | {100 * g['piga']['success_rate']:.0f}% | {g['planet']} | {g['ddpg']} |")
    p = record["plan_time"]
    lines += [f"\n## Plan time per step (median, this run)\n\npiga {p['piga_ms']:.2f} ms, PlaNet-style {p['planet_ms']:.1f} ms: "
              f"ratio {p['ratio']:.1f}x.\n"]
    return "\n".join(lines) + "\n"


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--out", required=True, help="writes OUT.json, OUT.md; runs in OUT_runs/")
    p.add_argument("--preset", choices=sorted(PRESETS), default="full")
    args = p.parse_args()
    import torch

    torch.set_num_threads(1)
    cfg = PRESETS[args.preset]
    out = Path(args.out)
    folder = out.with_name(out.name + "_runs")
    folder.mkdir(parents=True, exist_ok=True)
    record: dict[str, Any] = {"command": shlex.join(["python", *sys.argv]), "preset": args.preset, "config": asdict(cfg),
                              "machine": machine()}
    files = collect_subsets(cfg, folder)
    rows = []
    for n, data in files.items():
        for agent, trainer in (("piga", train_piga), ("planet", train_planet_run)):
            runs = []
            for seed in cfg.seeds:
                run = folder / f"{agent}-n{n}-s{seed}"
                seconds = trainer(data, run, seed, cfg)
                runs.append({"seed": seed, "train_seconds": seconds, "control": evaluate(agent, run, cfg)})
                print(f"{agent} n={n} seed={seed}: success {runs[-1]['control']['success_rate']:.2f}", flush=True)
            rows.append({"sequences": n, "agent": agent, "runs": runs,
                         "success_mean": sum(r["control"]["success_rate"] for r in runs) / len(runs),
                         "return_mean": sum(r["control"]["mean_return"] for r in runs) / len(runs),
                         "train_seconds_mean": sum(r["train_seconds"] for r in runs) / len(runs)})
    record["sample_efficiency"] = rows
    record["oracle"] = evaluate("oracle", None, cfg)
    largest = files[max(cfg.sizes)]
    ddpg = []
    for obs, steps in cfg.ddpg_steps:
        for seed in cfg.ddpg_seeds:
            run = folder / f"ddpg-{obs}-s{seed}"
            metrics = train_ddpg_run(obs, steps, seed, largest, run, cfg)
            ddpg.append({"obs": obs, "seed": seed, "metrics": metrics, "control": evaluate("ddpg", run, cfg)})
            print(f"ddpg {obs} seed={seed}: first -200 at {metrics['first_step_reaching_minus_200']}", flush=True)
    record["ddpg"] = ddpg
    from piga.episodes import parse_range

    multipliers = parse_range(cfg.sweep)
    best = {agent: folder / f"{agent}-n{max(cfg.sizes)}-s{cfg.seeds[0]}" for agent in ("piga", "planet")}
    best["ddpg"] = folder / f"ddpg-{cfg.ddpg_steps[0][0]}-s{cfg.ddpg_seeds[0]}"
    agents = ["piga", "oracle", "planet", "ddpg"]
    record["sweep"] = {"agents": agents, "multipliers": multipliers,
                       "success": [[evaluate(a, best.get(a), cfg, m, cfg.sweep_episodes)["success_rate"] for a in agents]
                                   for m in multipliers]}
    record["goals"] = goal_images(best["piga"], cfg, folder)
    piga_ms = evaluate("piga", best["piga"], cfg, episodes=1)["plan_ms_median"]
    planet_ms = evaluate("planet", best["planet"], cfg, episodes=1)["plan_ms_median"]
    record["plan_time"] = {"piga_ms": piga_ms, "planet_ms": planet_ms, "ratio": planet_ms / piga_ms}
    write_json(out.with_suffix(".json"), record)
    with atomic_output(out.with_suffix(".md"), overwrite=True) as tmp:
        tmp.write_text(markdown(record))
    print(f"wrote {out.with_suffix('.json')} and {out.with_suffix('.md')}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
