"""Benchmark: time per control step of the planner, on one torch thread, encoding included.

For the oracle and the piga agent of a trained model, it runs upright swing-ups (episode 0 from
hanging down, the others from random states) and times each call of the agent's ``act``: for
the piga agent that is reading the state from the frames (encoder and velocity estimator) and
planning; for the oracle, planning alone. The planner is the default one (CEM, 200 candidates x
20 steps x 5 iterations, warm start).

Two more rows plan with the same agent over slower engines of the same physics, kept here as
references: "piga, numpy operators" rolls the candidates with five in-place numpy operators per
step and scores them with torch operators (the planner's engine before its compiled loop), and
"piga, nn.Module engine" rolls them through :func:`piga.world.physics.rollout` on the model's own
``Pendulum`` module. The differences are the overhead removed; their success and return show
that the planner's decisions did not change.

With ``--planet RUN_DIR`` (a ``piga-baseline planet`` run), the PlaNet-style agent (latent CEM with
PlaNet's settings: horizon 12, 10 iterations, 1000 candidates, top 100) is timed too, in the same
process on the same episodes, and the page gives the ratio per env step: PlaNet-style plans once
every action-repeat env steps and holds the action between, piga at every step. This is the
benchmark's plan-time ratio measured in one run, on one machine, rather than across records.
PlaNet's settings imagine more model steps per env step than piga's (1000 x 12 x 10 per plan every
2 env steps, against 200 x 20 x 5 at every step: 3x). ``--equal-budget`` adds a row of the same
PlaNet-style agent whose CEM imagines piga's model steps per env step, over piga's lookahead in env
steps, with piga's iterations and elite fraction (:func:`equal_budget_cem`), and the page gives
both ratios: at each agent's own budget and at equal budget.

It trains nothing. Give it a run folder of ``piga-train-model``, for example the control
benchmark's model (``piga-collect --out data/pendulum.h5`` then ``piga-train-model
data/pendulum.h5 --out runs/pendulum``):

    python benchmarks/plan_time.py --model runs/pendulum --out results/plan_time
    python benchmarks/plan_time.py --model runs/pendulum --planet runs/planet --equal-budget --no-reference \
        --episodes 20 --out results/plan_time_planet

Writes OUT.json and OUT.md (with the machine). Nothing else should run on the machine meanwhile.
"""

from __future__ import annotations

import os
import shlex
import sys
import math
from dataclasses import replace
from pathlib import Path

import numpy as np
import torch
from torch import Tensor

from common import machine, out_prefix, write_page
from agents.config import CEMConfig
from agents.dynamics import PendulumDynamics, start_of
from agents.mpc import MPCConfig, OracleAgent, PigaMPCAgent
from piga.control.registry import baseline_agent
from piga.control.episodes import EpisodeConfig, run_episodes
from piga.evaluation.episodes import EpisodeSummary, summary_markdown
from piga.io.checkpoint import RunKind
from piga.world.model import PhysicsModel
from piga.world.physics import rollout
from piga.io.runs import load_model
from piga.cli.common import ArgumentParser, positive_int, seed_int


class ModuleDynamics:
    """The reference: rollouts through :func:`piga.world.physics.rollout` and the model's ``Pendulum`` module
    (model convention inside, Gymnasium's outside)."""

    def __init__(self, model: PhysicsModel):
        self.system, self.integrator = model.system, model.integrator
        self.offset = model.physical_parameters().get("offset", 0.0)

    def rollout(self, state: Tensor, actions: Tensor, generator: torch.Generator | None = None) -> Tensor:
        theta, theta_dot = start_of(state)
        b = actions.shape[0]
        p0 = torch.full((b, 1, 1), theta - self.offset)
        v0 = torch.full((b, 1, 1), float(theta_dot))
        p, v = rollout(self.system, self.integrator, p0, v0, actions)  # (B, H, 1, 1) each
        return torch.stack([p[..., 0, 0] + self.offset, v[..., 0, 0]], -1)  # (B, H, 2)

    def reset(self) -> None: ...

    def executed(self, action: np.ndarray) -> None: ...


