"""Benchmark: time per plan and per control step of the PlaNet-style agent (latent CEM with PlaNet's settings:
horizon 12, 10 iterations, 1000 candidates, top 100), by scoring engine and torch thread count.

The rows alternate within one run, so that a load that changes while it runs affects them alike:
"reference" scores candidates by rolling out the model's prior step by step
(:class:`agents.planet.planner.LatentDynamics`) and scoring the states with its reward head (the
readable loop), "fast" with :class:`agents.planet.imagine.Imagination` (the agent's
default; the same numbers without the overheads). Each timed call is one full ``act``: filtering
the newest frame into the belief, then planning, at the env steps where the agent plans (every
``action_repeat``-th); the mean per env step counts the held steps too. Both agents must pick the
same actions (checked).

The model is the default size (``RSSMConfig()``); its weights do not change the cost, so it needs
no training unless ``--model RUN_DIR`` (a ``piga-baseline planet`` run) is given:

    python benchmarks/planet_plan_time.py --out results/planet_plan_time --threads 1 2

With ``--device cuda`` the agents filter and plan on a GPU (PlaNet's batched latent CEM, as PlaNet ran it),
and the page names the GPU; each ``act`` ends with the action copied back to the CPU, so the times include the
synchronisation. A CUDA generator draws other numbers than the CPU's, so only the two GPU engines' actions are
compared with each other.

Writes OUT.json and OUT.md (with the machine and the load average). Nothing else should run on the
machine meanwhile; otherwise, read only the ratio.
"""

from __future__ import annotations

import os
import shlex
import sys
import time
from pathlib import Path

import numpy as np
import torch

from common import machine, out_prefix, write_page
from agents.planet.config import LatentPlannerConfig, RSSMConfig
from agents.planet.planner import PlanetAgent
from agents.planet.rssm import WorldModel
from piga.cli.common import ArgumentParser, PigaError, positive_int
from piga.io.pool import git_commit


def measure(model: WorldModel, threads: int, steps: int, seed: int = 0, device: str = "cpu") -> dict[str, object]:
    """Median ms per ``act`` for both engines, alternating, on ``threads`` torch threads and ``device``."""
    torch.set_num_threads(threads)
    frames = np.random.default_rng(seed).integers(0, 256, (steps, 1, 64, 64), dtype=np.uint8)
    agents = {"reference": PlanetAgent(model, LatentPlannerConfig(seed=seed), fast=False, device=device),
              "fast": PlanetAgent(model, LatentPlannerConfig(seed=seed), device=device)}
    times: dict[str, list[float]] = {name: [] for name in agents}
    actions: dict[str, list[float]] = {name: [] for name in agents}
    for agent in agents.values():
        agent.reset()
        agent.act(frames[0])  # warm-up (allocations, thread pool)
        agent.reset()
    planned: dict[str, list[bool]] = {name: [] for name in agents}
    for frame in frames:
        for name, agent in agents.items():
            start = time.perf_counter()
            actions[name].append(float(agent.act(frame)[0]))
            times[name].append(time.perf_counter() - start)
            planned[name].append(agent.planned)  # with an action repeat R, a plan at every R-th step only
    plans = {n: [t for t, p in zip(times[n], planned[n]) if p] for n in agents}
    reference, fast = (float(1000 * np.median(plans[n])) for n in ("reference", "fast"))
    return {"device": device, "threads": threads, "steps": steps, "action_repeat": model.config.action_repeat, "plans": len(plans["fast"]),
            "reference_ms": reference, "fast_ms": fast, "speedup": reference / fast,
            "fast_ms_per_step": float(1000 * np.sum(times["fast"]) / steps),
            "same_actions": bool(np.allclose(actions["reference"], actions["fast"], atol=1e-4))}


def main() -> int:
    p = ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--out", type=out_prefix, required=True, help="writes OUT.json and OUT.md")
    p.add_argument("--model", help="a piga-baseline planet run folder (default: an untrained default-size model)")
    p.add_argument("--threads", type=positive_int, nargs="+", default=[1], help="torch thread counts to measure (default 1)")
    p.add_argument("--steps", type=positive_int, default=20, help="env steps timed per engine and thread count (default 20)")
    p.add_argument("--device", choices=["cpu", "cuda"], default="cpu", help="where the agents plan (default cpu)")
    args = p.parse_args()
    if args.device == "cuda" and not torch.cuda.is_available():
        raise PigaError("--device cuda: torch sees no CUDA GPU here")
    if args.model:
        from agents.planet.run import load_planet

        model = load_planet(args.model)[0]
    else:
        torch.manual_seed(0)
        model = WorldModel(RSSMConfig()).eval()
    load_before = os.getloadavg()
    rows = [measure(model, t, args.steps, device=args.device) for t in args.threads]
    gpu = torch.cuda.get_device_name() if args.device == "cuda" else None
    record = {"command": shlex.join(["python", *sys.argv]), "commit": git_commit(), "machine": machine(), "gpu": gpu, "model": args.model or "untrained RSSMConfig()",
              "load_average_before": load_before, "load_average_after": os.getloadavg(), "rows": rows}
    out = Path(args.out)
    lines = [f"# PlaNet-style plan time per plan and per control step\n\nCommand: `{record['command']}` at commit "
             f"{(record['commit'] or 'unknown')[:7]}\n",
             (f"Machine: {record['machine']['cpu']}, {record['machine']['cores']} cores"
              + (f", planning on {gpu} (torch {torch.__version__})" if gpu else "")
              + f"; load average {load_before[0]:.2f} before, {record['load_average_after'][0]:.2f} after.\n"),
             f"The agent plans once every {rows[0]['action_repeat']} env steps (its model's action repeat); the ms "
             "columns are medians per plan, and the last one is the fast engine's mean time per env step.\n",
             "| threads | plans | reference ms | fast ms | speedup | fast ms per env step | same actions |",
             "|---|---|---|---|---|---|---|"]
    lines += [f"| {r['threads']} | {r['plans']} | {r['reference_ms']:.0f} | {r['fast_ms']:.0f} | {r['speedup']:.2f}x | "
              f"{r['fast_ms_per_step']:.0f} | {r['same_actions']} |" for r in rows]
    write_page(out, record, "\n".join(lines) + "\n")
    print("\n".join(lines[2:]))
    return 0


if __name__ == "__main__":
    from piga.cli.common import run_script

    run_script(main, __file__)
