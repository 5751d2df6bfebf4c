"""Benchmark: how the scenes' velocity reading biases the physical parameters, on true positions (no pixels).

For each scene (spring, gravity, digits-spring, the paper's values) it simulates sequences as
``piga-collect`` does (:func:`envs.scenes.draw_start`, seed 100) and fits the engine's physical
parameters to the true positions: windows of the fast preset's L and T_pred, the engine's Euler with
M = 5 substeps, parameters from 1, Adam. The only difference between the rows is how the velocity
at frame L is read from the L true positions: ``cubic`` (the backward difference plus the Taylor
term of ``ModelConfig.velocity_physics``) or ``shoot`` (``ModelConfig.velocity_shoot``: through the
engine). Without pixels, an encoder or a velocity MLP, whatever bias is left is the velocity
reading's and the integrator's.

    python benchmarks/velocity_bias.py --out results/velocity_bias

Writes OUT.json and OUT.md.
"""

from __future__ import annotations

import sys
from typing import Any

import numpy as np
import torch
from common import machine, out_prefix, write_page

from envs.scenes import draw_start, scene_config
from piga.data.collect import sequence_rng
from piga.data.collect_scenes import SCENE_STEPS
from piga.world.model import ModelConfig, PhysicsModel
from piga.cli.common import ArgumentParser, positive_int, seed_int

SCENES = ("spring", "gravity", "digits-spring")
MODES = {"cubic": {"velocity_physics": True}, "shoot": {"velocity_shoot": True}}


def true_positions(scene: str, sequences: int, seed: int) -> torch.Tensor:
    """(B, T, N, 2) positions of ``sequences`` sequences drawn as piga-collect draws them."""
    config = scene_config(scene)
    paths = [draw_start(config, sequence_rng(seed, n)[1], SCENE_STEPS[scene])[0] for n in range(sequences)]
    return torch.tensor(np.stack(paths), dtype=torch.float64)


def fit(scene: str, positions: torch.Tensor, mode: str, steps: int, seed: int) -> dict[str, float]:
    """The engine's parameters fitted to true positions with one velocity reading."""
    config = scene_config(scene)
    ell, t_pred = 4, 12 if config.physics == "gravity" else 6  # the fast preset's windows
    windows = torch.cat([positions[:, s : s + ell + t_pred]
                         for s in range(0, positions.shape[1] - ell - t_pred + 1, 2)])  # (W, L+T, N, 2)
    model = PhysicsModel(ModelConfig(system=config.physics, dt=config.dt, image_size=config.image_size, channels=3,
                                     n_objects=config.n_objects, input_frames=ell, pred_frames=t_pred, substeps=5,
                                     velocity_correction=False, **MODES[mode])).double()
    optimizer = torch.optim.Adam(model.system.parameters(), lr=3e-2)
    gen = torch.Generator().manual_seed(seed)
    for step in range(steps):
        for group in optimizer.param_groups:
            group["lr"] = 3e-2 if step < 0.7 * steps else 3e-3
        w = windows[torch.randint(0, len(windows), (64,), generator=gen)]
        loss = (model.predict(w[:, :ell], None, t_pred) - w[:, ell:]).square().mean()
        optimizer.zero_grad()
        loss.backward()
        optimizer.step()
    return model.physical_parameters()


def main(argv: list[str] | None = None) -> int:
    p = ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--out", type=out_prefix, required=True, help="output prefix: OUT.json and OUT.md")
    p.add_argument("--sequences", type=positive_int, default=200, help="sequences per scene (default %(default)s)")
    p.add_argument("--steps", type=positive_int, default=1000, help="Adam steps per fit (default %(default)s)")
    p.add_argument("--seed", type=seed_int, default=100, help="data seed, as the systems benchmark's (default %(default)s)")
    args = p.parse_args(argv)
    torch.set_num_threads(1)
    rows: list[dict[str, Any]] = []
    for scene in SCENES:
        positions = true_positions(scene, args.sequences, args.seed)
        truth = scene_config(scene).params
        for mode in MODES:
            learned = fit(scene, positions, mode, args.steps, seed=0)
            for name, value in learned.items():
                rows.append({"scene": scene, "mode": mode, "parameter": name, "true": truth[name], "learned": value,
                             "relative_error": (value - truth[name]) / truth[name]})
                print(f"{scene} {mode} {name}: {value:.4f} (true {truth[name]:g})", flush=True)
    record = {"command": " ".join(["python", "benchmarks/velocity_bias.py", *(argv or sys.argv[1:])]),
              "machine": machine(), "sequences": args.sequences, "steps": args.steps, "rows": rows}
    lines = ["# The scenes' velocity reading and the bias of the parameters (true positions, no pixels)", "",
             f"Reproduce: `{record['command']}`. {args.sequences} sequences per scene, the paper's values, the fast "
             "preset's windows, Euler M = 5 (the data: 10 substeps), parameters from 1.", "",
             "| scene | velocity at frame L | parameter | true | learned | signed error |", "|---|---|---|---|---|---|"]
    lines += [f"| {r['scene']} | {r['mode']} | {r['parameter']} | {r['true']:g} | {r['learned']:.4f} | "
              f"{100 * r['relative_error']:+.2f}% |" for r in rows]
    write_page(args.out, record, "\n".join(lines) + "\n")  # both or neither
    return 0


if __name__ == "__main__":
    from piga.cli.common import run_script

    run_script(main, __file__)