class UfuncDynamics:
    """The reference: the same semi-implicit Euler as :class:`agents.dynamics.PendulumDynamics`, with
    five in-place numpy operators on (B,) rows per step; the planner scores it with torch operators."""

    def __init__(self, dynamics: PendulumDynamics):
        self.d = dynamics

    def rollout(self, state: Tensor, actions: Tensor, generator: torch.Generator | None = None) -> Tensor:
        theta, theta_dot = start_of(state)
        b, steps = actions.shape[:2]
        h = self.d.dt / self.d.substeps
        push = np.multiply(actions[..., 0].numpy().T, h * h * self.d.torque_gain, dtype=np.float32)  # (H, B): h²·k_u·u
        kick = np.float32(h * h * self.d.gravity_gain)
        angles, moves = np.empty((steps, b), np.float32), np.empty((steps, b), np.float32)
        q, d = np.full(b, theta, np.float32), np.full(b, h * theta_dot, np.float32)  # θ and h·θ̇
        s = np.empty(b, np.float32)
        for j in range(steps):
            for _ in range(self.d.substeps):
                np.sin(q, out=s)
                s *= kick
                s += push[j]
                d = np.add(d, s, out=moves[j])
                q = np.add(q, d, out=angles[j])
        moves *= np.float32(1.0 / h)
        return torch.from_numpy(np.stack([angles, moves], -1)).transpose(0, 1)  # (B, H, 2)

    def reset(self) -> None: ...

    def executed(self, action: np.ndarray) -> None: ...


PLANET = "PlaNet-style (latent CEM, PlaNet's settings)"
"""The row label of the PlaNet-style agent."""
PLANET_EQUAL = "PlaNet-style (latent CEM, piga's budget)"
"""The row label of the PlaNet-style agent planning with piga's model steps per env step."""


def model_steps(cem: CEMConfig) -> int:
    """Model steps one plan imagines: candidates x horizon x iterations."""
    return cem.candidates * cem.horizon * cem.iterations


def equal_budget_cem(piga: CEMConfig, repeat: int, planet: CEMConfig = CEMConfig()) -> CEMConfig:
    """A latent CEM that imagines piga's model steps per env step while planning once every ``repeat``
    env steps: piga's lookahead in env steps (its horizon / ``repeat`` latent steps, rounded up), piga's
    iterations and elite fraction, and the candidates that make up the work. PlaNet's other settings
    (``planet``: its initial std, no momentum) stay.

    For piga's 200 x 20 x 5 (top 20) and action repeat 2: 800 candidates x 10 steps x 5 iterations,
    top 80, 40,000 model steps per plan, 20,000 per env step like piga's."""
    horizon = math.ceil(piga.horizon / repeat)
    candidates = round(model_steps(piga) * repeat / (horizon * piga.iterations))
    return replace(planet, horizon=horizon, iterations=piga.iterations, candidates=candidates,
                   elites=max(1, round(candidates * piga.elites / piga.candidates)))


def planet_ratio(rows: list[dict]) -> dict | None:
    """The PlaNet-style rows' median time per env step (per plan / env steps per plan) over piga's, from
    the rows of one run (each row with its ``model_steps`` per plan); None without a PlaNet-style row."""
    by = {row["agent"]: row for row in rows}
    if PLANET not in by:
        return None
    piga_ms = by["piga"]["plan_ms_median"]
    out: dict = {"piga_ms_per_step": piga_ms, "piga_model_steps_per_step": by["piga"]["model_steps"]}
    texts = []
    for key, label, what in (("own", PLANET, "at each agent's own budget"), ("equal", PLANET_EQUAL, "at equal budget")):
        if label not in by:
            continue
        row = by[label]
        repeat = row["env_steps_per_plan"]
        per_step = row["plan_ms_median"] / repeat
        out[key] = {"planet_ms_per_plan": row["plan_ms_median"], "planet_ms_per_step": per_step,
                    "planet_model_steps_per_step": row["model_steps"] / repeat, "ratio_per_step": per_step / piga_ms}
        texts.append(f"{what} ({row['model_steps'] / repeat:,.0f} model steps per env step against piga's "
                     f"{by['piga']['model_steps']:,}), PlaNet-style {per_step:.1f} ms (a plan of {row['plan_ms_median']:.1f} ms "
                     f"every {repeat} env steps) against piga's {piga_ms:.2f} ms: piga plans {per_step / piga_ms:.0f}x faster")
    out["ratio_per_step"] = out["own"]["ratio_per_step"]  # the own-budget row exists: PLANET is in the rows
    out["text"] = "Per env step, in this run: " + "; ".join(texts) + "."
    return out


