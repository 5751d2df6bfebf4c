"""Benchmark: what policies that learned nothing score in the SB3 runs' own evaluation.

A learning curve's "above random" needs random's score, measured the way the curve is: this plays uniformly random
actions, no torque, and full torque either way, each through the evaluation that ``piga-baseline ddpg`` scores its
runs with (its env as the run sees it, SB3's ``evaluate_policy``, the evaluation env seeded with the run's seed +
10000 before the episodes, as its ``EvalCallback`` is: the first ``--eval-episodes`` episodes are exactly the
starts each point of a run's curve is scored on), then ``--episodes`` in all for a steadier mean.

    python benchmarks/reference_policies.py --out results/reference_policies

Writes ``OUT.json`` and ``OUT.md``.
"""

from __future__ import annotations

import shlex
import sys
from typing import Any

import numpy as np

from common import machine, machine_words, out_prefix, signed, write_page
from piga.cli.common import ArgumentParser, positive_int, seed_int

from envs import DMC_PENDULUM, ENV_IDS, PIXEL_PENDULUM

#: The policies: a name and the action each step (``rng`` draws the random one).
POLICIES = ("uniform random", "no torque", "full torque +1", "full torque −1")


class Fixed:
    """A policy for SB3's ``evaluate_policy``: ``predict`` returns one of :data:`POLICIES`' actions for each env."""

    def __init__(self, name: str, seed: int) -> None:
        self.name, self.rng = name, np.random.default_rng(seed)

    def predict(self, observation: Any, state: Any = None, episode_start: Any = None,
                deterministic: bool = True) -> tuple[np.ndarray, None]:
        n = len(observation)
        if self.name == "uniform random":
            return self.rng.uniform(-1.0, 1.0, (n, 1)).astype(np.float32), None
        value = {"no torque": 0.0, "full torque +1": 1.0, "full torque −1": -1.0}[self.name]
        return np.full((n, 1), value, np.float32), None


def scores(env: str, name: str, seed: int, episodes: int) -> list[float]:
    """The returns of ``episodes`` evaluation episodes of policy ``name`` on ``env``, from the run's evaluation starts."""
    from stable_baselines3.common.evaluation import evaluate_policy

    from agents.sb3.config import SB3Config
    from agents.sb3.train import _vec_env

    config = SB3Config(env=env, obs="pixels", algo="drqv2", seed=seed)  # the pixel runs' env and frame stack
    venv = _vec_env(config, None, 0, episode_seed=None)
    try:
        venv.seed(config.seed + 10_000)  # as the runs' evaluation callback does before each evaluation
        returns, _ = evaluate_policy(Fixed(name, seed), venv, n_eval_episodes=episodes, deterministic=True,
                                     return_episode_rewards=True)
    finally:
        venv.close()
    return [float(r) for r in returns]


def markdown(record: dict[str, Any]) -> str:
    first = record["eval_episodes"]
    lines = [
        "# Policies that learned nothing, in the SB3 runs' evaluation",
        "",
        f"From `{record['command']}` on {machine_words(record['machine'])}.",
        "",
        f"Each policy plays {record['episodes']} evaluation episodes from the starts a run of seed {record['seed']} is "
        f"evaluated on; the first {first} are exactly the starts of each point of its learning curve. On "
        f"{DMC_PENDULUM} the return is DMC's score (0-1000; a run has learned at 200), on {PIXEL_PENDULUM} "
        "Pendulum-v1's return (learned at −200).",
        "",
        f"| env | policy | mean of the first {first} (the curve's starts) | mean ± std of all {record['episodes']} | range |",
        "|---|---|---|---|---|",
    ]
    for env, by_policy in record["scores"].items():
        for name, returns in by_policy.items():
            xs = np.array(returns)
            lines.append(f"| {env} | {name} | {signed(xs[:first].mean())} | {signed(xs.mean())} ± {xs.std():.1f} | "
                         f"{signed(xs.min())} to {signed(xs.max())} |")
    return "\n".join(lines + [""])


def main(argv: list[str] | None = None) -> int:
    p = ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--out", type=out_prefix, required=True, help="output prefix: OUT.md and OUT.json")
    p.add_argument("--envs", nargs="+", choices=ENV_IDS, default=list(ENV_IDS), help="the envs (default: both)")
    p.add_argument("--episodes", type=positive_int, default=50, help="episodes per policy (default %(default)s)")
    p.add_argument("--seed", type=seed_int, default=0, help="the run seed whose evaluation starts are played (default %(default)s)")
    args = p.parse_args(argv)
    from agents.sb3.config import SB3Config

    eval_episodes = SB3Config().eval_episodes
    if args.episodes < eval_episodes:
        p.error(f"--episodes must be at least the runs' {eval_episodes} evaluation episodes")
    results = {env: {name: scores(env, name, args.seed, args.episodes) for name in POLICIES} for env in args.envs}
    command = shlex.join(["python", "benchmarks/reference_policies.py", *(sys.argv[1:] if argv is None else argv)])
    record = {"command": command, "machine": machine(), "seed": args.seed, "episodes": args.episodes,
              "eval_episodes": eval_episodes, "scores": results}
    write_page(args.out, record, markdown(record))
    return 0


if __name__ == "__main__":
    from piga.cli.common import run_script

    run_script(main, __file__)
