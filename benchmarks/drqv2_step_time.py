"""Benchmark: where a DrQ-v2 training step's time goes (env, acting, replay sampling, the update), on a CPU or a GPU.

A run's env step is one ``venv.step`` (the env with its view: for ``piga/DMCPendulum-v0 --view drqv2``, two MuJoCo
steps and one 84x84 RGB render, stacked), one action from the actor (``model.predict``), and, every
``train_freq`` steps, one update (``DrQV2.train``: a batch of 256 n-step stacks sampled from SB3's replay buffer,
moved to the device, then the critic's and the actor's steps). The script builds the run's model exactly as
``piga-baseline ddpg --algo drqv2`` does (:func:`agents.sb3.train.new_model`), fills its buffer with ``--fill``
random-action steps, then times each part alone (medians of ``--repeats`` calls, after two untimed ones), and
last the whole loop (``model.learn`` for ``--loop`` more steps, evaluations off), so that the parts' sum can be
checked against the loop:

    python benchmarks/drqv2_step_time.py --out results/drqv2_step_time --env piga/DMCPendulum-v0 --view drqv2

On a GPU (``--device cuda``) each timed call ends with ``torch.cuda.synchronize()``. The page adds what an
evaluation costs (its ``eval_episodes`` episodes of env steps and deterministic actions) and the steps per second
that a run with evaluations every ``--eval-every`` steps can reach. Writes ``OUT.json`` and ``OUT.md``; time it
on an otherwise idle machine.
"""

from __future__ import annotations

import shlex
import statistics
import sys
import time
from collections.abc import Callable
from typing import Any

import numpy as np
import torch

from common import machine, machine_words, out_prefix, write_page
from piga.cli.common import ArgumentParser, positive_int
from piga.io.pool import git_commit

from agents.sb3.config import DMC_VIEWS, SB3Config
from envs import ENV_IDS, PIXEL_PENDULUM


def median_ms(call: Callable[[], Any], repeats: int, sync: Callable[[], None]) -> float:
    """Median milliseconds of ``call`` over ``repeats`` timed calls, after two untimed ones."""
    for _ in range(2):
        call()
    times = []
    for _ in range(repeats):
        sync()
        started = time.perf_counter()
        call()
        sync()
        times.append(time.perf_counter() - started)
    return 1000 * statistics.median(times)


def measure(config: SB3Config, device: torch.device, fill: int, repeats: int, loop: int) -> dict[str, Any]:
    """Median ms of each part of a training step, and the loop's ms per step."""
    from agents.sb3.train import _vec_env, new_model

    sync = torch.cuda.synchronize if device.type == "cuda" else (lambda: None)
    venv = _vec_env(config, None, 0, episode_seed=config.seed)
    model = new_model(config, venv, device)
    model.learn(fill)  # below learning_starts: random actions, no update
    obs = venv.reset()
    rng = np.random.default_rng(0)
    low, high = venv.action_space.low, venv.action_space.high
    parts = {
        "env_step": median_ms(lambda: venv.step(rng.uniform(low, high, (1, *low.shape)).astype(np.float32)), repeats, sync),
        "act": median_ms(lambda: model.predict(obs, deterministic=False), repeats, sync),
        "sample": median_ms(lambda: model.replay_buffer.sample(model.batch_size), repeats, sync),
        "update": median_ms(lambda: model.train(gradient_steps=1, batch_size=model.batch_size), repeats, sync),
    }
    sync()
    started = time.perf_counter()
    model.learn(loop, reset_num_timesteps=False)  # past learning_starts: acting, storing and updating, no evaluation
    sync()
    loop_ms = 1000 * (time.perf_counter() - started) / loop
    per_step = parts["env_step"] + parts["act"] + parts["update"] / config.train_freq
    return {"parts_ms": parts, "sum_ms_per_step": per_step, "loop_ms_per_step": loop_ms}