def main() -> int:
    p = ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--model", required=True, help="run folder of piga-train-model (a pendulum model)")
    p.add_argument("--out", type=out_prefix, default="results/plan_time", help="output prefix (default %(default)s)")
    p.add_argument("--episodes", type=positive_int, default=5, help="episodes per agent (default %(default)s)")
    p.add_argument("--steps", type=positive_int, default=EpisodeConfig.steps, help="steps per episode (default %(default)s)")
    p.add_argument("--seed", type=seed_int, default=0)
    p.add_argument("--no-reference", action="store_true", help="skip the two reference-engine rows")
    p.add_argument("--planet", help="also time the PlaNet-style agent of this piga-baseline planet run (PlaNet's planner)")
    p.add_argument("--equal-budget", action="store_true",
                   help="with --planet: also time it planning piga's model steps per env step (equal_budget_cem)")
    args = p.parse_args()
    if args.equal_budget and not args.planet:
        p.error("--equal-budget times the --planet run's agent at piga's budget; give --planet")
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
        learned_dynamics = PendulumDynamics.of(model.system, model.integrator)  # type: ignore[arg-type]
        agents.append(("piga, numpy operators", PigaMPCAgent(model, mpc, dynamics=UfuncDynamics(learned_dynamics))))
        agents.append(("piga, nn.Module engine", PigaMPCAgent(model, mpc, dynamics=ModuleDynamics(model))))
    cems = {label: mpc.cem for label, _ in agents}
    if args.planet:  # piga-control's PlaNet-style agent: PlaNet's planner settings
        planet = baseline_agent(RunKind.PLANET, args.planet, seed=args.seed)
        agents.append((PLANET, planet))
        cems[PLANET] = planet.config.cem  # type: ignore[attr-defined]
        if args.equal_budget:
            from agents.planet.config import LatentPlannerConfig
            from agents.planet.planner import PlanetAgent

            equal = equal_budget_cem(mpc.cem, planet.repeat, planet.config.cem)  # type: ignore[attr-defined]
            agents.append((PLANET_EQUAL, PlanetAgent(planet.model, LatentPlannerConfig(cem=equal, seed=args.seed))))  # type: ignore[attr-defined]
            cems[PLANET_EQUAL] = equal
    load_before = os.getloadavg()
    rows = []
    for label, agent in agents:
        # each agent reads the frames it needs (PlaNet-style: the newest), and plans every `repeat` env steps
        result = run_episodes(agent, replace(config, frame_stack=getattr(agent, "input_frames", config.frame_stack)))  # type: ignore[arg-type]
        rows.append({"agent": label, **result.summary.to_dict(), "env_steps_per_plan": getattr(agent, "repeat", 1),
                     "cem": cems[label].__dict__, "model_steps": model_steps(cems[label])})
        s = rows[-1]
        print(f"{label}: plan {s['plan_ms_median']:.2f} ms median, {s['plan_ms_p95']:.2f} ms p95; "
              f"success {100 * s['success_rate']:.0f}%, mean return {s['mean_return']:.1f}")
    command = shlex.join(["python", *sys.argv])
    where = machine()
    load = {"before": load_before, "after": os.getloadavg()}
    cem = mpc.cem
    ratio = planet_ratio(rows)
    if ratio:
        print(ratio["text"])
    md = "\n".join([
        "# Plan time per control step", "",
        f"Command: `{command}`", "",
        f"Model: `{args.model}` (learned g = {learned['g']:.4f}, a = {learned['a']:.4f}). Machine: {where['cpu']}, "
        f"{where['cores']} cores; load average {load['before'][0]:.2f} before, {load['after'][0]:.2f} after (1 min); one torch "
        f"thread. Planner: CEM, {cem.candidates} candidates x {cem.horizon} steps x "
        f"{cem.iterations} iterations, top {cem.elites}, warm start. Time per call of the agent's `act`: for the piga "
        "agent, reading the state from the frames and planning; for the oracle, planning."
        + ("" if args.no_reference else " The reference rows plan with the same agent over slower engines of the same "
           "physics: five in-place numpy operators per step, scored with torch operators (\"numpy operators\"), and "
           "`piga.world.physics.rollout` on the model's `Pendulum` module (\"nn.Module engine\").")
        + " The planner's own engine is one numba-compiled loop that rolls and scores.", "",
        summary_markdown([EpisodeSummary.from_dict(r) for r in rows]).rstrip(),
        *([] if ratio is None else [
            "", f"PlaNet-style: `{args.planet}` (a `piga-baseline planet` run). Its row times its plans only: `act` at the "
            "env steps where it plans (filtering the newest frame into its belief, then latent CEM); it holds the action "
            "in between.", "", "| agent | CEM per plan (candidates x horizon x iterations, top) | env steps per plan | "
            "model steps per env step |", "|---|---|---|---|",
            *(f"| {r['agent']} | {r['cem']['candidates']} x {r['cem']['horizon']} x {r['cem']['iterations']}, top "
              f"{r['cem']['elites']} | {r['env_steps_per_plan']} | {r['model_steps'] / r['env_steps_per_plan']:,.0f} |"
              for r in rows if r["agent"] in ("piga", PLANET, PLANET_EQUAL)),
            "", ratio["text"]]),
    ])
    out = Path(args.out)
    write_page(out, {"command": command, "machine": where, "model": args.model, "learned": learned,
                     "load_average": load, "rows": rows, "planet": args.planet, "planet_ratio": ratio}, md)
    return 0


if __name__ == "__main__":
    from piga.cli.common import run_script

    run_script(main, __file__)
