"""Benchmark: time per control step of the planner, on one torch thread, encoding included.

For the oracle and the piga agent of a trained model, it runs upright swing-ups (episode 0 from
hanging down, the others from random states) and times each call of the agent's ``act``: for
the piga agent that is reading the state from the frames (encoder and velocity estimator) and
planning; for the oracle, planning alone. The planner is the default one (CEM, 200 candidates x
20 steps x 5 iterations, warm start).

A third row, "piga, nn.Module engine", plans with the same agent but rolls the candidates through
:func:`piga.physics.rollout` on the model's own ``Pendulum`` module, as the planner did before it
had a dynamics of its own: the difference is the overhead removed, and its success and return
show that the planner's decisions did not change.

It trains nothing. Give it a run folder of ``piga-train-model``, for example the control
benchmark's model (``piga-collect --out data/pendulum.h5`` then ``piga-train-model
data/pendulum.h5 --out runs/pendulum``):

    python benchmarks/plan_time.py --model runs/pendulum --out results/plan_time

Writes OUT.json and OUT.md (with the machine). Nothing else should run on the machine meanwhile.
"""

from __future__ import annotations

import argparse
import shlex
import sys
from pathlib import Path

import numpy as np
import torch
from torch import Tensor

from common import machine
from agents.mpc import MPCConfig, OracleAgent, PigaMPCAgent
from piga.atomic import atomic_output, write_json
from piga.episodes import EpisodeConfig, run_episodes, summary_markdown
from piga.model import PhysicsModel
from piga.physics import rollout
from piga.runs import load_model


class ModuleDynamics:
    """The reference: rollouts through :func:`piga.physics.rollout` and the model's ``Pendulum`` module
    (model convention inside, Gymnasium's outside)."""

    def __init__(self, model: PhysicsModel):
        self.system, self.integrator = model.system, model.integrator
        self.offset = model.physical_parameters().get("offset", 0.0)

    def rollout(self, theta: float, theta_dot: float, actions: Tensor) -> tuple[Tensor, Tensor]:
        b = actions.shape[0]
        p0 = torch.full((b, 1, 1), theta - self.offset)
        v0 = torch.full((b, 1, 1), float(theta_dot))
        p, v = rollout(self.system, self.integrator, p0, v0, actions)  # (B, H, 1, 1) each
        return p[..., 0, 0] + self.offset, v[..., 0, 0]

    def reset(self) -> None: ...

    def executed(self, action: np.ndarray) -> None: ...


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--model", required=True, help="run folder of piga-train-model (a pendulum model)")
    p.add_argument("--out", default="results/plan_time", help="output prefix (default %(default)s)")
    p.add_argument("--episodes", type=int, default=5, help="episodes per agent (default %(default)s)")
    p.add_argument("--steps", type=int, default=EpisodeConfig.steps, help="steps per episode (default %(default)s)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--no-reference", action="store_true", help="skip the nn.Module-engine row")
    args = p.parse_args()
    torch.set_num_threads(1)
    model, _ = load_model(args.model)
    learned = model.physical_parameters()
    mpc = MPCConfig(seed=args.seed)
    config = EpisodeConfig(episodes=args.episodes, steps=args.steps, seed=args.seed, frame_stack=model.config.input_frames)
    agents: list[tuple[str, object]] = [
        ("oracle", OracleAgent.for_env(config.env_config(), mpc)),
        ("piga", PigaMPCAgent(model, mpc)),
    ]
    if not args.no_reference:
        agents.append(("piga, nn.Module engine", PigaMPCAgent(model, mpc, dynamics=ModuleDynamics(model))))
    rows = []
    for label, agent in agents:
        result = run_episodes(agent, config)  # type: ignore[arg-type]
        rows.append({"agent": label, **result["summary"]})
        s = rows[-1]
        print(f"{label}: plan {s['plan_ms_median']:.2f} ms median, {s['plan_ms_p95']:.2f} ms p95; "
              f"success {100 * s['success_rate']:.0f}%, mean return {s['mean_return']:.1f}")
    command = shlex.join(["python", *sys.argv])
    where = machine()
    cem = mpc.cem
    md = "\n".join([
        "# Plan time per control step", "",
        f"Command: `{command}`", "",
        f"Model: `{args.model}` (learned g = {learned['g']:.4f}, a = {learned['a']:.4f}). Machine: {where['cpu']}, "
        f"{where['cores']} cores; one torch thread. Planner: CEM, {cem.candidates} candidates x {cem.horizon} steps x "
        f"{cem.iterations} iterations, top {cem.elites}, warm start. Time per call of the agent's `act`: for the piga "
        "agent, reading the state from the frames and planning; for the oracle, planning. The nn.Module-engine row plans "
        "with the same agent over `piga.physics.rollout` on the model's `Pendulum` module (the planner's engine before).", "",
        summary_markdown(rows),
    ])
    out = Path(args.out)
    with atomic_output(out.with_suffix(".md"), overwrite=True) as tmp:
        tmp.write_text(md)
    write_json(out.with_suffix(".json"), {"command": command, "machine": where, "model": args.model, "learned": learned,
                                          "rows": rows}, overwrite=True)
    print(f"wrote {out.with_suffix('.md')} and {out.with_suffix('.json')}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
