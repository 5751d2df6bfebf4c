"""Benchmark: how Gymnasium's ±8 rad/s speed clip biases a fit of g and a, by reset speed range.

It steps Gymnasium's own ``Pendulum-v1`` (no rendering) with random actions u ~ U(-2, 2) from
resets θ ~ U(-π, π), θ̇ ~ U(-s, s), for Gymnasium's s = 1 and the paper's s = 6. It then fits
g and a by least squares on the true states with the model's engine (one semi-implicit Euler
step per frame, no clip): θ̇_{t+1} - θ̇_t = dt·(1.5·g·sin θ_t + 3·a·u_t). The share of steps the
clip touches and the fitted errors show why ``piga-collect`` keeps Gymnasium's ±1 by default.

    python benchmarks/speed_clip_bias.py --out results/speed_clip_bias
"""

from __future__ import annotations

import shlex
import sys
from pathlib import Path

import gymnasium as gym
import numpy as np

from envs.pendulum import MAX_ACTION, PENDULUM_DT
from common import out_prefix, write_page
from piga.cli.common import ArgumentParser, positive_int, seed_int


def fit(max_speed: float, sequences: int, steps: int, seed: int) -> dict[str, float]:
    """Least-squares g, a on true states, and the share of steps at the clip."""
    env = gym.make("Pendulum-v1")
    rng = np.random.default_rng(seed)
    rows, targets, clipped = [], [], 0
    for n in range(sequences):
        env.reset(seed=seed + n, options={"x_init": np.pi, "y_init": max_speed})
        for _ in range(steps):
            th, thd = env.unwrapped.state
            u = rng.uniform(-MAX_ACTION, MAX_ACTION)
            env.step(np.array([u], dtype=np.float32))
            thd_next = env.unwrapped.state[1]
            clipped += abs(thd_next) >= 8 - 1e-6
            rows.append([1.5 * PENDULUM_DT * np.sin(th), 3 * PENDULUM_DT * u])
            targets.append(thd_next - thd)
    (g, a), *_ = np.linalg.lstsq(np.array(rows), np.array(targets), rcond=None)
    return {"max_speed": max_speed, "clipped_share": clipped / (sequences * steps), "g": float(g), "a": float(a),
            "g_error": float(g / 10 - 1), "a_error": float(a - 1)}


def main() -> None:
    p = ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--out", type=out_prefix, default="results/speed_clip_bias", help="output stem (.json and .md)")
    p.add_argument("--sequences", type=positive_int, default=500)
    p.add_argument("--steps", type=positive_int, default=40)
    p.add_argument("--seed", type=seed_int, default=0)
    args = p.parse_args()
    rows = [fit(s, args.sequences, args.steps, args.seed) for s in (1.0, 6.0)]
    command = shlex.join(["python", *sys.argv])
    lines = ["# Gymnasium's speed clip and a fit of g and a", "", f"Command: `{command}`", "",
             f"{args.sequences} sequences x {args.steps} steps of random actions per row; least squares on the true states.", "",
             "| reset θ̇ range | steps at the ±8 clip | fitted g | g error | fitted a | a error |", "|---|---|---|---|---|---|"]
    lines += [f"| ±{r['max_speed']:g} | {100 * r['clipped_share']:.1f}% | {r['g']:.3f} | {100 * r['g_error']:+.1f}% | {r['a']:.3f} | "
              f"{100 * r['a_error']:+.1f}% |" for r in rows]
    print("\n".join(lines))
    write_page(Path(args.out), {"command": command, "rows": rows}, "\n".join(lines) + "\n")  # both or neither


if __name__ == "__main__":
    from piga.cli.common import run_script

    run_script(main, __file__)