def markdown(record: dict[str, Any]) -> str:
    r = record["result"]
    p = r["parts_ms"]
    freq, episodes, episode = record["train_freq"], record["eval_episodes"], record["episode_steps"]
    eval_ms = episodes * episode * (p["env_step"] + p["act"])
    every = record["eval_every"]
    rate = 1000 * every / (every * r["loop_ms_per_step"] + eval_ms)
    device = record["gpu"] or "the CPU"
    return "\n".join([
        "# Where DrQ-v2's training step goes",
        "",
        f"Measured on {machine_words(record['machine'])}; model and batches on {device}. From `{record['command']}` "
        f"at commit {(record.get('commit') or 'unknown')[:7]}.",
        "",
        f"DrQ-v2 on `{record['env']}` (view {record['view']}), buffer filled with {record['fill']} random-action steps; "
        f"medians of {record['repeats']} calls each:",
        "",
        "| part | ms per call | calls per env step | ms per env step |",
        "|---|---|---|---|",
        f"| env step (physics, render, stack) | {p['env_step']:.2f} | 1 | {p['env_step']:.2f} |",
        f"| act (actor on one stack) | {p['act']:.2f} | 1 | {p['act']:.2f} |",
        f"| update (batch {record['batch_size']}; its replay sample included) | {p['update']:.2f} | 1/{freq} | {p['update'] / freq:.2f} |",
        f"| of which the replay sample (to the device) | {p['sample']:.2f} | 1/{freq} | {p['sample'] / freq:.2f} |",
        f"| sum | | | {r['sum_ms_per_step']:.2f} |",
        f"| the whole loop (`model.learn`, {record['loop']} steps, no evaluation) | | | {r['loop_ms_per_step']:.2f} |",
        "",
        f"An evaluation ({episodes} episodes of {episode} env steps, acting deterministically) costs about "
        f"{eval_ms / 1000:.0f} s. With one every {every} steps, a run makes about **{rate:.0f} env steps per second**.",
        "",
    ])


def main(argv: list[str] | None = None) -> int:
    p = ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--out", type=out_prefix, required=True, help="output prefix: OUT.json and OUT.md")
    p.add_argument("--env", choices=ENV_IDS, default=PIXEL_PENDULUM, help="the env (default %(default)s)")
    p.add_argument("--view", choices=sorted(DMC_VIEWS), default="face", help="the DMC env's view (default %(default)s)")
    p.add_argument("--device", choices=["cpu", "cuda"], default="cpu", help="where the model trains (default %(default)s)")
    p.add_argument("--fill", type=positive_int, default=1000, help="random-action steps in the buffer (default %(default)s)")
    p.add_argument("--repeats", type=positive_int, default=20, help="timed calls per part (default %(default)s)")
    p.add_argument("--loop", type=positive_int, default=200, help="steps of the timed whole loop (default %(default)s)")
    p.add_argument("--eval-every", type=positive_int, default=5000, help="the run's evaluation period, for the page's "
                   "steps per second (default %(default)s)")
    p.add_argument("--threads", type=positive_int, default=1, help="torch threads (default %(default)s)")
    args = p.parse_args(argv)
    if args.fill < 300:
        p.error("--fill must be at least 300 (a batch of 256 n-step stacks)")
    if args.device == "cuda" and not torch.cuda.is_available():
        p.error("--device cuda: torch sees no CUDA GPU here")
    torch.set_num_threads(args.threads)
    view = {"view": args.view} if args.env != PIXEL_PENDULUM else {}
    episode = SB3Config(env=args.env, algo="drqv2", obs="pixels", **view).episode_steps
    steps = ((args.fill + args.loop) // episode + 2) * episode  # a whole number of evaluations, never reached
    config = SB3Config(env=args.env, algo="drqv2", obs="pixels", steps=steps, learning_starts=args.fill + 1, eval_every=episode,
                       threads=args.threads, device=args.device, **view)
    device = torch.device(args.device)
    result = measure(config, device, args.fill, args.repeats, args.loop)
    record = {"command": shlex.join(["python", "benchmarks/drqv2_step_time.py", *(sys.argv[1:] if argv is None else argv)]),
              "commit": git_commit(), "machine": machine(),
              "gpu": torch.cuda.get_device_name() if device.type == "cuda" else None,
              "env": args.env, "view": config.view, "fill": args.fill, "repeats": args.repeats, "loop": args.loop,
              "batch_size": config.batch_size, "train_freq": config.train_freq, "eval_every": args.eval_every,
              "eval_episodes": config.eval_episodes, "episode_steps": config.episode_steps, "result": result}
    write_page(args.out, record, markdown(record))
    return 0


if __name__ == "__main__":
    from piga.cli.common import run_script

    run_script(main, __file__)
