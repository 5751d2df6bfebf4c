"""Benchmark: how much faster is DrQ-v2's update with its encoder in bfloat16, and how far does it move?

DrQ-v2's training time on a CPU is its update: convolutions over batches of 256 stacks, forward for the
observation and the next one, backward for one (a py-spy profile of a run on the DMC pendulum put 95% of its
time there; acting and rendering the rest). ``--encoder-precision bfloat16`` runs those convolutions under
torch's autocast, on images and weights kept channels-last in memory (oneDNN's native layout for them); the actor,
the critic and the losses stay float32.

For each precision the script builds the run's model exactly as ``piga-baseline ddpg --algo drqv2`` does
(:func:`agents.sb3.train.new_model`, the same seed), fills its replay buffer with ``--fill`` random-action
steps of the env, then times single updates (``DrQV2.train``, batch 256): ``--repeats`` rounds, each of
``--updates`` timed updates per precision after ``--warmup`` untimed ones, the precisions alternating within
a round so that a drift of the machine's speed touches both. The table gives the median seconds per update
and the ratio of the medians.

How far bfloat16 moves the update: from the same weights and the same batch, the critic's loss and the
encoder's gradient under each precision (relative difference, and the cosine of the two gradients).

    python benchmarks/drqv2_precision.py --out results/drqv2_precision

Writes ``OUT.json`` and ``OUT.md``. Time it on an otherwise idle machine (one torch thread: ``--threads``).
"""

from __future__ import annotations

import shlex
import statistics
import sys
import time
from typing import Any

import torch

from common import machine, machine_words, out_prefix, write_page
from piga.cli.common import ArgumentParser, positive_int

from agents.sb3.config import PRECISIONS, SB3Config, bfloat16_in_hardware
from envs import ENV_IDS, PIXEL_PENDULUM

#: The precisions compared (``auto`` is one of them, resolved).
COMPARED = tuple(p for p in PRECISIONS if p != "auto")


def build(precision: str, env: str, fill: int, threads: int) -> Any:
    """The run's DrQ-v2 model in ``precision``, its buffer holding ``fill`` random-action steps."""
    from agents.sb3.train import _vec_env, new_model

    episode = SB3Config(env=env, algo="drqv2", obs="pixels").episode_steps
    steps = (fill // episode + 2) * episode  # beyond the fill, a whole number of episodes (evaluations)
    config = SB3Config(env=env, algo="drqv2", obs="pixels", steps=steps, learning_starts=fill + 1,
                       eval_every=episode, encoder_precision=precision, threads=threads, device="cpu")
    venv = _vec_env(config, None, 0, episode_seed=config.seed)
    model = new_model(config, venv, torch.device("cpu"))
    model.learn(fill)  # below learning_starts: random actions, no update
    return model


def time_updates(model: Any, n: int) -> list[float]:
    """Seconds of each of ``n`` updates of a batch of 256."""
    out = []
    for _ in range(n):
        started = time.perf_counter()
        model.train(gradient_steps=1, batch_size=model.batch_size)
        out.append(time.perf_counter() - started)
    return out


def agreement(models: dict[str, Any]) -> dict[str, float]:
    """The critic's loss and the encoder's gradient of one update from float32's weights and one batch, under
    each precision: their relative differences and the gradients' cosine."""
    import torch.nn.functional as F

    from agents.sb3.drqv2 import random_shift

    reference = models["float32"]
    batch = reference.replay_buffer.sample(reference.batch_size)
    results = {}
    for name, model in models.items():
        policy = model.policy
        policy.load_state_dict(reference.policy.state_dict())
        generator = torch.Generator().manual_seed(0)
        obs = policy.encoder(random_shift(batch.observations.float(), generator=generator))
        q1, q2 = policy.critic(obs, batch.actions)
        target = batch.rewards  # the loss's form is what matters here, not a bootstrapped target
        loss = F.mse_loss(q1, target) + F.mse_loss(q2, target)
        policy.zero_grad(set_to_none=True)
        loss.backward()
        grad = torch.cat([p.grad.flatten() for p in policy.encoder.parameters()])
        results[name] = (loss.item(), grad)
    (loss32, grad32), (loss16, grad16) = results["float32"], results["bfloat16"]
    return {"critic_loss_float32": loss32, "critic_loss_bfloat16": loss16,
            "critic_loss_relative_difference": abs(loss16 - loss32) / abs(loss32),
            "encoder_gradient_relative_difference": ((grad16 - grad32).norm() / grad32.norm()).item(),
            "encoder_gradient_cosine": F.cosine_similarity(grad16, grad32, dim=0).item()}


def markdown(record: dict[str, Any]) -> str:
    m = record["timing"]
    a = record["agreement"]
    return "\n".join([
        "# DrQ-v2's update: the encoder in bfloat16 against float32",
        "",
        f"Measured on {machine_words(record['machine'])}; bfloat16 in hardware: "
        f"{'yes' if record['bfloat16_in_hardware'] else 'no'}. From `{record['command']}`.",
        "",
        f"One update of DrQ-v2 (batch 256 stacks of {record['frame_stack']} frames of {record['image_size']}x"
        f"{record['image_size']}, {record['env']}), medians over {record['repeats']} rounds of {record['updates']} updates each, "
        "the precisions alternating:",
        "",
        "| encoder (bfloat16: autocast, channels-last) | seconds per update (median) | min | max |",
        "|---|---|---|---|",
        *[f"| {p} | {m[p]['median']:.3f} | {m[p]['min']:.3f} | {m[p]['max']:.3f} |" for p in COMPARED],
        "",
        f"float32 / bfloat16: **{record['speedup']:.2f}x**. An agent step costs half an update (one update every 2 env "
        "steps) plus acting and rendering, about 5% of a run's time.",
        "",
        "From the same weights and batch, one update's critic loss differs by "
        f"{100 * a['critic_loss_relative_difference']:.3f}% and the encoder's gradient by "
        f"{100 * a['encoder_gradient_relative_difference']:.1f}% (cosine {a['encoder_gradient_cosine']:.4f}). "
        "Whether a run learns as well is a question for whole runs: results/ddpg_tuning.md.",
        "",
    ])


def main(argv: list[str] | None = None) -> int:
    p = ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--out", type=out_prefix, required=True, help="output prefix: OUT.json and OUT.md")
    p.add_argument("--env", choices=ENV_IDS, default=PIXEL_PENDULUM, help="the env (default %(default)s)")
    p.add_argument("--fill", type=positive_int, default=1000, help="random-action steps in the buffer (default %(default)s)")
    p.add_argument("--repeats", type=positive_int, default=5, help="rounds (default %(default)s)")
    p.add_argument("--updates", type=positive_int, default=5, help="timed updates per precision and round (default %(default)s)")
    p.add_argument("--warmup", type=int, default=2, help="untimed updates per precision first (default %(default)s)")
    p.add_argument("--threads", type=int, default=1, help="torch threads (default %(default)s)")
    args = p.parse_args(argv)
    if min(args.repeats, args.updates) < 1 or args.warmup < 0 or args.fill < 300 or args.threads < 1:
        p.error("need --repeats, --updates and --threads >= 1, --warmup >= 0 and --fill >= 300 (a batch of 256 n-step stacks)")
    torch.set_num_threads(args.threads)
    models = {precision: build(precision, args.env, args.fill, args.threads) for precision in COMPARED}
    for model in models.values():
        time_updates(model, args.warmup)
    seconds: dict[str, list[float]] = {precision: [] for precision in COMPARED}
    for _ in range(args.repeats):
        for precision, model in models.items():
            seconds[precision] += time_updates(model, args.updates)
    timing = {precision: {"median": statistics.median(s), "min": min(s), "max": max(s), "n": len(s)}
              for precision, s in seconds.items()}
    sample = models["float32"].observation_space.shape  # (K, H, W)
    record = {"command": shlex.join(["python", "benchmarks/drqv2_precision.py", *(sys.argv[1:] if argv is None else argv)]),
              "machine": machine(), "bfloat16_in_hardware": bfloat16_in_hardware(), "env": args.env,
              "frame_stack": sample[0], "image_size": sample[-1], "repeats": args.repeats, "updates": args.updates,
              "timing": timing, "speedup": timing["float32"]["median"] / timing["bfloat16"]["median"],
              "agreement": agreement(models), "seconds": seconds}
    write_page(args.out, record, markdown(record))
    return 0


if __name__ == "__main__":
    from piga.cli.common import run_script

    run_script(main, __file__)
